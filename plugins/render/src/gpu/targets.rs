//! Per-env render targets: the view uniforms and projection, camera targets and their readback,
//! the shadow map, and [`Targets`] (creation, camera slots, mapping and reading frames).

mod encode;

use std::sync::Arc;

use nalgebra::{Isometry3, Matrix4, Vector3};

use crate::config::{look_at, LightDesc};
use crate::geometry::FrameGeometry;
use crate::RenderError;

use super::device::{RenderDevice, COLOR_FORMAT, DATA_FORMAT, DEPTH_FORMAT};

/// The per-view uniform block (see `View` in shader.wgsl).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    light_view_proj: [[f32; 4]; 4],
    cam_pos: [f32; 4],
    cam_fwd: [f32; 4],
    light_dir: [f32; 4],
    params: [f32; 4],
}

fn columns(m: &Matrix4<f64>) -> [[f32; 4]; 4] {
    let mut out = [[0.0f32; 4]; 4];
    for (c, col) in out.iter_mut().enumerate() {
        for (r, x) in col.iter_mut().enumerate() {
            *x = m[(r, c)] as f32;
        }
    }
    out
}

/// Clip-from-camera matrix of a pinhole camera (optical frame; wgpu clip space, depth 0..1).
pub fn projection(
    width: u32,
    height: u32,
    (fx, fy, cx, cy): (f64, f64, f64, f64),
    near: f64,
    far: f64,
) -> Matrix4<f64> {
    let (w, h) = (width as f64, height as f64);
    Matrix4::new(
        2.0 * fx / w,
        0.0,
        2.0 * (cx + 0.5) / w - 1.0,
        0.0,
        0.0,
        -2.0 * fy / h,
        1.0 - 2.0 * (cy + 0.5) / h,
        0.0,
        0.0,
        0.0,
        far / (far - near),
        -far * near / (far - near),
        0.0,
        0.0,
        1.0,
        0.0,
    )
}

/// What a camera sees this frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSetup {
    /// `world_from_camera`, optical frame.
    pub world_from_camera: Isometry3<f64>,
    /// `(fx, fy, cx, cy)`, px.
    pub pinhole: (f64, f64, f64, f64),
    /// Image size, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Clipping distances, m.
    pub near: f64,
    /// Far clipping distance, m.
    pub far: f64,
    /// Draw target markers.
    pub markers: bool,
    /// Draw contact and grasp markers.
    pub overlays: bool,
}

/// A rendered camera image, flat and row-major (row 0 at the top).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraFrame {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Colour, `height x width x 3` u8 (sRGB).
    pub rgb: Vec<u8>,
    /// Depth along the optical axis, `height x width` f32 metres; 0 where nothing was hit.
    pub depth: Vec<f32>,
    /// Object id per pixel, `height x width` (object index + 1; 0 = background or no object).
    pub segmentation: Vec<u32>,
    /// `world_from_camera` (optical frame: x right, y down, z forward) at render time.
    pub world_from_camera: Isometry3<f64>,
    /// Intrinsics `(fx, fy, cx, cy)`, px.
    pub pinhole: (f64, f64, f64, f64),
}

fn align(x: u32, to: u32) -> u32 {
    x.div_ceil(to) * to
}

/// Render targets and readback of one camera slot.
pub(crate) struct CameraTarget {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) color: wgpu::Texture,
    data: wgpu::Texture,
    color_view: wgpu::TextureView,
    data_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    uniform: wgpu::Buffer,
    /// Bind group and the shadow-map generation it was made for.
    bind: (u64, wgpu::BindGroup),
    readback: wgpu::Buffer,
    color_row: u32,
    data_row: u32,
    data_offset: u64,
    last: Option<ViewSetup>,
}

/// The shadow map of one env.
struct ShadowMap {
    size: u32,
    view: wgpu::TextureView,
    uniform: wgpu::Buffer,
    bind: wgpu::BindGroup,
}

