//! `results.csv` and `results.json`: one row per measured configuration, with stable columns.
//!
//! The CSV columns are the fields of [`Row`] in declaration order; their names and meanings are
//! part of the contract (BENCHMARKS.md documents them) so that rows measured elsewhere — another
//! device, or a peer renderer such as `tools/peer-vtk` — can be merged with `--import`. Times are
//! milliseconds, memory bytes; a quantity that does not apply to a row (evaluations of a splatting
//! frame, GPU time of a CPU peer) is empty in the CSV and `null` in the JSON.

use super::BenchError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One configuration's measurements.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Who rendered it: `vmls`, or a peer (`vtk`), or what `--import` read.
    pub source: String,
    /// Series name in the plot: the method (`fixed`, `splat`, …) or the peer's renderer.
    pub method: String,
    /// The configuration's overrides, `key=value` joined by `;` (empty: the scene as written).
    pub settings: String,
    pub device: String,
    pub driver: String,
    pub vmls_version: String,
    pub commit: String,
    pub width: u32,
    pub height: u32,
    /// Timed frames (after the first frame and the warm-up frames).
    pub frames: u32,
    /// GPU time of a whole frame from timestamp queries: median, smallest, largest.
    pub gpu_ms: Option<f64>,
    pub gpu_ms_min: Option<f64>,
    pub gpu_ms_max: Option<f64>,
    /// Median GPU time per kernel, `name=ms` joined by `;` (e.g. `raycast=812.4`).
    pub kernel_ms: String,
    /// Wall time of a frame as the caller sees it (median of the timed frames).
    pub wall_ms: f64,
    /// The first frame with a fresh persistent renderer: upload, kernel compilation, tables,
    /// buffers and the render itself (wall), and its GPU time.
    pub first_frame_wall_ms: f64,
    pub first_frame_gpu_ms: Option<f64>,
    /// CPU preparation of the dataset before any GPU work (supports, octree), once per dataset.
    pub prepare_ms: f64,
    /// MLS evaluations per frame and per second of GPU time (ray casting only).
    pub evaluations: Option<u64>,
    pub evaluations_per_s: Option<f64>,
    /// Bytes written from the host to the device by the first frame (renderer creation
    /// included) and by one later frame.
    pub bytes_uploaded_first: Option<u64>,
    pub bytes_uploaded_next: Option<u64>,
    /// Error against the reference (see `metrics`).
    pub rmse: Option<f64>,
    pub max_abs: Option<f64>,
    pub max_x: Option<u32>,
    pub max_y: Option<u32>,
    pub psnr: Option<f64>,
    pub non_finite: Option<u64>,
    /// 99th percentile of the per-pixel RGBA error (`metrics::ImageError::p99`); missing from
    /// files written before it.
    #[serde(default)]
    pub p99: Option<f64>,
    /// With `render.tolerance`: E, the error its pilots estimated for the step they chose
    /// (beside the measured `p99`), and whether every share of E was shown to hold.
    #[serde(default)]
    pub tolerance: Option<f64>,
    #[serde(default)]
    pub tolerance_estimate: Option<f64>,
    #[serde(default)]
    pub tolerance_met: Option<bool>,
    /// The adaptive integrator's own estimate of the frame's error, in the measure of `p99`
    /// (`crate::renderer::GpuImage::error_estimate`, 99th percentile), beside it.
    #[serde(default)]
    pub error_estimate: Option<f64>,
    /// Share of the device's ceilings the frame's ray-casting kernel reached, by the cost model
    /// of [`super::ceiling`] against `probe_fma` and the gather ceiling of its loads
    /// (`probe_memory:coherent-texel-gather`, or `march-texel-gather` for the fast path),
    /// measured in the same run.
    /// Splatting rows: `splat_raster`'s shares of the FMA ceiling and of the streaming
    /// bandwidth (its broadcast record loads).
    /// `bound_by` names the larger (`fma`, `gather`, `texel-gather`, `march-texel-gather`,
    /// `stream`); all three are
    /// empty when the run skipped the ceilings.
    /// These three columns may be missing from imported files (rows written before them).
    #[serde(default)]
    pub fma_share: Option<f64>,
    #[serde(default)]
    pub memory_share: Option<f64>,
    /// Which of the two is larger (the names above).
    #[serde(default)]
    pub bound_by: String,
    /// What the error was measured against.
    pub reference: String,
    /// The shader variant's name.
    pub variant: String,
}

