//! The parse → render path: any file that parses (the first byte picks the format) and holds
//! at most 4096 samples renders a 6×6 image with the f64 CPU twins, within a small work
//! budget, without NaN and without panicking.
#![no_main]
// `parse_built` serves the structure-aware targets only.
#[allow(dead_code)]
mod render_small;

const FORMATS: [&str; 9] = [
    "vtk", "vti", "vtr", "vts", "vtu", "vtp", "nrrd", "csv", "ply",
];

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let name = format!("fuzz.{}", FORMATS[usize::from(pick) % FORMATS.len()]);
    if let Ok(dataset) = vmls::data::parse_dataset_bytes(std::path::Path::new(&name), rest) {
        render_small::render_small(&name, &dataset);
    }
});
