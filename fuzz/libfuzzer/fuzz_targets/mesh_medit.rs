//! libFuzzer target: `modesuite_engine::shapes::load_volume_bytes` on a `.mesh` file, then the
//! boundary of what loaded.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(v) = modesuite_engine::shapes::load_volume_bytes(Path::new("f.mesh"), data) {
        let _ = v.mesh.boundary_surface_compact();
    }
});
