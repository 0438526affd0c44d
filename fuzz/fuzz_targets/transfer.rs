//! The transfer function's points (and isosurfaces) as the scene's `[transfer]` section reads
//! them; a function that parses must look up every value finitely.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(table) = format!("v = {text}").parse::<toml::Table>() else {
        return;
    };
    let Some(value) = table.get("v") else {
        return;
    };
    if let Ok(tf) = vmls::view::transfer::TransferFunction::from_toml(value) {
        for s in [-1e30, -1.0, 0.0, 0.25, 0.5, 1.0, 1e30] {
            let (rgb, tau) = tf.lookup(s);
            assert!(
                rgb.iter().all(|c| c.is_finite()) && tau.is_finite(),
                "{s}: {rgb:?} {tau}"
            );
        }
    }
});
