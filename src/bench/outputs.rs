//! The bench's output directory: what a run may write there and what it may remove.
//!
//! Contract:
//! - `DIR/images/` holds one `NNN.exr` per configuration. Its names are recorded, before each
//!   image is written, in `DIR/images/.vmls-bench` (one name a line), so that a later run can
//!   tell the images it wrote from the user's files.
//! - A run removes only recorded images (the stale ones of an earlier run, which must not pass
//!   for this run's). It refuses, before any work and before removing anything, an `images/`
//!   that holds an entry the record does not name (a user's folder, a file of an older vmls),
//!   or a recorded entry that is not a regular file or that is one of the run's inputs.
//! - Every file the run writes (images, SPIR-V dumps, the results) is refused when it is the
//!   same file as an input (the scene, its data file, an imported CSV), by identity as in
//!   [`crate::files::Outputs`].

use super::BenchError;
use crate::files::{FileError, check_not_input};
use std::path::{Path, PathBuf};

/// The record of the images a bench wrote, inside `images/`.
pub const RECORD: &str = ".vmls-bench";

/// The file names a run writes for configuration `index`.
pub fn image_name(index: usize) -> String {
    format!("{index:03}.exr")
}

/// The run's inputs, which no output may be: (role, path).
pub type Inputs = Vec<(String, PathBuf)>;

/// The images directory of one run, prepared (see the module contract).
pub struct ImagesDir {
    dir: PathBuf,
    recorded: Vec<String>,
    inputs: Inputs,
}

fn io(path: &Path, action: &'static str, source: std::io::Error) -> BenchError {
    FileError::Io {
        path: path.to_path_buf(),
        action,
        source,
    }
    .into()
}

fn foreign(dir: &Path, name: &str, what: &str) -> BenchError {
    BenchError::Io {
        path: dir.join(name).display().to_string(),
        message: format!(
            "{what}; vmls bench removes only images it recorded in {RECORD}, so it refuses an \
             images/ folder holding anything else: move it or choose another --out"
        ),
    }
}

/// The inputs as the output layer takes them.
pub fn refs(inputs: &Inputs) -> Vec<(&str, &Path)> {
    inputs
        .iter()
        .map(|(r, p)| (r.as_str(), p.as_path()))
        .collect()
}

