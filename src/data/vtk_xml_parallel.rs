//! Parallel VTK XML (issue 30 §2): the summary files that ParaView and VTK's parallel writers
//! produce — `.pvti` (PImageData), `.pvtr` (PRectilinearGrid), `.pvts` (PStructuredGrid),
//! `.pvtu` (PUnstructuredGrid) and `.pvtp` (PPolyData) — each naming its pieces, serial files
//! read by [`super::vtk_xml`]. The `type` attribute of `<VTKFile>` decides the kind.
//!
//! [`Summary::read`] reads the summary alone; [`Summary::assemble`] reads pieces and joins them
//! into one [`Dataset`] ([`load`]: every piece). A rank of a distributed render reads only the
//! pieces whose extents meet its brick ([`Summary::pieces_meeting`]).
//!
//! Contract and choices:
//! - a piece's `Source` is relative to the summary's folder (or absolute); a missing piece is
//!   the error of reading that file;
//! - grids: the summary's `WholeExtent` is the grid; every piece's `Extent` (the summary's
//!   attribute) must lie inside it and match its file's point counts, and the pieces together
//!   must cover it; where pieces overlap (their shared face, ghost layers) the later piece's
//!   values are kept, since a writer gives a shared point the same value in every piece.
//!   `.pvti`: the summary's `Origin` and `Spacing` place the grid (each piece's file must agree:
//!   its first point where the summary puts it, its spacing the same); `.pvtr`: each axis's
//!   coordinates are the pieces', which must agree where pieces share them (to 1e-9 of the
//!   axis's length); `.pvts`: the points are the pieces';
//! - `.pvtu`/`.pvtp`: the pieces are concatenated (point indices offset by the points of the
//!   pieces before); points that two pieces share become coincident samples, merged (their
//!   values averaged) when the sample set is built; with `GhostLevel` > 0, cells flagged as
//!   duplicates in a `vtkGhostType` cell array (bit 0, VTK's DUPLICATECELL) are dropped, so that
//!   no cell counts twice;
//! - arrays: every piece must hold the same numeric arrays, in the same order, as the first;
//!   `vtkGhostType` arrays are not kept; each array keeps the first piece's storage (a later
//!   piece stored otherwise turns it into f32);
//! - sizes: the whole extent's point count is checked against [`MAX_SAMPLES`] before any piece
//!   is read, and the sum of an unstructured file's pieces as they are read.

use super::dataset::{Cells, DataArray, Dataset, Geometry, Location};
use super::vtk_xml_tree::{El, build};
use super::{DataError, MAX_SAMPLES, Values};
use std::path::{Path, PathBuf};

/// The parallel kinds, the serial kind of their pieces and the summary's element.
const KINDS: [(&str, &str); 5] = [
    ("PImageData", "ImageData"),
    ("PRectilinearGrid", "RectilinearGrid"),
    ("PStructuredGrid", "StructuredGrid"),
    ("PUnstructuredGrid", "UnstructuredGrid"),
    ("PPolyData", "PolyData"),
];

/// Whether `path` names a parallel VTK XML file (by its extension).
pub fn is_parallel(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    [".pvti", ".pvtr", ".pvts", ".pvtu", ".pvtp"]
        .iter()
        .any(|e| name.ends_with(e))
}

/// One piece of a summary: its file and, for the grids, its extent.
#[derive(Debug, Clone, PartialEq)]
pub struct Piece {
    pub source: PathBuf,
    pub extent: Option<[i64; 6]>,
}

/// A parallel file's summary: its kind, the grid's whole extent and placement, its pieces.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub path: PathBuf,
    /// The serial kind of the pieces ("ImageData", …).
    pub kind: &'static str,
    /// Grids: the whole extent.
    pub whole: Option<[i64; 6]>,
    /// `.pvti`: origin and spacing.
    pub origin: [f64; 3],
    pub spacing: [f64; 3],
    pub ghost_level: u32,
    /// The numeric arrays `<PPointData>` and `<PCellData>` declare, in the order the pieces'
    /// datasets list them (point arrays first).
    pub arrays: Vec<(String, Location)>,
    pub pieces: Vec<Piece>,
}

/// Reads a parallel file and every piece it names, joined into one dataset.
pub fn load(path: &Path) -> Result<Dataset, DataError> {
    let summary = Summary::read(path)?;
    let all: Vec<usize> = (0..summary.pieces.len()).collect();
    summary.assemble(&all)
}

