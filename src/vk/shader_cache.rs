//! Compiled kernels kept on disk between processes: shaderc takes 80–140 ms per kernel variant
//! on the development machine, about a third of a first frame there and most of one on a real
//! GPU (BENCHMARKS.md, "On a real GPU"), and a command-line render is always a first frame.
//!
//! Contract:
//! - Off unless a process turns it on ([`use_disk_cache`]; the `vmls` program does, at
//!   `$XDG_CACHE_HOME/vmls/shaders` or `~/.cache/vmls/shaders`, and `VMLS_SHADER_CACHE` names
//!   another directory or `off`). A library user decides where, or whether, to write.
//! - A file is found by a key over everything the SPIR-V depends on: every GLSL file as the
//!   compiler reads it ([`super::source_texts`], so `VMLS_GLSL_DIR` edits miss), the kernel's
//!   name, text and macro definitions, the compile options and this format's version.
//! - A file is used only when its header, key, length, checksum and SPIR-V magic all agree;
//!   anything else (a truncated write, a flipped byte, another program's file) is a miss and is
//!   compiled and written again. Writes go to a temporary in the same directory and are renamed
//!   into place, so a reader never sees half a file.
//! - Best effort: a directory that cannot be created, read or written costs the compile it
//!   would have saved, never a failure.
//!
//! File layout (u32 little-endian words): `b"VMLS"`, format, key (2 words), checksum of the
//! SPIR-V (2 words), SPIR-V word count, then the SPIR-V.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Bump when the compile options or this layout change.
const FORMAT: u32 = 1;
const MAGIC: u32 = u32::from_le_bytes(*b"VMLS");
const HEADER_WORDS: usize = 7;
const SPIRV_MAGIC: u32 = 0x0723_0203;

/// The process-wide cache directory; `None`: off.
static DIR: Mutex<Option<PathBuf>> = Mutex::new(None);

/// Turns the disk cache on at `dir` (created at first write) or off, for every
/// [`super::ShaderCompiler`] created afterwards.
pub fn use_disk_cache(dir: Option<PathBuf>) {
    *DIR.lock().unwrap_or_else(|p| p.into_inner()) = dir;
}

/// The directory [`use_disk_cache`] set.
pub(super) fn disk_cache_dir() -> Option<PathBuf> {
    DIR.lock().unwrap_or_else(|p| p.into_inner()).clone()
}

/// FNV-1a, 64 bits: stable across Rust releases and processes (std's hasher is not promised
/// to be), which a key stored on disk needs.
#[derive(Clone, Copy)]
pub(super) struct Fnv(u64);

