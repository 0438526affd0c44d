//! Data in: every loader turns a file (or a generator) into a [`Volume`], a regular grid of f32
//! scalars with origin and per-axis spacing.
//!
//! Contract shared by all loaders:
//! - values are stored x-fastest (`index = x + nx·(y + ny·z)`), converted to f32 (after any
//!   scaling the format defines, e.g. NIfTI slope/intercept);
//! - a NaN or ±Inf value is rejected with [`DataError::NonFinite`] naming the file and the first
//!   offending sample (we reject rather than skip: a silently holed volume would render a wrong
//!   image that looks plausible);
//! - dimensions are checked with overflow-safe arithmetic and against [`MAX_SAMPLES`] before any
//!   allocation, so an absurd header cannot exhaust memory;
//! - every error names the file and the line or byte offset where the input stopped making sense.

pub mod dataset;
pub(crate) mod encoding;
pub mod marschner_lobb;
pub mod nifti;
pub mod nrrd;
pub mod points;
pub mod random;
pub mod values;
pub mod vtk;
pub mod vtk_legacy;
pub mod vtk_xml;
mod vtk_xml_decode;
pub mod vtk_xml_parallel;
mod vtk_xml_tree;

use std::path::{Path, PathBuf};
pub use values::{Storage, Values};

/// Largest grid we accept from a file: 2^30 samples (4 GiB of f32). Larger grids exceed every
/// Vulkan storage-buffer limit we know of and would only fail later, less clearly.
pub const MAX_SAMPLES: u64 = 1 << 30;

/// Largest magnitude of a data value. The kernels compute in f32, whose largest value is
/// 3.4e38: values of ±1e38 overflow in MLS sums and render wrongly, ±1e34 render exactly
/// (measured); 1e30 leaves room for every weighted sum and product the kernels form.
pub const MAX_VALUE: f32 = 1e30;

/// Largest magnitude of any coordinate (origin, far corner, point): squared distances, which
/// the kernels form in f32, stay below 1e30.
pub const MAX_COORDINATE: f64 = 1e15;

/// Smallest extent of a domain along an axis, in world units (squared, still a normal f32).
pub const MIN_EXTENT: f64 = 1e-12;

/// Smallest extent along an axis relative to the coordinates' magnitude there: below it the
/// f64 world positions (and the f32 ones relative to the domain's centre) cannot tell
/// neighbouring samples apart.
pub const MIN_RELATIVE_EXTENT: f64 = 1e-9;

/// Whether a data value is one vmls renders: finite and within ±[`MAX_VALUE`].
pub fn renderable_value(v: f32) -> bool {
    v.is_finite() && v.abs() <= MAX_VALUE
}

/// Largest data file we read: [`MAX_SAMPLES`] doubles and room for a header, or text.
pub const MAX_FILE_BYTES: u64 = 8 * MAX_SAMPLES + (1 << 20);

/// Reads a data file: a regular file of at most [`MAX_FILE_BYTES`] (see [`crate::files`]), so
/// that a FIFO, a device or a directory is refused before any read.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, DataError> {
    Ok(crate::files::read_input(path, MAX_FILE_BYTES)?)
}

/// A regular grid of scalar samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume {
    /// Samples per axis (x, y, z), each ≥ 1.
    pub dims: [usize; 3],
    /// World position of sample (0, 0, 0).
    pub origin: [f64; 3],
    /// Distance between neighbouring samples per axis, each > 0.
    pub spacing: [f64; 3],
    /// `dims[0]·dims[1]·dims[2]` finite values, x fastest.
    pub values: Values,
}

impl Volume {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// True when the grid holds no sample.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Linear index of grid point (i, j, k).
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// World position of grid point (i, j, k).
    pub fn position(&self, i: usize, j: usize, k: usize) -> [f64; 3] {
        [
            self.origin[0] + i as f64 * self.spacing[0],
            self.origin[1] + j as f64 * self.spacing[1],
            self.origin[2] + k as f64 * self.spacing[2],
        ]
    }

    /// Axis-aligned bounding box of the sample positions: (min, max).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut max = self.origin;
        for (a, m) in max.iter_mut().enumerate() {
            *m += (self.dims[a].saturating_sub(1)) as f64 * self.spacing[a];
        }
        (self.origin, max)
    }

    /// Smallest and largest value.
    pub fn value_range(&self) -> (f32, f32) {
        self.values.range()
    }
}

