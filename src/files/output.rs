//! Writing outputs all or nothing through exclusively created temporaries.

use super::{FileError, FileId};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use tempfile::NamedTempFile;

/// The temporaries alive in this process, so that a signal handler that must exit at once
/// can still remove them ([`remove_temporaries`]).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    // A panic while holding the lock leaves the list as valid as before it.
    LIVE.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Deletes every temporary an unfinished [`Outputs`] holds, for a process about to exit
/// without unwinding (a second Ctrl-C): nothing partial is left on disk.
pub fn remove_temporaries() {
    for path in live().drain(..) {
        let _ = std::fs::remove_file(path);
    }
}

/// One planned output.
struct Item {
    role: String,
    target: PathBuf,
    /// `None` once renamed onto the target.
    temp: Option<NamedTempFile>,
    written: bool,
}

impl Item {
    fn temp_path(&self) -> Option<PathBuf> {
        self.temp.as_ref().map(|t| t.path().to_path_buf())
    }
}

impl Drop for Item {
    fn drop(&mut self) {
        if let Some(path) = self.temp_path() {
            live().retain(|p| *p != path);
        }
    }
}

/// A set of outputs written all or nothing (see the module contract).
pub struct Outputs {
    items: Vec<Item>,
}

/// The temporary for `target`: a random name beside it that is never longer than the
/// target's own name (8 characters at least), so any name that fits the file system's name
/// limit has a temporary that fits too.
fn temporary_for(target: &Path, dir: &Path) -> Result<NamedTempFile, FileError> {
    let name_len = target.file_name().map_or(0, |n| n.as_encoded_bytes().len());
    let random = name_len.saturating_sub(1).clamp(7, 15);
    let mut builder = tempfile::Builder::new();
    builder.prefix(".").suffix("").rand_bytes(random);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // Ordinary file permissions (less the umask), as a plain create would give: the
        // exclusive creation is what makes the name safe, not a private mode.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(dir).map_err(|source| FileError::Io {
        path: target.to_path_buf(),
        action: "create a temporary file beside",
        source,
    })
}

impl Outputs {
    /// Plans `outputs` (role, path): refuses any that is the same file as an input or as
    /// another output, or that names a directory, a device or a missing directory, then
    /// creates every temporary, so that an unwritable directory fails before any work.
    pub fn new(outputs: &[(&str, &Path)], inputs: &[(&str, &Path)]) -> Result<Self, FileError> {
        let mut planned: Vec<(&str, &Path, FileId)> = Vec::new();
        for &(role, target) in outputs {
            let bad = |found: String| FileError::BadTarget {
                path: target.to_path_buf(),
                role: role.to_string(),
                found,
            };
            if let Ok(meta) = std::fs::metadata(target)
                && !meta.is_file()
            {
                return Err(bad(if meta.is_dir() {
                    "a directory".into()
                } else {
                    "an existing file that is not a regular file".into()
                }));
            }
            let Some(id) = FileId::of(target) else {
                return Err(bad("a directory that does not exist".into()));
            };
            check_not_input(role, target, inputs)?;
            if let Some((other_role, other, _)) = planned.iter().find(|(_, _, o)| *o == id) {
                return Err(FileError::SameFile {
                    first: target.to_path_buf(),
                    first_role: role.to_string(),
                    second: other.to_path_buf(),
                    second_role: other_role.to_string(),
                    what: "another output",
                });
            }
            planned.push((role, target, id));
        }
        let items = planned
            .into_iter()
            .map(|(role, target, _)| {
                let dir = match target.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p,
                    _ => Path::new("."),
                };
                let temp = temporary_for(target, dir)?;
                live().push(temp.path().to_path_buf());
                Ok(Item {
                    role: role.to_string(),
                    target: target.to_path_buf(),
                    temp: Some(temp),
                    written: false,
                })
            })
            .collect::<Result<_, FileError>>()?;
        Ok(Self { items })
    }

    /// Writes the contents of the planned output `target` through `write` into its temporary.
    pub fn write(
        &mut self,
        target: &Path,
        write: impl FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
    ) -> Result<(), FileError> {
        let Some(item) = self.items.iter_mut().find(|i| i.target == target) else {
            return Err(FileError::BadTarget {
                path: target.to_path_buf(),
                role: "unplanned".into(),
                found: "an output that was not planned".into(),
            });
        };
        let io = |source| FileError::Io {
            path: item.target.clone(),
            action: "write",
            source,
        };
        let Some(temp) = item.temp.as_ref() else {
            return Err(io(std::io::Error::other("the output was already renamed")));
        };
        let file = temp.as_file();
        let mut w = BufWriter::new(file);
        write(&mut w).map_err(io)?;
        w.flush().map_err(io)?;
        drop(w);
        file.sync_all().map_err(io)?;
        item.written = true;
        Ok(())
    }

    /// Renames every temporary over its target, once every output was written; an output
    /// left unwritten fails the whole set and renames nothing.
    pub fn commit(self) -> Result<(), FileError> {
        if let Some(missing) = self.items.iter().find(|i| !i.written) {
            return Err(FileError::BadTarget {
                path: missing.target.clone(),
                role: missing.role.clone(),
                found: "an output that was never written".into(),
            });
        }
        for mut item in self.items {
            let path = item.temp_path();
            let Some(temp) = item.temp.take() else {
                continue;
            };
            live().retain(|p| Some(p) != path.as_ref());
            temp.persist(&item.target).map_err(|e| FileError::Io {
                path: item.target.clone(),
                action: "rename the finished temporary onto",
                source: e.error,
            })?;
        }
        Ok(())
    }
}