/// Point counts per axis of an extent.
fn dims_of(e: &[i64; 6]) -> [usize; 3] {
    [0, 1, 2].map(|a| (e[2 * a + 1] - e[2 * a] + 1) as usize)
}

impl Summary {
    /// The summary of the parallel file at `path` (no piece is read).
    pub fn read(path: &Path) -> Result<Self, DataError> {
        let bytes = super::read_file(path)?;
        let doc = build(path, &bytes, false)?;
        let root = El { doc: &doc, i: 0 };
        if root.name() != "VTKFile" {
            return Err(root.format("a <VTKFile> root element", format!("<{}>", root.name())));
        }
        let ty = root.need_attr("type")?;
        let Some(&(element, kind)) = KINDS.iter().find(|(p, _)| *p == ty) else {
            return Err(root.unsupported(format!(
                "VTKFile type {} in a parallel file (vmls reads {})",
                crate::files::excerpt_text(ty, 40),
                KINDS.map(|k| k.0).join(", ")
            )));
        };
        let body = root.need(element)?;
        let grid = !matches!(kind, "UnstructuredGrid" | "PolyData");
        let extent = |el: El<'_, '_>, key: &str| -> Result<Option<[i64; 6]>, DataError> {
            let Some(v) = el.numbers::<i64>(key, 6)? else {
                return Ok(None);
            };
            let e = [v[0], v[1], v[2], v[3], v[4], v[5]];
            if (0..3).any(|a| e[2 * a] > e[2 * a + 1]) {
                return Err(el.format(
                    format!("a {key} with min <= max on each axis"),
                    format!("{v:?}"),
                ));
            }
            Ok(Some(e))
        };
        let whole = if grid {
            let w = extent(body, "WholeExtent")?
                .ok_or_else(|| body.format("a WholeExtent attribute", "none"))?;
            let d = dims_of(&w).map(|n| n as u64);
            super::checked_sample_count(path, d)?;
            Some(w)
        } else {
            None
        };
        let three = |key: &str, default: f64| -> Result<[f64; 3], DataError> {
            let v = body.numbers::<f64>(key, 3)?.unwrap_or(vec![default; 3]);
            if v.iter().any(|x| !x.is_finite()) {
                return Err(body.format(format!("a finite {key}"), format!("{v:?}")));
            }
            Ok([v[0], v[1], v[2]])
        };
        let (origin, spacing) = (three("Origin", 0.0)?, three("Spacing", 1.0)?);
        if kind == "ImageData" && spacing.iter().any(|s| *s <= 0.0) {
            return Err(body.format("a Spacing > 0 on each axis", format!("{spacing:?}")));
        }
        let ghost_level = match body.attr("GhostLevel") {
            None => 0,
            Some(t) => t
                .trim()
                .parse::<u32>()
                .map_err(|_| body.format("GhostLevel as a whole number", format!("\"{t}\"")))?,
        };
        let mut arrays = Vec::new();
        for (tag, location) in [
            ("PPointData", Location::Point),
            ("PCellData", Location::Cell),
        ] {
            for a in body.child(tag).iter().flat_map(|el| el.children()) {
                let numeric = !matches!(a.attr("type"), Some("String" | "Bit"));
                if a.name() == "PDataArray" && numeric {
                    arrays.push((a.attr("Name").unwrap_or_default().to_string(), location));
                }
            }
        }
        let folder = path.parent().unwrap_or(Path::new(""));
        let mut pieces = Vec::new();
        for p in body.children().filter(|c| c.name() == "Piece") {
            let source = p.need_attr("Source")?;
            let extent = if grid {
                let e =
                    extent(p, "Extent")?.ok_or_else(|| p.format("an Extent attribute", "none"))?;
                let w = whole.unwrap_or(e);
                if (0..3).any(|a| e[2 * a] < w[2 * a] || e[2 * a + 1] > w[2 * a + 1]) {
                    return Err(p.format(
                        format!("an Extent inside the WholeExtent {w:?}"),
                        format!("{e:?}"),
                    ));
                }
                Some(e)
            } else {
                None
            };
            pieces.push(Piece {
                source: folder.join(source),
                extent,
            });
        }
        if pieces.is_empty() {
            return Err(body.format("<Piece Source=\"...\"/> elements", "none"));
        }
        Ok(Self {
            path: path.to_path_buf(),
            kind,
            whole,
            origin,
            spacing,
            ghost_level,
            arrays,
            pieces,
        })
    }

