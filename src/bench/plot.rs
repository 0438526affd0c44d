//! `speed_error.svg` / `.png`: error against frame time, log–log, one series per renderer and
//! method, the Pareto front marked and its points labelled with their settings; and, for runs
//! with `render.tolerance`, `tolerance.svg` / `.png`: measured against requested error.
//!
//! Time is the median GPU time from timestamp queries where a row has it, else its wall time
//! (peers without timestamps); error is the RMSE against the run's reference. Text is drawn
//! with DejaVu Sans embedded in the binary, so plots look the same on a bare machine.

use super::BenchError;
use super::results::{Row, pareto_front};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Smallest error drawn: a row identical to the reference sits on the bottom edge.
const ERROR_FLOOR: f64 = 1e-7;

/// A log–log chart on `root` with the project's margins, fonts and labels: each axis its
/// range and description, and the tick label formats of x and y.
#[allow(clippy::type_complexity)]
fn log_log<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    title: &str,
    (x, x_desc): (std::ops::Range<f64>, &str),
    (y, y_desc): (std::ops::Range<f64>, &str),
    (x_fmt, y_fmt): (fn(&f64) -> String, fn(&f64) -> String),
) -> Result<ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>, String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut chart = ChartBuilder::on(root)
        .margin(16)
        .caption(title, ("sans-serif", 20))
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(x.log_scale(), y.log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// The series legend in the project's style at `position`, then the drawing presented.
fn legend_and_present<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>,
    root: &DrawingArea<DB, Shift>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(position)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)
}

/// The (time, error) a row is drawn at, if it has both.
fn point(r: &Row) -> Option<(f64, f64)> {
    let t = r.gpu_ms.unwrap_or(r.wall_ms);
    let e = r.rmse?;
    (t.is_finite() && t > 0.0 && e.is_finite()).then_some((t, e.max(ERROR_FLOOR)))
}

/// The series a row belongs to.
fn series_name(r: &Row) -> String {
    if r.source == "vmls" {
        r.method.clone()
    } else {
        format!("{} ({})", r.method, r.source)
    }
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    rows: &[Row],
    title: &str,
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let points: Vec<(f64, f64)> = rows.iter().filter_map(point).collect();
    let bounds = |f: fn(&(f64, f64)) -> f64| {
        let lo = points.iter().map(f).fold(f64::INFINITY, f64::min);
        let hi = points.iter().map(f).fold(0.0, f64::max);
        if lo.is_finite() && hi > 0.0 {
            (lo * 0.6, hi * 1.7)
        } else {
            (1e-3, 1.0)
        }
    };
    let (t0, t1) = bounds(|p| p.0);
    let (e0, e1) = bounds(|p| p.1);
    let mut chart = log_log(
        &root,
        title,
        (
            t0..t1,
            "frame time, ms (GPU timestamps; wall time for peers without them)",
        ),
        (e0..e1, "RMSE against the reference"),
        (|v| format!("{v}"), |v| format!("{v:.1e}")),
    )?;
    let mut names: Vec<String> = rows.iter().map(series_name).collect();
    names.sort();
    names.dedup();
    for (k, name) in names.iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| series_name(r) == *name)
            .filter_map(point)
            .collect();
        let peer = rows
            .iter()
            .any(|r| series_name(r) == *name && r.source != "vmls");
        let anno = if peer {
            chart.draw_series(
                pts.iter()
                    .map(|&p| TriangleMarker::new(p, 7, color.filled()).into_dyn()),
            )
        } else {
            chart.draw_series(
                pts.iter()
                    .map(|&p| Circle::new(p, 5, color.filled()).into_dyn()),
            )
        }
        .map_err(err)?;
        anno.label(name.as_str())
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, color.filled()));
    }
    let front_rows: Vec<(&Row, (f64, f64))> = pareto_front(rows)
        .into_iter()
        .filter_map(|i| point(&rows[i]).map(|p| (&rows[i], p)))
        .collect();
    let front: Vec<(f64, f64)> = front_rows.iter().map(|(_, p)| *p).collect();
    chart
        .draw_series(LineSeries::new(
            front.iter().copied(),
            BLACK.stroke_width(1),
        ))
        .map_err(err)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK));
    chart
        .draw_series(
            front
                .iter()
                .map(|&p| Circle::new(p, 8, BLACK.stroke_width(1))),
        )
        .map_err(err)?;
    for (row, p) in front_rows {
        let text = format!("  {} {}", series_name(row), row.short_settings());
        chart
            .draw_series(std::iter::once(Text::new(
                text,
                p,
                ("sans-serif", 11).into_font().color(&BLACK),
            )))
            .map_err(err)?;
    }
    legend_and_present(&mut chart, &root, SeriesLabelPosition::UpperRight)
}