impl Row {
    /// The settings without the method (which names the row's series), for labels.
    pub fn short_settings(&self) -> String {
        self.settings
            .split(';')
            .filter(|s| !s.is_empty() && !s.starts_with("render.method="))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// The rows as CSV with a header line (`results.csv`).
pub fn csv_bytes(rows: &[Row]) -> Result<Vec<u8>, BenchError> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let err = |e: &dyn std::fmt::Display| BenchError::Io {
        path: "results.csv".into(),
        message: e.to_string(),
    };
    for r in rows {
        w.serialize(r).map_err(|e| err(&e))?;
    }
    w.into_inner().map_err(|e| err(&e))
}

/// Largest results file `read_csv` reads (a sweep writes a few hundred bytes per row).
pub const MAX_CSV_BYTES: u64 = 256 << 20;

/// Reads rows written as [`csv_bytes`] (by this or another machine, or by a peer script).
pub fn read_csv(path: &Path) -> Result<Vec<Row>, BenchError> {
    let bytes = crate::files::read_input(path, MAX_CSV_BYTES)?;
    let mut r = csv::Reader::from_reader(bytes.as_slice());
    r.deserialize()
        .enumerate()
        .map(|(i, row)| {
            row.map_err(|e| BenchError::Import {
                path: path.display().to_string(),
                line: i + 2,
                message: e.to_string(),
            })
        })
        .collect()
}

/// The rows with the run's context as pretty JSON and a newline (`results.json`).
pub fn json_bytes(context: &serde_json::Value, rows: &[Row]) -> Result<Vec<u8>, BenchError> {
    let value = serde_json::json!({ "run": context, "rows": rows });
    let mut text = serde_json::to_vec_pretty(&value).map_err(|e| BenchError::Io {
        path: "results.json".into(),
        message: e.to_string(),
    })?;
    text.push(b'\n');
    Ok(text)
}

/// The rows no other row beats on both GPU time and RMSE (ties kept), fastest first. Rows
/// without a finite time or error, or with non-finite pixels, are never on the front.
pub fn pareto_front(rows: &[Row]) -> Vec<usize> {
    let point = |r: &Row| match (r.gpu_ms.or(Some(r.wall_ms)), r.rmse) {
        (Some(t), Some(e)) if t.is_finite() && e.is_finite() && r.non_finite.unwrap_or(0) == 0 => {
            Some((t, e))
        }
        _ => None,
    };
    let mut front: Vec<usize> = (0..rows.len())
        .filter(|&i| {
            let Some((t, e)) = point(&rows[i]) else {
                return false;
            };
            !rows
                .iter()
                .filter_map(point)
                .any(|(t2, e2)| t2 <= t && e2 <= e && (t2 < t || e2 < e))
        })
        .collect();
    front.sort_by(|&a, &b| {
        let ta = point(&rows[a]).map_or(f64::INFINITY, |p| p.0);
        let tb = point(&rows[b]).map_or(f64::INFINITY, |p| p.0);
        ta.total_cmp(&tb)
    });
    front
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn row(method: &str, gpu_ms: f64, rmse: f64) -> Row {
        Row {
            source: "vmls".into(),
            method: method.into(),
            settings: String::new(),
            device: "d".into(),
            driver: "v".into(),
            vmls_version: "0".into(),
            commit: "c".into(),
            width: 2,
            height: 2,
            frames: 1,
            gpu_ms: Some(gpu_ms),
            gpu_ms_min: Some(gpu_ms),
            gpu_ms_max: Some(gpu_ms),
            kernel_ms: format!("raycast={gpu_ms}"),
            wall_ms: gpu_ms + 1.0,
            first_frame_wall_ms: 10.0,
            first_frame_gpu_ms: None,
            prepare_ms: 0.0,
            evaluations: None,
            evaluations_per_s: None,
            bytes_uploaded_first: Some(100),
            bytes_uploaded_next: None,
            rmse: Some(rmse),
            max_abs: Some(rmse * 3.0),
            max_x: Some(1),
            max_y: Some(0),
            psnr: Some(-20.0 * rmse.log10()),
            non_finite: Some(0),
            p99: Some(rmse * 2.0),
            tolerance: None,
            tolerance_estimate: None,
            tolerance_met: None,
            error_estimate: None,
            fma_share: Some(0.1),
            memory_share: None,
            bound_by: "fma".into(),
            reference: "r".into(),
            variant: "x".into(),
        }
    }

    #[test]
    fn front_keeps_only_undominated_rows() {
        let rows = vec![
            row("a", 10.0, 0.1),
            row("a", 20.0, 0.05),
            row("b", 15.0, 0.2), // slower and worse than the first
            row("b", 30.0, 0.01),
            row("c", 25.0, 0.05), // slower than the second at the same error
        ];
        assert_eq!(pareto_front(&rows), vec![0, 1, 3]);
        let mut bad = rows.clone();
        bad[0].non_finite = Some(2);
        assert_eq!(pareto_front(&bad), vec![2, 1, 3]);
    }

    #[test]
    fn csv_round_trip_keeps_every_column() {
        let dir = std::env::temp_dir().join(format!("vmls-results-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("r.csv");
        let mut rows = vec![row("fixed", 12.5, 0.03), row("splat", 3.0, 0.2)];
        rows[1].settings = "render.step=0.5;splat.slab=0.25".into();
        rows[1].gpu_ms = None;
        std::fs::write(&path, csv_bytes(&rows).expect("csv")).expect("write");
        assert_eq!(read_csv(&path).expect("read"), rows);
        std::fs::write(&path, "source,method\nvmls,fixed\n").expect("write");
        let err = read_csv(&path).expect_err("missing columns");
        assert!(err.to_string().contains("line 2"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