    /// The grid pieces whose extents meet the index box `lo ..= hi` of the whole grid (every
    /// piece of an unstructured file).
    pub fn pieces_meeting(&self, lo: [i64; 3], hi: [i64; 3]) -> Vec<usize> {
        (0..self.pieces.len())
            .filter(|&i| match self.pieces[i].extent {
                Some(e) => (0..3).all(|a| e[2 * a] <= hi[a] && e[2 * a + 1] >= lo[a]),
                None => true,
            })
            .collect()
    }

    fn error(&self, expected: impl Into<String>, found: impl Into<String>) -> DataError {
        DataError::Format {
            path: self.path.clone(),
            location: "its pieces".into(),
            expected: expected.into(),
            found: found.into(),
        }
    }

    /// Reads the pieces `which` (indices into `pieces`) and joins them: for a grid, over the
    /// index box they cover together, which they must fill (all pieces: the whole extent).
    pub fn assemble(&self, which: &[usize]) -> Result<Dataset, DataError> {
        let mut read = Vec::with_capacity(which.len());
        for &i in which {
            let piece = &self.pieces[i];
            let d = super::vtk_xml::load(&piece.source)?;
            let kind = match d.geometry {
                Geometry::Image { .. } => "ImageData",
                Geometry::Rectilinear { .. } => "RectilinearGrid",
                Geometry::Structured { .. } => "StructuredGrid",
                Geometry::Unstructured { .. } => "UnstructuredGrid",
                Geometry::Points { .. } => "PolyData",
            };
            if kind != self.kind {
                return Err(self.error(
                    format!("{} pieces", self.kind),
                    format!("{kind} in {}", piece.source.display()),
                ));
            }
            read.push((piece, d));
        }
        let dataset = match self.whole {
            Some(_) => self.join_grid(&read)?,
            None => self.join_cells(read)?,
        };
        dataset.validate(&self.path)?;
        Ok(dataset)
    }

    /// The pieces' arrays, by name and order, checked against the first piece's.
    fn check_arrays(&self, read: &[(&Piece, Dataset)]) -> Result<(), DataError> {
        let names = |d: &Dataset| -> Vec<(String, Location)> {
            d.arrays
                .iter()
                .map(|a| (a.name.clone(), a.location))
                .collect()
        };
        let first = names(&read[0].1);
        for (piece, d) in &read[1..] {
            if names(d) != first {
                return Err(self.error(
                    format!("the arrays of the first piece, {first:?}"),
                    format!("{:?} in {}", names(d), piece.source.display()),
                ));
            }
        }
        Ok(())
    }