/// One env's GPU state.
pub struct Targets {
    device: Arc<RenderDevice>,
    vertices: Option<(wgpu::Buffer, u64)>,
    indices: Option<(wgpu::Buffer, u64)>,
    shadow: ShadowMap,
    /// Bumped whenever the shadow map is replaced.
    generation: u64,
    pub(crate) cameras: Vec<(String, CameraTarget)>,
    background: [f32; 3],
    light: LightDesc,
}

/// A 2-D texture of one mip level and sample.
pub(crate) fn texture(
    device: &wgpu::Device,
    label: &str,
    w: u32,
    h: u32,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

fn grow_buffer(
    device: &wgpu::Device,
    slot: &mut Option<(wgpu::Buffer, u64)>,
    bytes: u64,
    usage: wgpu::BufferUsages,
) {
    if slot.as_ref().is_some_and(|(_, cap)| *cap >= bytes) {
        return;
    }
    let cap = bytes.next_power_of_two().max(4096);
    *slot = Some((
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("geometry"),
            size: cap,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }),
        cap,
    ));
}

impl ShadowMap {
    fn new(device: &RenderDevice, size: u32) -> Self {
        let d = &device.device;
        let tex = texture(
            d,
            "shadow map",
            size,
            size,
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let uniform = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("shadow view"),
            size: std::mem::size_of::<ViewUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shadow view"),
            layout: &device.pipelines.shadow_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        Self {
            size,
            view: tex.create_view(&Default::default()),
            uniform,
            bind,
        }
    }
}

/// The shadow-map resolution for cameras whose largest side is `side` px: the next power of
/// two, in 256..=2048 (shadow texels cost as much as camera pixels on a software rasteriser).
pub fn auto_shadow_map(side: u32) -> u32 {
    side.next_power_of_two().clamp(256, 2048)
}

impl Targets {
    /// GPU state for one env (the shadow map is sized on first use).
    pub fn new(device: Arc<RenderDevice>, light: &LightDesc, background: [f32; 3]) -> Self {
        let shadow = ShadowMap::new(&device, 1);
        Self {
            shadow,
            generation: 0,
            device,
            vertices: None,
            indices: None,
            cameras: Vec::new(),
            background,
            light: light.clone(),
        }
    }

    /// Resizes the shadow map for this frame's views (camera bind groups follow).
    fn fit_shadow_map(&mut self, views: &[(usize, ViewSetup)]) {
        let side = views
            .iter()
            .map(|(_, v)| v.width.max(v.height))
            .max()
            .unwrap_or(1);
        let size = match self.light.shadow_map {
            Some(0) => 1,
            Some(n) => n,
            None => auto_shadow_map(side),
        };
        if size != self.shadow.size {
            self.shadow = ShadowMap::new(&self.device, size);
            self.generation += 1;
        }
    }

