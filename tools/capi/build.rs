//! Generates include/vmls.h from the crate's `extern "C"` items with cbindgen, and rewrites it
//! only when it changed (so that a build leaves a committed, current header untouched).

fn main() {
    let dir = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_else(|_| ".".into());
    println!("cargo:rerun-if-changed=src/lib.rs");
    println!("cargo:rerun-if-changed=cbindgen.toml");
    let config = match cbindgen::Config::from_file(format!("{dir}/cbindgen.toml")) {
        Ok(c) => c,
        Err(e) => panic!("tools/capi/cbindgen.toml: {e}"),
    };
    let bindings = match cbindgen::generate_with_config(&dir, config) {
        Ok(b) => b,
        Err(e) => panic!("cbindgen could not read tools/capi/src/lib.rs: {e}"),
    };
    let path = format!("{dir}/include/vmls.h");
    let mut text = Vec::new();
    bindings.write(&mut text);
    if std::fs::read(&path).ok().as_deref() != Some(text.as_slice())
        && let Err(e) = std::fs::write(&path, &text)
    {
        panic!("{path}: {e}");
    }
}