impl Fnv {
    pub(super) fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    pub(super) fn bytes(mut self, data: &[u8]) -> Self {
        for &b in data {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }

    /// A length-prefixed field, so that ("ab", "c") and ("a", "bc") differ.
    pub(super) fn field(self, data: &[u8]) -> Self {
        self.bytes(&(data.len() as u64).to_le_bytes()).bytes(data)
    }

    pub(super) fn finish(self) -> u64 {
        self.0
    }
}

fn checksum(words: &[u32]) -> u64 {
    Fnv::new().bytes(bytemuck::cast_slice(words)).finish()
}

/// The file of `key` for kernel `name` in `dir`.
pub(super) fn path(dir: &Path, name: &str, key: u64) -> PathBuf {
    let stem: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    dir.join(format!("{stem}-{key:016x}.spv"))
}

/// Largest file read: a kernel's SPIR-V is well under 1 MiB, and a bigger file under our name
/// is not ours.
const MAX_FILE_BYTES: u64 = 16 << 20;

/// The SPIR-V stored for `key`, if a valid file holds it.
pub(super) fn load(dir: &Path, name: &str, key: u64) -> Option<Vec<u32>> {
    let file = path(dir, name, key);
    let meta = std::fs::metadata(&file).ok()?;
    if !meta.is_file() || meta.len() > MAX_FILE_BYTES {
        return None;
    }
    let bytes = std::fs::read(&file).ok()?;
    if bytes.len() % 4 != 0 || bytes.len() < 4 * (HEADER_WORDS + 1) {
        return None;
    }
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let pair = |i: usize| u64::from(words[i]) | (u64::from(words[i + 1]) << 32);
    let spirv = &words[HEADER_WORDS..];
    let valid = words[0] == MAGIC
        && words[1] == FORMAT
        && pair(2) == key
        && words[6] as usize == spirv.len()
        && pair(4) == checksum(spirv)
        && spirv[0] == SPIRV_MAGIC;
    valid.then(|| spirv.to_vec())
}

/// Stores `spirv` for `key`; failures are ignored (the module contract).
pub(super) fn store(dir: &Path, name: &str, key: u64, spirv: &[u32]) {
    let sum = checksum(spirv);
    let mut words = vec![
        MAGIC,
        FORMAT,
        key as u32,
        (key >> 32) as u32,
        sum as u32,
        (sum >> 32) as u32,
        spirv.len() as u32,
    ];
    words.extend_from_slice(spirv);
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    let target = path(dir, name, key);
    // One temporary per process and store: threads of one process may store the same key.
    static STORES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let temp = dir.join(format!(
        ".{}.{}.{}.tmp",
        target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        std::process::id(),
        STORES.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    let written = std::fs::create_dir_all(dir)
        .and_then(|()| std::fs::write(&temp, &bytes))
        .and_then(|()| std::fs::rename(&temp, &target));
    if written.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("vmls-shader-cache-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_stored_kernel_loads_back_and_a_damaged_file_is_a_miss() {
        let d = dir("roundtrip");
        let spirv = vec![SPIRV_MAGIC, 0x0001_0500, 7, 11, 13];
        store(&d, "raycast.comp", 42, &spirv);
        assert_eq!(load(&d, "raycast.comp", 42), Some(spirv.clone()));
        // Another key, another kernel: misses.
        assert_eq!(load(&d, "raycast.comp", 43), None);
        assert_eq!(load(&d, "mls_eval.comp", 42), None);
        let file = path(&d, "raycast.comp", 42);
        let good = std::fs::read(&file).expect("stored");
        // Every single flipped byte is caught (header, length, checksum or magic).
        for at in 0..good.len() {
            let mut bad = good.clone();
            bad[at] ^= 0x10;
            std::fs::write(&file, &bad).expect("write");
            assert_eq!(load(&d, "raycast.comp", 42), None, "flipped byte {at}");
        }
        // Truncated anywhere.
        for len in [0, 3, 4 * HEADER_WORDS, good.len() - 4] {
            std::fs::write(&file, &good[..len]).expect("write");
            assert_eq!(load(&d, "raycast.comp", 42), None, "truncated to {len}");
        }
        // No temporary is left behind.
        let names: Vec<_> = std::fs::read_dir(&d)
            .expect("dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn threads_storing_one_key_at_once_leave_one_valid_file() {
        let d = dir("threads");
        let spirv: Vec<u32> = std::iter::once(SPIRV_MAGIC).chain(0..50_000).collect();
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| store(&d, "raycast.comp", 9, &spirv));
            }
        });
        assert_eq!(load(&d, "raycast.comp", 9).as_ref(), Some(&spirv));
        assert_eq!(std::fs::read_dir(&d).expect("dir").count(), 1);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn oversized_files_and_directories_under_a_kernel_name_are_misses() {
        let d = dir("odd");
        std::fs::create_dir_all(path(&d, "raycast.comp", 5)).expect("a directory in its place");
        assert_eq!(load(&d, "raycast.comp", 5), None);
        let big = std::fs::File::create(path(&d, "raycast.comp", 6)).expect("create");
        big.set_len(MAX_FILE_BYTES + 4)
            .expect("a sparse file past the cap");
        assert_eq!(load(&d, "raycast.comp", 6), None);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn an_unwritable_directory_costs_nothing_but_the_compile() {
        // A file where the directory should be: create_dir_all fails, store returns.
        let d = dir("blocked");
        std::fs::write(&d, b"not a directory").expect("write");
        store(&d, "raycast.comp", 1, &[SPIRV_MAGIC, 1]);
        assert_eq!(load(&d, "raycast.comp", 1), None);
        let _ = std::fs::remove_file(&d);
    }

    #[test]
    fn fnv_fields_are_length_prefixed() {
        let a = Fnv::new().field(b"ab").field(b"c").finish();
        let b = Fnv::new().field(b"a").field(b"bc").finish();
        assert_ne!(a, b);
        // FNV-1a's published test vector for "a".
        assert_eq!(Fnv::new().bytes(b"a").finish(), 0xaf63_dc4c_8601_ec8c);
    }
}
