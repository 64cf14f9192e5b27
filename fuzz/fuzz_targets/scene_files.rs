//! Fuzz target: `rendiff::fuzz::scene_files` (see src/fuzz.rs): scene text,
//! an OBJ and a PNG written to a fresh folder, loaded from disk, rendered,
//! exported to SDL (checked) and written.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    rendiff::fuzz::scene_files(data);
});
