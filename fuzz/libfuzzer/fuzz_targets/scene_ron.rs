//! libFuzzer target: `modesuite_engine::scene::parse_str` and, on success, compiling the scene
//! with an engine-only app (`EnginePlugins`: no robots, renderer or learning plugins).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(desc) = modesuite_engine::scene::parse_str(text, "f") {
            let mut app = modesuite_engine::SimApp::new();
            app.add_group(modesuite_engine::EnginePlugins);
            let _ = app.compile_scene(&desc, &modesuite_engine::SceneSource::in_memory("/tmp"));
        }
    }
});
