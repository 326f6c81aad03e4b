#![no_main]
//! cargo-fuzz target: the pcd reader must return a value or a typed error for any input.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = trispline_fuzz::targets::run("pcd", data);
});