/// Refuses `target` (an output of role `role`) when it is the same file as one of `inputs`
/// (role, path), by identity ([`FileId`]): every spelling, symlink and hard link is caught.
pub fn check_not_input(
    role: &str,
    target: &Path,
    inputs: &[(&str, &Path)],
) -> Result<(), FileError> {
    let Some(id) = FileId::of(target) else {
        return Ok(());
    };
    match inputs
        .iter()
        .find(|(_, p)| FileId::of(p).is_some_and(|i| i == id))
    {
        Some(&(input_role, input)) => Err(FileError::SameFile {
            first: target.to_path_buf(),
            first_role: role.to_string(),
            second: input.to_path_buf(),
            second_role: input_role.to_string(),
            what: "an input",
        }),
        None => Ok(()),
    }
}

/// Writes one output (see [`Outputs`]), refusing it when it is one of `inputs`.
pub fn write_output(
    role: &str,
    target: &Path,
    inputs: &[(&str, &Path)],
    write: impl FnOnce(&mut BufWriter<&File>) -> std::io::Result<()>,
) -> Result<(), FileError> {
    let mut outputs = Outputs::new(&[(role, target)], inputs)?;
    outputs.write(target, write)?;
    outputs.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .expect("read_dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn all_or_nothing() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.txt");
        let b = dir.path().join("b.txt");
        let mut out = Outputs::new(&[("a", &a), ("b", &b)], &[]).expect("plan");
        out.write(&a, |w| w.write_all(b"A")).expect("write a");
        // b never written: nothing lands, and dropping the set leaves no temporary.
        assert!(out.commit().is_err());
        assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
        let mut out = Outputs::new(&[("a", &a), ("b", &b)], &[]).expect("plan");
        out.write(&a, |w| w.write_all(b"A")).expect("write a");
        let failed = out.write(&b, |_| Err(std::io::Error::other("disk on fire")));
        assert!(failed.is_err());
        drop(out);
        assert!(names(dir.path()).is_empty());
        let mut out = Outputs::new(&[("a", &a), ("b", &b)], &[]).expect("plan");
        out.write(&a, |w| w.write_all(b"A")).expect("write a");
        out.write(&b, |w| w.write_all(b"B")).expect("write b");
        out.commit().expect("commit");
        assert_eq!(names(dir.path()), ["a.txt", "b.txt"]);
        assert_eq!(std::fs::read(&b).expect("read"), b"B");
    }

    #[test]
    fn temporaries_fit_beside_long_names() {
        let dir = tempfile::tempdir().expect("tempdir");
        let long = dir.path().join(format!("{}.png", "n".repeat(248)));
        write_output("image", &long, &[], |w| w.write_all(b"x")).expect("252-byte name");
        assert_eq!(std::fs::read(&long).expect("read"), b"x");
    }

    #[cfg(unix)]
    #[test]
    fn planted_symlinks_redirect_nothing() {
        let dir = tempfile::tempdir().expect("tempdir");
        let victim = dir.path().join("victim");
        std::fs::write(&victim, b"keep").expect("write");
        let target = dir.path().join("out.png");
        // A symlink at the fixed name the old writer used, and at the target itself.
        std::os::unix::fs::symlink(&victim, dir.path().join(".out.png.partial")).expect("link");
        write_output("image", &target, &[], |w| w.write_all(b"new")).expect("write");
        assert_eq!(std::fs::read(&victim).expect("read"), b"keep");
        let link = dir.path().join("link.png");
        std::os::unix::fs::symlink(&victim, &link).expect("link");
        // Writing through a symlinked target replaces the link, never the file it points at.
        write_output("image", &link, &[], |w| w.write_all(b"new")).expect("write");
        assert_eq!(std::fs::read(&victim).expect("read"), b"keep");
        assert!(!std::fs::symlink_metadata(&link).expect("meta").is_symlink());
    }

    #[test]
    fn outputs_equal_to_inputs_or_each_other_are_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let scene = dir.path().join("scene.toml");
        std::fs::write(&scene, b"[camera]").expect("write");
        let spelled = dir.path().join(".").join("scene.toml");
        let e = Outputs::new(&[("--stats", &spelled)], &[("scene", &scene)])
            .err()
            .expect("refused")
            .to_string();
        assert!(
            e.contains("scene.toml (--stats)") && e.contains("(scene)"),
            "{e}"
        );
        assert_eq!(std::fs::read(&scene).expect("read"), b"[camera]");
        let x = dir.path().join("x.png");
        let x2 = dir.path().join("./x.png");
        let e = Outputs::new(&[("-o", &x), ("--eval-map", &x2)], &[])
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("another output"), "{e}");
        let e = Outputs::new(&[("-o", dir.path())], &[]).err().expect("dir");
        assert!(e.to_string().contains("a directory"), "{e}");
        let missing = dir.path().join("no/such/x.png");
        let e = Outputs::new(&[("-o", &missing)], &[])
            .err()
            .expect("missing");
        assert!(e.to_string().contains("does not exist"), "{e}");
        assert_eq!(names(dir.path()), ["scene.toml"]);
    }
}
