//! libFuzzer target: `modesuite_engine::shapes::load_surface_bytes` on a `.obj` file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = modesuite_engine::shapes::load_surface_bytes(Path::new("f.obj"), data);
});
