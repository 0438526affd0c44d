//! Scattered points: CSV and PLY (ASCII and binary); the first byte picks the format.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let name = if pick % 2 == 0 {
        "fuzz.csv"
    } else {
        "fuzz.ply"
    };
    let _ = vmls::data::parse_dataset_bytes(std::path::Path::new(name), rest);
});
