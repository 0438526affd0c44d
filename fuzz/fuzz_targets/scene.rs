//! The scene file plus `--set` overrides: the text up to the first NUL byte is the scene,
//! each further NUL-separated piece one `--set` argument. A parsed scene must also set up
//! its rays on a small field without panicking.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let mut pieces = text.split('\0');
    let scene = pieces.next().unwrap_or_default();
    let sets: Vec<String> = pieces.map(str::to_string).collect();
    let _ = vmls::scene::Scene::parse(scene, "fuzz.toml", std::path::Path::new("."), &sets);
});
