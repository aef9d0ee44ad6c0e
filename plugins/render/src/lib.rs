//! # modesuite-render
//!
//! Rendering for modesuite: headless RGB-D and segmentation cameras with wgpu, episode videos
//! and the interactive viewer with keyboard teleoperation.
//!
//! Status: empty. The engine foundation landed first; this crate is filled by the render issue
//! (wgpu is deliberately not a dependency yet, to keep the default build lean until it is used).
