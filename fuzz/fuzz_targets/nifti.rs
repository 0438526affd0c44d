//! NIfTI-1 (.nii and gzip-compressed .nii.gz): the first byte picks which.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let name = if pick % 2 == 0 {
        "fuzz.nii"
    } else {
        "fuzz.nii.gz"
    };
    let _ = vmls::data::parse_dataset_bytes(std::path::Path::new(name), rest);
});
