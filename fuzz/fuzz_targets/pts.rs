#![no_main]
//! cargo-fuzz target: the pts reader must return a value or a typed error for any input.

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = trispline_fuzz::targets::run("pts", data);
});
