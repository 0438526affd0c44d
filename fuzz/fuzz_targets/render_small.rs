//! Shared by the targets that go past parsing: a dataset of at most 4096 points renders a 6×6
//! image with the f64 CPU twins, within a small work budget, without NaN and without panicking.

use std::path::Path;
use vmls::data::dataset::Dataset;
use vmls::scene::Scene;

/// Renders `dataset` (parsed from the file `name`) as `vmls render` would, seen from outside
/// its box; returns quietly where the scene or field refuses it (that is an error message, not a
/// finding), asserts every pixel finite.
pub fn render_small(name: &str, dataset: &Dataset) {
    if dataset.geometry.point_count() > 4096 {
        return;
    }
    let path = Path::new(name);
    let overrides = [
        format!("volume.file=\"{name}\""),
        "camera.width=6".into(),
        "camera.height=6".into(),
        "render.step=0.5".into(),
    ];
    let Ok(mut scene) = Scene::parse("", "fuzz", Path::new("."), &overrides) else {
        return;
    };
    let Ok(field) = scene.field_from_dataset(dataset, path, |_| {}) else {
        return;
    };
    let (lo, hi) = field.bounds();
    let centre = field.frame_origin + 0.5 * (lo + hi);
    let reach = (hi - lo).length().max(1e-9);
    scene.camera.target = centre.to_array();
    scene.camera.eye = (centre + reach * glam::DVec3::new(1.6, 1.3, 1.1)).to_array();
    let Ok(setup) = scene.ray_setup(&field) else {
        return;
    };
    if setup.check_budget(2e5).is_err() {
        return;
    }
    // 16² table entries per length: the table code and its scalar range (where the 1e30
    // constant-field NaN was found) run exactly as at 512², and building 64² tables was 80% of
    // a structure-aware target's time (perf: `segment_integral`), 9x fewer executions per second.
    // A deferred octree that cannot be built is a refused input, not a finding.
    let Ok(image) = vmls::raycast::raycast_frame(
        &setup,
        &field,
        &scene.transfer,
        scene.render.table_resolution.min(16),
    ) else {
        return;
    };
    for p in &image {
        assert!(p.rgba.iter().all(|c| c.is_finite()), "{name}: {:?}", p.rgba);
    }
}

/// The body of the structure-aware targets: the first byte decides whether a file that parses
/// is also rendered (one input in 16: rendering costs some 20 parses), the rest feeds `build`,
/// which returns the file and its name (the name picks the reader).
pub fn parse_built(
    data: &[u8],
    build: impl FnOnce(
        &mut libfuzzer_sys::arbitrary::Unstructured,
    ) -> libfuzzer_sys::arbitrary::Result<(Vec<u8>, &'static str)>,
) {
    let Some((&first, data)) = data.split_first() else {
        return;
    };
    let mut u = libfuzzer_sys::arbitrary::Unstructured::new(data);
    let Ok((file, name)) = build(&mut u) else {
        return;
    };
    if let Ok(dataset) = vmls::data::parse_dataset_bytes(Path::new(name), &file)
        && first % 16 == 7
    {
        render_small(name, &dataset);
    }
}