    /// Grid pieces placed in the index box they cover.
    fn join_grid(&self, read: &[(&Piece, Dataset)]) -> Result<Dataset, DataError> {
        self.check_arrays(read)?;
        let extents: Vec<[i64; 6]> = read
            .iter()
            .map(|(p, _)| p.extent.unwrap_or_default())
            .collect();
        let mut cover = extents[0];
        for e in &extents[1..] {
            for a in 0..3 {
                cover[2 * a] = cover[2 * a].min(e[2 * a]);
                cover[2 * a + 1] = cover[2 * a + 1].max(e[2 * a + 1]);
            }
        }
        let dims = dims_of(&cover);
        let n = dims[0] * dims[1] * dims[2];
        let cdims = dims.map(|d| d.saturating_sub(1).max(1));
        let cells = cdims[0] * cdims[1] * cdims[2];
        // Which points the pieces have written, to find a hole.
        let mut covered = vec![false; n];
        let mut arrays: Vec<DataArray> = read[0]
            .1
            .arrays
            .iter()
            .filter(|a| a.name != "vtkGhostType")
            .map(|a| DataArray {
                name: a.name.clone(),
                location: a.location,
                components: a.components,
                values: filled(
                    a.values.storage(),
                    match a.location {
                        Location::Point => n,
                        Location::Cell => cells,
                    },
                ),
            })
            .collect();
        let mut coords: [Vec<Option<f64>>; 3] = dims.map(|d| vec![None; d]);
        let mut points = vec![[0.0f64; 3]; if self.kind == "StructuredGrid" { n } else { 0 }];
        for ((piece, d), e) in read.iter().zip(&extents) {
            let pd = dims_of(e);
            if d.geometry.point_count() != pd[0] * pd[1] * pd[2] {
                return Err(self.error(
                    format!("{pd:?} points (the summary's Extent {e:?})"),
                    format!("{} in {}", d.geometry.point_count(), piece.source.display()),
                ));
            }
            let off = [0, 1, 2].map(|a| (e[2 * a] - cover[2 * a]) as usize);
            match &d.geometry {
                Geometry::Image {
                    origin, spacing, ..
                } => {
                    let start =
                        [0, 1, 2].map(|a| self.origin[a] + e[2 * a] as f64 * self.spacing[a]);
                    let scale = (0..3)
                        .map(|a| self.spacing[a] * pd[a] as f64)
                        .fold(0.0, f64::max);
                    let agree = (0..3).all(|a| {
                        (origin[a] - start[a]).abs() <= 1e-9 * scale.max(1.0)
                            && (spacing[a] - self.spacing[a]).abs() <= 1e-9 * self.spacing[a]
                    });
                    if !agree {
                        return Err(self.error(
                            format!(
                                "a piece starting at {start:?} with spacing {:?}",
                                self.spacing
                            ),
                            format!("{origin:?}, {spacing:?} in {}", piece.source.display()),
                        ));
                    }
                }
                Geometry::Rectilinear { coords: c } => {
                    for a in 0..3 {
                        let span = c[a].last().copied().unwrap_or(0.0) - c[a][0];
                        for (k, &x) in c[a].iter().enumerate() {
                            let slot = &mut coords[a][off[a] + k];
                            if let Some(y) = *slot
                                && (x - y).abs() > 1e-9 * span.abs().max(1e-300)
                            {
                                return Err(self.error(
                                    format!("axis {a} coordinate {y} where pieces meet"),
                                    format!("{x} in {}", piece.source.display()),
                                ));
                            }
                            *slot = Some(x);
                        }
                    }
                }
                Geometry::Structured { points: p, .. } => {
                    for_each_run(pd, dims, off, |src, dst, len| {
                        points[dst..dst + len].copy_from_slice(&p[src..src + len]);
                    });
                }
                _ => {}
            }
            for_each_run(pd, dims, off, |_, dst, len| {
                covered[dst..dst + len].iter_mut().for_each(|c| *c = true);
            });
            let pc = pd.map(|x| x.saturating_sub(1).max(1));
            for (out, a) in arrays
                .iter_mut()
                .zip(d.arrays.iter().filter(|a| a.name != "vtkGhostType"))
            {
                let (from, to) = match a.location {
                    Location::Point => (pd, dims),
                    Location::Cell => (pc, cdims),
                };
                for_each_run(from, to, off, |src, dst, len| {
                    copy_run(&mut out.values, dst, &a.values, src, len);
                });
            }
        }
        if let Some(hole) = covered.iter().position(|c| !c) {
            let (x, y, z) = (
                hole % dims[0],
                (hole / dims[0]) % dims[1],
                hole / (dims[0] * dims[1]),
            );
            return Err(self.error(
                format!("pieces covering the extent {cover:?}"),
                format!(
                    "no piece holding point ({}, {}, {})",
                    cover[0] + x as i64,
                    cover[2] + y as i64,
                    cover[4] + z as i64
                ),
            ));
        }
        let geometry = match self.kind {
            "ImageData" => Geometry::Image {
                dims,
                origin: [0, 1, 2].map(|a| self.origin[a] + cover[2 * a] as f64 * self.spacing[a]),
                spacing: self.spacing,
            },
            "RectilinearGrid" => Geometry::Rectilinear {
                coords: coords.map(|c| c.into_iter().map(|x| x.unwrap_or(0.0)).collect()),
            },
            _ => Geometry::Structured { dims, points },
        };
        Ok(Dataset { geometry, arrays })
    }

