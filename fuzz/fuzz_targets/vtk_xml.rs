//! VTK XML (.vti/.vtr/.vts/.vtu/.vtp; ASCII, base64, zlib, appended): the first byte picks the
//! extension, the rest is the file.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let ext = ["vti", "vtr", "vts", "vtu", "vtp"][usize::from(pick) % 5];
    let path = std::path::PathBuf::from(format!("fuzz.{ext}"));
    let _ = vmls::data::parse_dataset_bytes(&path, rest);
});
