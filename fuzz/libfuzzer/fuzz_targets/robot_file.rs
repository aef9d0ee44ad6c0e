//! libFuzzer target: `modesuite_robots::description::RobotFile::parse` (`*.robot.ron`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = modesuite_robots::description::RobotFile::parse(text, "f.robot.ron");
    }
});
