//! NRRD (raw, text, gzip; attached data): parse and validate never panic.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = vmls::data::parse_dataset_bytes(std::path::Path::new("fuzz.nrrd"), data);
});
