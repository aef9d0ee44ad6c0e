//! libFuzzer target: `modesuite_robots::urdf::parse_urdf` (urdf-rs parsing and validation).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let assets = modesuite_robots::urdf::AssetPaths::new("/tmp");
        let _ = modesuite_robots::urdf::parse_urdf(text, "f.urdf", Path::new("/tmp"), &assets);
    }
});
