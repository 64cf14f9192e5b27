//! Fuzz target: `rendiff::fuzz::scene_text` (see src/fuzz.rs), with
//! relative paths resolved in the bundled `scenes/` folder.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    rendiff::fuzz::scene_text(&dir, data);
});
