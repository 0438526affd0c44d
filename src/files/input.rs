//! Reading inputs: regular files only, bounded reads, identity for the same-file checks.

use super::FileError;
use std::fs::{File, Metadata};
use std::io::Read;
use std::path::{Path, PathBuf};

/// What a path is, in words, when it is not a regular file.
fn kind_of(meta: &Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("something that is not a regular file")
}

/// Opens without blocking: opening a FIFO for reading would otherwise wait for a writer before
/// we could look at what it is.
fn open_nonblocking(path: &Path) -> std::io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    options.open(path)
}

/// Opens a regular file of at most `limit` bytes for reading (see the module contract): a FIFO,
/// a device or a directory is refused before any read. Returns the file and its size.
fn open_input(path: &Path, limit: u64) -> Result<(File, u64), FileError> {
    let io = |action, source| FileError::Io {
        path: path.to_path_buf(),
        action,
        source,
    };
    let not_regular = |found| FileError::NotRegular {
        path: path.to_path_buf(),
        found,
    };
    // Stat first so that a socket or a FIFO is named as such rather than failing to open.
    let meta = std::fs::metadata(path).map_err(|e| io("read", e))?;
    if let Some(found) = kind_of(&meta) {
        return Err(not_regular(found));
    }
    // The path may have changed between the two looks: judge what was actually opened.
    let file = open_nonblocking(path).map_err(|e| io("read", e))?;
    let meta = file.metadata().map_err(|e| io("read", e))?;
    if let Some(found) = kind_of(&meta) {
        return Err(not_regular(found));
    }
    let size = meta.len();
    if size > limit {
        return Err(FileError::TooLarge {
            path: path.to_path_buf(),
            size,
            limit,
        });
    }
    Ok((file, size))
}

/// [`open_input`], then reads at most `head` bytes from the start: a header, read before the
/// reader decides how to read the rest. Returns the file (positioned after the head), its size
/// and the head. Readers that stream a large payload (NRRD raw data) use it instead of
/// [`read_input`], and check their own memory.
pub fn read_head(path: &Path, limit: u64, head: u64) -> Result<(File, u64, Vec<u8>), FileError> {
    let (mut file, size) = open_input(path, limit)?;
    let bytes = read_up_to(path, &mut file, head.min(size))?;
    Ok((file, size, bytes))
}

/// At most `n` bytes from `file`'s position (fewer at its end), read errors naming `path`.
fn read_up_to(path: &Path, file: &mut File, n: u64) -> Result<Vec<u8>, FileError> {
    let mut bytes = Vec::with_capacity(n as usize);
    file.take(n)
        .read_to_end(&mut bytes)
        .map_err(|source| FileError::Io {
            path: path.to_path_buf(),
            action: "read",
            source,
        })?;
    Ok(bytes)
}

/// Reads a whole regular file of at most `limit` bytes (see the module contract).
pub fn read_input(path: &Path, limit: u64) -> Result<Vec<u8>, FileError> {
    let (mut file, size) = open_input(path, limit)?;
    // The whole file is read into memory: a sparse or huge file must fit what is free.
    super::memory::check("reading the whole file", size, "use a smaller file").map_err(
        |message| FileError::Memory {
            path: path.to_path_buf(),
            message,
        },
    )?;
    read_up_to(path, &mut file, size)
}

/// The identity of a file: what a path resolves to, independent of its spelling.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileId {
    /// An existing file: its device and inode (symlinks followed, hard links equal).
    Existing(u64, u64),
    /// A path that does not exist yet: its canonical directory and its name.
    Planned(PathBuf),
}

impl FileId {
    /// The identity of `path`, or `None` when its directory cannot be resolved either.
    pub fn of(path: &Path) -> Option<FileId> {
        if let Ok(meta) = std::fs::metadata(path) {
            return Some(Self::existing(&meta, path));
        }
        let name = path.file_name()?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        Some(FileId::Planned(dir.canonicalize().ok()?.join(name)))
    }

    #[cfg(unix)]
    fn existing(meta: &Metadata, _path: &Path) -> FileId {
        use std::os::unix::fs::MetadataExt;
        FileId::Existing(meta.dev(), meta.ino())
    }

    #[cfg(not(unix))]
    fn existing(_meta: &Metadata, path: &Path) -> FileId {
        use std::hash::{Hash, Hasher};
        let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        let mut h = std::collections::hash_map::DefaultHasher::new();
        canonical.hash(&mut h);
        FileId::Existing(0, h.finish())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_regular_files_and_refuses_the_rest() {
        let dir = tempfile::tempdir().expect("tempdir");
        let f = dir.path().join("a.txt");
        std::fs::write(&f, b"hello").expect("write");
        assert_eq!(read_input(&f, 5).expect("read"), b"hello");
        let e = read_input(&f, 4).expect_err("over the limit").to_string();
        assert!(e.contains("5 bytes") && e.contains("4 bytes"), "{e}");
        let e = read_input(dir.path(), 1 << 20)
            .expect_err("a directory")
            .to_string();
        assert!(e.contains("a directory"), "{e}");
        #[cfg(target_os = "linux")]
        {
            let e = read_input(Path::new("/dev/zero"), 1 << 20).expect_err("a device");
            assert!(e.to_string().contains("character device"), "{e}");
        }
    }

    #[test]
    fn identity_ignores_spelling() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.png");
        std::fs::write(&a, b"x").expect("write");
        let dotted = dir.path().join(".").join("a.png");
        assert_eq!(FileId::of(&a), FileId::of(&dotted));
        let b = dir.path().join("b.png");
        assert_ne!(FileId::of(&a), FileId::of(&b));
        assert_eq!(FileId::of(&b), FileId::of(&dir.path().join("./b.png")));
        #[cfg(unix)]
        {
            let link = dir.path().join("link.png");
            std::os::unix::fs::symlink(&a, &link).expect("symlink");
            let hard = dir.path().join("hard.png");
            std::fs::hard_link(&a, &hard).expect("hard link");
            assert_eq!(FileId::of(&a), FileId::of(&link));
            assert_eq!(FileId::of(&a), FileId::of(&hard));
        }
    }
}
