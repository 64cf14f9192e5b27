//! Fuzz target: `rendiff::fuzz::obj_bytes` (see src/fuzz.rs).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    rendiff::fuzz::obj_bytes(data);
});