    /// Unstructured or point pieces, concatenated; duplicate ghost cells dropped.
    fn join_cells(&self, read: Vec<(&Piece, Dataset)>) -> Result<Dataset, DataError> {
        self.check_arrays(&read)?;
        let mut points: Vec<[f64; 3]> = Vec::new();
        let mut cells = Cells::default();
        let mut arrays: Vec<DataArray> = Vec::new();
        for (piece, d) in read {
            let first = points.len();
            let (p, c) = match d.geometry {
                Geometry::Unstructured { points, cells } => (points, Some(cells)),
                Geometry::Points { points } => (points, None),
                _ => (Vec::new(), None),
            };
            if (first + p.len()) as u64 > MAX_SAMPLES {
                return Err(self.error(
                    format!("at most {MAX_SAMPLES} points over all pieces"),
                    format!("more by {}", piece.source.display()),
                ));
            }
            points.extend(p);
            // Cells a neighbour owns (VTK's DUPLICATECELL bit), with ghost levels.
            let ghost = d
                .arrays
                .iter()
                .find(|a| a.name == "vtkGhostType" && a.location == Location::Cell);
            let keep: Vec<bool> = match (&c, ghost) {
                (Some(c), Some(g)) if self.ghost_level > 0 => (0..c.len())
                    .map(|i| (g.values.get(i) as u32) & 1 == 0)
                    .collect(),
                (Some(c), _) => vec![true; c.len()],
                (None, _) => Vec::new(),
            };
            if let Some(c) = &c {
                for i in (0..c.len()).filter(|&i| keep[i]) {
                    let shifted: Vec<u32> = c.cell(i).iter().map(|&v| v + first as u32).collect();
                    cells.push(c.types[i], &shifted);
                }
            }
            let kept: Vec<usize> = (0..keep.len()).filter(|&i| keep[i]).collect();
            let mut own = d.arrays.into_iter().filter(|a| a.name != "vtkGhostType");
            if arrays.is_empty() {
                arrays = own
                    .map(|a| match a.location {
                        Location::Cell => DataArray {
                            values: a.values.select(&kept),
                            ..a
                        },
                        Location::Point => a,
                    })
                    .collect();
                continue;
            }
            for out in &mut arrays {
                let Some(a) = own.next() else { break };
                out.values.append(match a.location {
                    Location::Cell => a.values.select(&kept),
                    Location::Point => a.values,
                });
            }
        }
        let geometry = match self.kind {
            "UnstructuredGrid" => Geometry::Unstructured { points, cells },
            _ => Geometry::Points { points },
        };
        Ok(Dataset { geometry, arrays })
    }
}

/// `len` zeros stored as `storage`.
fn filled(storage: super::Storage, len: usize) -> Values {
    match storage {
        super::Storage::F32 => Values::F32(vec![0.0; len]),
        super::Storage::U8 => Values::U8(vec![0; len]),
        super::Storage::I8 => Values::I8(vec![0; len]),
        super::Storage::U16 => Values::U16(vec![0; len]),
        super::Storage::I16 => Values::I16(vec![0; len]),
    }
}

/// Copies `len` values from `src[from..]` to `dst[to..]`; a source stored otherwise turns `dst`
/// into f32 first.
fn copy_run(dst: &mut Values, to: usize, src: &Values, from: usize, len: usize) {
    match (&mut *dst, src) {
        (Values::F32(d), Values::F32(s)) => d[to..to + len].copy_from_slice(&s[from..from + len]),
        (Values::U8(d), Values::U8(s)) => d[to..to + len].copy_from_slice(&s[from..from + len]),
        (Values::I8(d), Values::I8(s)) => d[to..to + len].copy_from_slice(&s[from..from + len]),
        (Values::U16(d), Values::U16(s)) => d[to..to + len].copy_from_slice(&s[from..from + len]),
        (Values::I16(d), Values::I16(s)) => d[to..to + len].copy_from_slice(&s[from..from + len]),
        (Values::F32(d), s) => {
            for k in 0..len {
                d[to + k] = s.get(from + k);
            }
        }
        (d, s) => {
            *d = Values::F32(d.as_f32().into_owned());
            copy_run(d, to, s, from, len);
        }
    }
}

/// Calls `f(source index, destination index, length)` for each x-run of a box of `from`
/// points placed at `off` in a grid of `to` points.
fn for_each_run(
    from: [usize; 3],
    to: [usize; 3],
    off: [usize; 3],
    mut f: impl FnMut(usize, usize, usize),
) {
    for z in 0..from[2] {
        for y in 0..from[1] {
            let src = (z * from[1] + y) * from[0];
            let dst = ((off[2] + z) * to[1] + off[1] + y) * to[0] + off[0];
            f(src, dst, from[0]);
        }
    }
}