/// Errors of the data layer. Every variant names the file it is about.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The file does not follow its format: `location` is "line N" or "byte N".
    #[error("{path}: {location}: expected {expected}, found {found}")]
    Format {
        path: PathBuf,
        location: String,
        expected: String,
        found: String,
    },
    /// The file is valid but uses a feature we do not read.
    #[error("{path}: {location}: unsupported {what}")]
    Unsupported {
        path: PathBuf,
        location: String,
        what: String,
    },
    #[error("{path}: data ends early: expected {expected} bytes/values, found {found}")]
    Truncated {
        path: PathBuf,
        expected: u64,
        found: u64,
    },
    #[error(
        "{path}: sample {index} (x={x}, y={y}, z={z}) is {value:e}: expected a finite value within ±1e30 (NaN, infinite and larger values are rejected: the kernels' f32 arithmetic would overflow)"
    )]
    NonFinite {
        path: PathBuf,
        index: usize,
        x: usize,
        y: usize,
        z: usize,
        value: f32,
    },
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    #[error("{path}: dimensions {dims:?} cannot be read: {reason}")]
    TooLarge {
        path: PathBuf,
        dims: [u64; 3],
        reason: String,
    },
    #[error(
        "{path}: unknown volume format (expected .vtk, .vti, .vtr, .vts, .vtu, .vtp, .pvti, .pvtr, .pvts, .pvtu, .pvtp, .csv, .ply, .nrrd, .nii or .nii.gz)"
    )]
    UnknownFormat { path: PathBuf },
    #[error("{path}: point {index} has a non-finite coordinate {point:?}")]
    NonFiniteCoordinate {
        path: PathBuf,
        index: usize,
        point: [f64; 3],
    },
    /// The domain's geometry is outside what the kernels can resolve, or has no volume.
    #[error("{path}: {what}: expected {expected}, found {found}")]
    Geometry {
        path: PathBuf,
        what: String,
        expected: String,
        found: String,
    },
    #[error(
        "{path}: array '{array}' element {index} is {value:e}: expected a finite value within ±1e30 (NaN, infinite and larger values are rejected: the kernels' f32 arithmetic would overflow)"
    )]
    NonFiniteValue {
        path: PathBuf,
        array: String,
        index: usize,
        value: f32,
    },
    #[error("{path}: cell {cell} refers to point {index}, but there are only {points} points")]
    IndexOutOfRange {
        path: PathBuf,
        cell: usize,
        index: u64,
        points: usize,
    },
    #[error(
        "{path}: {location}: cell type {id} ({name}) is not supported (vmls reads tetrahedra, hexahedra, voxels, wedges and pyramids)"
    )]
    UnsupportedCell {
        path: PathBuf,
        location: String,
        id: u32,
        name: &'static str,
    },
    /// Loading the file would take more host memory than the machine has free.
    #[error("{path}: {message}")]
    Memory { path: PathBuf, message: String },
    #[error(
        "{path}: no scalar values to render: the file holds positions only (a CSV needs a \
         numeric column besides x, y, z; a PLY a scalar vertex property besides x, y, z; a VTK \
         file point or cell data)"
    )]
    NoArray { path: PathBuf },
    #[error("{path}: no array named '{name}' (arrays in the file: {available})")]
    NoSuchArray {
        path: PathBuf,
        name: String,
        available: String,
    },
}

/// Checks dims for zero, overflow, [`MAX_SAMPLES`] and the host memory of an f32 grid read from
/// f32 data; returns the sample count.
pub fn checked_sample_count(path: &Path, dims: [u64; 3]) -> Result<usize, DataError> {
    checked_grid_count(path, dims, 4, Storage::F32)
}

/// [`checked_sample_count`] for a grid whose file holds `file_bytes` per sample (decoded, for a
/// compressed stream) and whose values are kept as `storage`.
pub fn checked_grid_count(
    path: &Path,
    dims: [u64; 3],
    file_bytes: u64,
    storage: Storage,
) -> Result<usize, DataError> {
    if dims.contains(&0) {
        return Err(DataError::TooLarge {
            path: path.to_path_buf(),
            dims,
            reason: "every dimension must be at least 1".into(),
        });
    }
    let n = dims[0]
        .checked_mul(dims[1])
        .and_then(|n| n.checked_mul(dims[2]))
        .ok_or_else(|| DataError::TooLarge {
            path: path.to_path_buf(),
            dims,
            reason: "the sample count overflows 64 bits".into(),
        })?;
    if n > MAX_SAMPLES {
        return Err(DataError::TooLarge {
            path: path.to_path_buf(),
            dims,
            reason: format!("{n} samples exceed the limit of {MAX_SAMPLES}"),
        });
    }
    let n = usize::try_from(n).map_err(|_| DataError::TooLarge {
        path: path.to_path_buf(),
        dims,
        reason: "the sample count does not fit this machine's address space".into(),
    })?;
    let what = format!("a {}×{}×{} grid", dims[0], dims[1], dims[2]);
    let per_sample = grid_host_bytes(file_bytes, storage);
    crate::files::memory::check(
        &what,
        n as u64 * per_sample,
        "crop or downsample the volume",
    )
    .map_err(|message| DataError::Memory {
        path: path.to_path_buf(),
        message,
    })?;
    Ok(n)
}

/// Host bytes a regular grid's sample costs on its way to the GPU, at the peak: the file's
/// bytes (or the inflated stream's) beside the decoded value, then the sample set's copy and the
/// device's (host memory on unified devices, a staging copy on discrete ones), each at the size
/// the values are kept at ([`Storage`]: 8- and 16-bit data stays at its size).
pub fn grid_host_bytes(file_bytes: u64, storage: Storage) -> u64 {
    file_bytes + 3 * storage.bytes() as u64
}

