//! The wgpu side: one [`RenderDevice`] (adapter, device, queue, pipelines) shared by every env
//! through an `Arc`, and per-env [`Targets`] (geometry buffers, shadow map, one set of render
//! targets and a readback buffer per camera).
//!
//! A frame is: upload the extracted geometry, draw the shadow map from the light, then per camera
//! one opaque pass into colour (`Rgba8UnormSrgb`) and data (`Rg32Uint`: linear depth bits,
//! segmentation id) targets, an optional translucent marker pass into colour only, and copies into
//! the readback buffer. Any number of envs and cameras go into one command buffer and one wait.
//!
//! Files: `device` (adapter, device, queue); `pipelines` (shaders, layouts, pipelines),
//! `targets` (per-env targets, views, readback) with `targets/encode` (recording a frame).

mod device;
mod pipelines;
mod targets;

pub use device::{quiet_device_select_without_session, RenderDevice, SOFTWARE_DRIVER_PACKAGES};
pub(crate) use targets::texture;
pub use targets::{auto_shadow_map, projection, CameraFrame, Targets, ViewSetup};

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector4;

    #[test]
    fn projection_matches_the_pinhole_model() {
        let (w, h) = (64, 48);
        let k = (50.0, 55.0, 30.0, 20.0);
        let p = projection(w, h, k, 0.1, 10.0);
        let x = Vector4::new(0.3, -0.2, 2.0, 1.0);
        let c = p * x;
        let (ndc_x, ndc_y, ndc_z) = (c.x / c.w, c.y / c.w, c.z / c.w);
        // Pixel u (pixel centres at integers) -> ndc x = 2 (u + 0.5) / w - 1.
        let u = k.0 * x.x / x.z + k.2;
        let v = k.1 * x.y / x.z + k.3;
        assert!((ndc_x - (2.0 * (u + 0.5) / w as f64 - 1.0)).abs() < 1e-12);
        assert!((ndc_y - (1.0 - 2.0 * (v + 0.5) / h as f64)).abs() < 1e-12);
        assert!(ndc_z > 0.0 && ndc_z < 1.0);
        let near = p * Vector4::new(0.0, 0.0, 0.1, 1.0);
        let far = p * Vector4::new(0.0, 0.0, 10.0, 1.0);
        assert!((near.z / near.w).abs() < 1e-12 && (far.z / far.w - 1.0).abs() < 1e-12);
    }
}
