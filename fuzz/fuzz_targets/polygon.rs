//! Fuzz target: `rendiff::fuzz::polygon` (see src/fuzz.rs).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    rendiff::fuzz::polygon(data);
});