impl ImagesDir {
    /// Creates `out/images/` if needed, refuses foreign entries, removes recorded ones.
    pub fn prepare(out: &Path, inputs: Inputs) -> Result<Self, BenchError> {
        let dir = out.join("images");
        std::fs::create_dir_all(&dir).map_err(|e| io(&dir, "create the directory", e))?;
        let record_path = dir.join(RECORD);
        let recorded: Vec<String> = match std::fs::symlink_metadata(&record_path) {
            Ok(meta) if meta.is_file() => {
                let bytes = crate::files::read_input(&record_path, 1 << 20)?;
                String::from_utf8_lossy(&bytes)
                    .lines()
                    .filter(|l| !l.is_empty())
                    .map(str::to_string)
                    .collect()
            }
            Ok(_) => return Err(foreign(&dir, RECORD, "the record is not a regular file")),
            Err(_) => Vec::new(),
        };
        let entries = std::fs::read_dir(&dir).map_err(|e| io(&dir, "list", e))?;
        let mut stale = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| io(&dir, "list", e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name == RECORD {
                continue;
            }
            if !recorded.contains(&name) {
                let shown = crate::files::excerpt_text(&name, 60);
                return Err(foreign(
                    &dir,
                    &shown,
                    "this entry was not written by vmls bench",
                ));
            }
            let meta = std::fs::symlink_metadata(entry.path())
                .map_err(|e| io(&entry.path(), "look at", e))?;
            if !meta.is_file() {
                return Err(foreign(
                    &dir,
                    &name,
                    "a recorded name is not a regular file",
                ));
            }
            check_not_input("stale bench image", &entry.path(), &refs(&inputs))?;
            stale.push(entry.path());
        }
        for path in stale {
            match std::fs::remove_file(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(io(&path, "remove the stale image", e));
                }
                _ => {}
            }
        }
        let images = Self {
            dir,
            recorded: Vec::new(),
            inputs,
        };
        images.save_record()?;
        Ok(images)
    }

    fn save_record(&self) -> Result<(), BenchError> {
        let text: String = self.recorded.iter().map(|n| format!("{n}\n")).collect();
        let inputs = refs(&self.inputs);
        crate::files::write_output("bench image record", &self.dir.join(RECORD), &inputs, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())
        })?;
        Ok(())
    }

    /// Writes configuration `index`'s image, recording its name first: a run stopped between
    /// the two leaves a recorded name without a file, never a file without a record.
    pub fn write(
        &mut self,
        index: usize,
        width: u32,
        height: u32,
        pixels: &[[f32; 4]],
    ) -> Result<(), BenchError> {
        let name = image_name(index);
        let path = self.dir.join(&name);
        check_not_input("bench image", &path, &refs(&self.inputs))?;
        if !self.recorded.contains(&name) {
            self.recorded.push(name);
            self.save_record()?;
        }
        crate::output::write_image(&path, width, height, pixels)?;
        Ok(())
    }
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
    fn only_recorded_images_are_removed_and_foreign_entries_refused() {
        let out = tempfile::tempdir().expect("tempdir");
        let mut images = ImagesDir::prepare(out.path(), Vec::new()).expect("prepare");
        images.write(0, 1, 1, &[[0.5; 4]]).expect("write");
        images.write(1, 1, 1, &[[0.5; 4]]).expect("write");
        let dir = out.path().join("images");
        assert_eq!(names(&dir), [".vmls-bench", "000.exr", "001.exr"]);
        // A second run removes the recorded images and starts an empty record.
        ImagesDir::prepare(out.path(), Vec::new()).expect("prepare again");
        assert_eq!(names(&dir), [".vmls-bench"]);
        // A user's folder inside images/ is refused and nothing is removed.
        ImagesDir::prepare(out.path(), Vec::new())
            .expect("prepare")
            .write(0, 1, 1, &[[0.5; 4]])
            .expect("write");
        std::fs::create_dir_all(dir.join("holiday")).expect("mkdir");
        std::fs::write(dir.join("holiday/photo.jpg"), b"jpg").expect("write");
        let e = ImagesDir::prepare(out.path(), Vec::new())
            .err()
            .expect("refused")
            .to_string();
        assert!(
            e.contains("holiday") && e.contains("not written by vmls"),
            "{e}"
        );
        assert_eq!(names(&dir), [".vmls-bench", "000.exr", "holiday"]);
        assert_eq!(
            std::fs::read(dir.join("holiday/photo.jpg")).expect("kept"),
            b"jpg"
        );
        // An image named like ours but not recorded is the user's too.
        std::fs::remove_dir_all(dir.join("holiday")).expect("rm");
        std::fs::write(dir.join("007.exr"), b"mine").expect("write");
        assert!(ImagesDir::prepare(out.path(), Vec::new()).is_err());
        assert_eq!(std::fs::read(dir.join("007.exr")).expect("kept"), b"mine");
    }

    #[test]
    fn an_image_that_is_an_input_is_refused() {
        let out = tempfile::tempdir().expect("tempdir");
        let dir = out.path().join("images");
        std::fs::create_dir_all(&dir).expect("mkdir");
        let scene = dir.join("000.exr");
        std::fs::write(&scene, b"[camera]").expect("write");
        std::fs::write(dir.join(RECORD), b"000.exr\n").expect("record");
        let inputs = vec![("scene".to_string(), scene.clone())];
        let e = ImagesDir::prepare(out.path(), inputs)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("same file"), "{e}");
        assert_eq!(std::fs::read(&scene).expect("kept"), b"[camera]");
    }
}