/// Refuses `what`, a generated f32 grid of `samples` values, when building it would not fit in
/// the host's free memory (see [`crate::files::memory`]); `change` says what lowers the need.
pub fn check_grid_host_memory(what: &str, samples: u64, change: &str) -> Result<(), String> {
    crate::files::memory::check(what, samples * grid_host_bytes(4, Storage::F32), change)
}

/// Rejects the first value that is not [`renderable_value`], naming its grid position.
pub fn check_finite(path: &Path, dims: [usize; 3], values: &[f32]) -> Result<(), DataError> {
    if let Some((index, &value)) = values
        .iter()
        .enumerate()
        .find(|(_, v)| !renderable_value(**v))
    {
        let x = index % dims[0];
        let y = (index / dims[0]) % dims[1];
        let z = index / (dims[0] * dims[1]);
        return Err(DataError::NonFinite {
            path: path.to_path_buf(),
            index,
            x,
            y,
            z,
            value,
        });
    }
    Ok(())
}

/// Loads a volume file, choosing the reader by extension (`.vtk`, `.nrrd`, `.nii`, `.nii.gz`).
/// `array` picks a named array where the format has several (VTK); `None` takes the first.
pub fn load(path: &Path, array: Option<&str>) -> Result<Volume, DataError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let volume = if name.ends_with(".vtk") {
        vtk::load(path, array)?
    } else if name.ends_with(".nrrd") {
        nrrd::load(path)?
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        nifti::load(path)?
    } else {
        return Err(DataError::UnknownFormat {
            path: path.to_path_buf(),
        });
    };
    dataset::Geometry::Image {
        dims: volume.dims,
        origin: volume.origin,
        spacing: volume.spacing,
    }
    .check_domain(path)?;
    Ok(volume)
}

/// Loads any supported file as a [`dataset::Dataset`] (geometry and every scalar array), validated by
/// [`dataset::Dataset::validate`]: legacy VTK (every dataset type, arrays named as in the file),
/// VTK XML, serial and parallel (a `.pvti` … summary and the pieces it names, joined:
/// [`vtk_xml_parallel`]), CSV and PLY points. Regular-grid formats (NRRD, NIfTI) give an image
/// with one point array named "scalars".
pub fn load_dataset(path: &Path) -> Result<dataset::Dataset, DataError> {
    if vtk_xml_parallel::is_parallel(path) {
        // A summary naming its pieces, each read from disk (vtk_xml_parallel).
        return vtk_xml_parallel::load(path);
    }
    if lower_name(path).ends_with(".nrrd") {
        // Streamed: raw data never sits in memory beside its values (nrrd::load).
        let dataset = dataset::Dataset::from_volume(nrrd::load(path)?, "scalars");
        dataset.validate(path)?;
        return Ok(dataset);
    }
    parse_dataset_bytes(path, &read_file(path)?)
}

/// A file name in lower case, for choosing its reader.
fn lower_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// The dimensions of a regular-grid file (NRRD, NIfTI) and how its values will be kept, read
/// from its header alone, so that a caller can check the device (and the header's own checks,
/// host memory included, run) before the data is read: a 1 GiB volume the device cannot hold is
/// refused without reading it. `None` for other formats, and where the header cannot be read
/// on its own (the full load then reports what is wrong).
pub fn grid_shape(path: &Path) -> Result<Option<([u64; 3], Storage)>, DataError> {
    let name = lower_name(path);
    if name.ends_with(".nrrd") {
        nrrd::grid_shape(path)
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        nifti::grid_shape(path)
    } else {
        Ok(None)
    }
}

/// [`load_dataset`] on bytes already read: the reader is chosen by `path`'s extension, and
/// `path` names the file in errors (the fuzz targets enter here).
pub fn parse_dataset_bytes(path: &Path, bytes: &[u8]) -> Result<dataset::Dataset, DataError> {
    if vtk_xml_parallel::is_parallel(path) {
        return Err(DataError::Unsupported {
            path: path.to_path_buf(),
            location: "byte 0".into(),
            what: "a parallel VTK XML summary from bytes: it names piece files, read from disk \
                   (load_dataset)"
                .into(),
        });
    }
    let name = lower_name(path);
    let dataset = if name.ends_with(".vtk") {
        vtk_legacy::parse_dataset(path, bytes)?
    } else if name.ends_with(".csv") {
        points::parse_csv(path, bytes)?
    } else if name.ends_with(".ply") {
        points::parse_ply(path, bytes)?
    } else if name.ends_with(".nrrd") {
        dataset::Dataset::from_volume(nrrd::parse(path, bytes)?, "scalars")
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        dataset::Dataset::from_volume(nifti::parse(path, bytes)?, "scalars")
    } else if [".vti", ".vtr", ".vts", ".vtu", ".vtp"]
        .iter()
        .any(|e| name.ends_with(e))
    {
        vtk_xml::parse(path, bytes)?
    } else {
        return Err(DataError::UnknownFormat {
            path: path.to_path_buf(),
        });
    };
    dataset.validate(path)?;
    Ok(dataset)
}