    fn camera_bind(&self, uniform: &wgpu::Buffer) -> wgpu::BindGroup {
        let dev = &self.device;
        dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("camera view"),
            layout: &dev.pipelines.view_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniform.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&self.shadow.view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(&dev.pipelines.compare_sampler),
                },
            ],
        })
    }

    /// The device these targets live on.
    pub fn device(&self) -> &Arc<RenderDevice> {
        &self.device
    }

    /// The slot of camera `name` at this size (created or resized as needed).
    pub(crate) fn slot(&mut self, name: &str, width: u32, height: u32) -> usize {
        if let Some(i) = self.cameras.iter().position(|(n, _)| n == name) {
            let t = &self.cameras[i].1;
            if t.width == width && t.height == height {
                return i;
            }
            self.cameras.remove(i);
        }
        let t = self.new_camera(width, height);
        self.cameras.push((name.to_string(), t));
        self.cameras.len() - 1
    }

    fn new_camera(&self, width: u32, height: u32) -> CameraTarget {
        let dev = &self.device;
        let d = &dev.device;
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::TEXTURE_BINDING;
        let color = texture(d, "colour", width, height, COLOR_FORMAT, usage);
        let data = texture(d, "depth+segmentation", width, height, DATA_FORMAT, usage);
        let depth = texture(
            d,
            "z-buffer",
            width,
            height,
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let uniform = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("camera view"),
            size: std::mem::size_of::<ViewUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = (self.generation, self.camera_bind(&uniform));
        let color_row = align(width * 4, wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let data_row = align(width * 8, wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let data_offset = align(color_row * height, 256) as u64;
        let readback = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: data_offset + (data_row * height) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        CameraTarget {
            width,
            height,
            color_view: color.create_view(&Default::default()),
            data_view: data.create_view(&Default::default()),
            color,
            data,
            depth_view: depth.create_view(&Default::default()),
            uniform,
            bind,
            readback,
            color_row,
            data_row,
            data_offset,
            last: None,
        }
    }

    fn light_view_proj(&self, geom: &FrameGeometry) -> (Matrix4<f64>, f64) {
        let (lo, hi) = geom
            .focus
            .unwrap_or((Vector3::repeat(-1.0), Vector3::repeat(1.0)));
        let c = 0.5 * (lo + hi);
        let r = (0.5 * (hi - lo).norm()).max(0.25) * 1.05;
        let d = Vector3::from(self.light.direction).normalize();
        let eye = c - d * (2.0 * r);
        let light_from_world = look_at(&eye, &c, &Vector3::z()).inverse().to_homogeneous();
        let ortho = Matrix4::new(
            1.0 / r,
            0.0,
            0.0,
            0.0,
            0.0,
            -1.0 / r,
            0.0,
            0.0,
            0.0,
            0.0,
            0.5 / r,
            -0.5,
            0.0,
            0.0,
            0.0,
            1.0,
        );
        (ortho * light_from_world, r)
    }

    /// Starts mapping the readback buffer of `slot` (after the submit).
    pub(crate) fn map(&self, slot: usize, done: std::sync::mpsc::Sender<Result<(), String>>) {
        self.cameras[slot]
            .1
            .readback
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |r| {
                let _ = done.send(r.map_err(|e| e.to_string()));
            });
    }

    /// Reads a mapped slot into a frame and unmaps it.
    pub(crate) fn read(&self, slot: usize) -> Result<CameraFrame, RenderError> {
        let t = &self.cameras[slot].1;
        let view = t
            .last
            .ok_or_else(|| RenderError::Device("camera read before render".into()))?;
        let (w, h) = (t.width as usize, t.height as usize);
        let mut frame = CameraFrame {
            width: t.width,
            height: t.height,
            rgb: Vec::with_capacity(w * h * 3),
            depth: Vec::with_capacity(w * h),
            segmentation: Vec::with_capacity(w * h),
            world_from_camera: view.world_from_camera,
            pinhole: view.pinhole,
        };
        {
            let bytes = t
                .readback
                .get_mapped_range(..)
                .map_err(|e| RenderError::Device(format!("readback: {e}")))?;
            for y in 0..h {
                let row = &bytes[y * t.color_row as usize..][..w * 4];
                for px in row.chunks_exact(4) {
                    frame.rgb.extend_from_slice(&px[..3]);
                }
                let row = &bytes[t.data_offset as usize + y * t.data_row as usize..][..w * 8];
                for px in row.chunks_exact(8) {
                    let d = u32::from_le_bytes([px[0], px[1], px[2], px[3]]);
                    let s = u32::from_le_bytes([px[4], px[5], px[6], px[7]]);
                    frame.depth.push(f32::from_bits(d));
                    frame.segmentation.push(s);
                }
            }
        }
        t.readback.unmap();
        Ok(frame)
    }

    /// The colour texture of `slot` (the viewer draws it to its window).
    pub(crate) fn color_texture(&self, slot: usize) -> &wgpu::Texture {
        &self.cameras[slot].1.color
    }
}
