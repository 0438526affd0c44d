//! The parse → render path: any file that parses (the first byte picks the format) and holds
//! at most 4096 samples renders a 6×6 image with the f64 CPU twins, within a small work
//! budget, without NaN and without panicking.
#![no_main]
use std::path::Path;
use vmls::scene::Scene;

const FORMATS: [&str; 9] = ["vtk", "vti", "vtr", "vts", "vtu", "vtp", "nrrd", "csv", "ply"];

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let name = format!("fuzz.{}", FORMATS[usize::from(pick) % FORMATS.len()]);
    let path = Path::new(&name);
    let Ok(dataset) = vmls::data::parse_dataset_bytes(path, rest) else {
        return;
    };
    if dataset.geometry.point_count() > 4096 {
        return;
    }
    let set = format!("volume.file=\"{name}\"");
    let overrides = [
        set,
        "camera.width=6".into(),
        "camera.height=6".into(),
        "render.step=0.5".into(),
    ];
    let Ok(mut scene) = Scene::parse("", "fuzz", Path::new("."), &overrides) else {
        return;
    };
    let Ok(field) = scene.field_from_dataset(&dataset, path, |_| {}) else {
        return;
    };
    // Look at the data from outside its box.
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
    let tables = vmls::render::build_tables(
        &setup,
        &field,
        &scene.transfer,
        scene.render.table_resolution.min(64),
        |_| {},
    );
    let image =
        vmls::render::raycast::raycast_image(&setup, &field, &scene.transfer, tables.as_ref());
    for p in &image {
        assert!(p.rgba.iter().all(|c| c.is_finite()), "{name}: {:?}", p.rgba);
    }
});