/// The plot as SVG text and as a 1100×750 PNG (`speed_error.svg`, `speed_error.png`).
pub fn speed_error_files(rows: &[Row], title: &str) -> Result<(Vec<u8>, Vec<u8>), BenchError> {
    files(rows, title, "speed_error", Plot::SpeedError)
}

/// `tolerance.svg` / `.png`: for the rows rendered to a `render.tolerance`, the measured p99
/// error against the requested E, log–log, one series per method, with the lines measured = E
/// (above it a case missed) and measured = E/10 (below it, over-accurate); a hollow marker is a
/// row whose tolerance reported itself not met.
pub fn tolerance_files(rows: &[Row], title: &str) -> Result<(Vec<u8>, Vec<u8>), BenchError> {
    files(rows, title, "tolerance", Plot::Tolerance)
}

/// Which plot [`files`] draws.
#[derive(Clone, Copy)]
enum Plot {
    SpeedError,
    Tolerance,
}

fn draw_plot<DB: DrawingBackend>(
    plot: Plot,
    root: DrawingArea<DB, Shift>,
    rows: &[Row],
    title: &str,
) -> Result<(), String> {
    match plot {
        Plot::SpeedError => draw(root, rows, title),
        Plot::Tolerance => draw_tolerance(root, rows, title),
    }
}

fn draw_tolerance<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    rows: &[Row],
    title: &str,
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let cases: Vec<(&Row, (f64, f64))> = rows
        .iter()
        .filter_map(|r| {
            let (e, m) = (r.tolerance?, r.p99?);
            (e > 0.0 && m.is_finite()).then_some((r, (e, m.max(ERROR_FLOOR))))
        })
        .collect();
    let lo = cases
        .iter()
        .map(|(_, (e, m))| (e / 10.0).min(*m))
        .fold(f64::INFINITY, f64::min);
    let hi = cases
        .iter()
        .map(|(_, (e, m))| e.max(*m))
        .fold(0.0, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > 0.0 {
        (lo * 0.5, hi * 2.0)
    } else {
        (1e-4, 1e-1)
    };
    let mut chart = log_log(
        &root,
        title,
        (lo..hi, "requested E (render.tolerance)"),
        (
            lo..hi,
            "measured: p99 of the RGBA error against the reference",
        ),
        (|v| format!("{v:.0e}"), |v| format!("{v:.0e}")),
    )?;
    for (factor, label) in [(1.0, "measured = E"), (0.1, "measured = E/10")] {
        let style = if factor == 1.0 {
            BLACK.stroke_width(2)
        } else {
            BLACK.mix(0.5).stroke_width(1)
        };
        chart
            // From where the line enters the square plot to where it leaves it.
            .draw_series(LineSeries::new(
                [(lo / factor, lo), (hi, hi * factor)],
                style,
            ))
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], style));
    }
    let mut names: Vec<String> = cases.iter().map(|(r, _)| series_name(r)).collect();
    names.sort();
    names.dedup();
    for (k, name) in names.iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let of = |met: bool| {
            cases
                .iter()
                .filter(move |(r, _)| series_name(r) == *name && r.tolerance_met != Some(!met))
                .map(|(_, p)| *p)
                .collect::<Vec<_>>()
        };
        chart
            .draw_series(
                of(true)
                    .into_iter()
                    .map(|p| Circle::new(p, 5, color.filled())),
            )
            .map_err(err)?
            .label(name.as_str())
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, color.filled()));
        chart
            .draw_series(
                of(false)
                    .into_iter()
                    .map(|p| Circle::new(p, 5, color.stroke_width(2))),
            )
            .map_err(err)?;
    }
    legend_and_present(&mut chart, &root, SeriesLabelPosition::UpperLeft)
}

/// `plot` as SVG text and as a 1100×750 PNG (`{stem}.svg`, `{stem}.png`).
fn files(
    rows: &[Row],
    title: &str,
    stem: &str,
    plot: Plot,
) -> Result<(Vec<u8>, Vec<u8>), BenchError> {
    crate::output::register_fonts();
    let (w, h) = (1100, 750);
    let (svg_name, png_name) = (format!("{stem}.svg"), format!("{stem}.png"));
    let err = |name: &str, message: String| BenchError::Io {
        path: name.into(),
        message,
    };
    let mut text = String::new();
    draw_plot(
        plot,
        SVGBackend::with_string(&mut text, (w, h)).into_drawing_area(),
        rows,
        title,
    )
    .map_err(|m| err(&svg_name, m))?;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw_plot(
        plot,
        BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area(),
        rows,
        title,
    )
    .map_err(|m| err(&png_name, m))?;
    let image = image::RgbImage::from_raw(w, h, rgb).ok_or_else(|| {
        err(
            &png_name,
            "the plot's pixel buffer does not match its size".into(),
        )
    })?;
    let mut png = Vec::new();
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| err(&png_name, e.to_string()))?;
    Ok((text.into_bytes(), png))
}
