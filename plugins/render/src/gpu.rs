//! The wgpu side: one [`RenderDevice`] (adapter, device, queue, pipelines) shared by every env
//! through an `Arc`, and per-env [`Targets`] (geometry buffers, shadow map, one set of render
//! targets and a readback buffer per camera).
//!
//! A frame is: upload the extracted geometry, draw the shadow map from the light, then per camera
//! one opaque pass into colour (`Rgba8UnormSrgb`) and data (`Rg32Uint`: linear depth bits,
//! segmentation id) targets, an optional translucent marker pass into colour only, and copies into
//! the readback buffer. Any number of envs and cameras go into one command buffer and one wait.

use std::future::Future;
use std::sync::{Arc, OnceLock};

use nalgebra::{Isometry3, Matrix4, Vector3};

use crate::config::{look_at, LightDesc};
use crate::geometry::{FrameGeometry, Vertex};
use crate::RenderError;

/// Depth format of the z-buffer and the shadow map.
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Colour target format (the shader writes linear colour; the target stores sRGB).
pub(crate) const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Depth bits and segmentation id.
const DATA_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rg32Uint;

/// The Debian packages that provide software adapters.
pub const SOFTWARE_DRIVER_PACKAGES: &str =
    "mesa-vulkan-drivers libvulkan1 (Vulkan, lavapipe) or libegl-mesa0 libgl1-mesa-dri (OpenGL, llvmpipe)";

/// Keeps Mesa's Vulkan device-select layer from looking for a Wayland session where there is
/// none. That implicit layer (installed with Mesa's Vulkan drivers, lavapipe's included) connects
/// to Wayland to pick a default GPU whenever an instance enables the Wayland surface extension, as
/// wgpu's do; without a session (`XDG_RUNTIME_DIR` unset: a headless machine, a container, CI)
/// libwayland prints `error: XDG_RUNTIME_DIR is invalid or not set in the environment.` to
/// stderr for every instance, which reads as a failure of the run. [`RenderDevice::new`] ranks
/// the adapters itself, so the layer is switched off (`NODEVICE_SELECT=1`, its manifest's
/// `disable_environment`) unless the user set that variable or chose a device with
/// `MESA_VK_DEVICE_SELECT`. Returns whether it switched the layer off.
///
/// It sets an environment variable: call it at the start of `main`, before other threads run.
pub fn quiet_device_select_without_session() -> bool {
    let unset = |k: &str| std::env::var_os(k).is_none();
    let off =
        unset("XDG_RUNTIME_DIR") && unset("NODEVICE_SELECT") && unset("MESA_VK_DEVICE_SELECT");
    if off {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    off
}

/// Runs a future to completion on this thread (wgpu's native futures resolve without an
/// executor; this parks until woken).
pub(crate) fn block_on<F: Future>(f: F) -> F::Output {
    struct Unpark(std::thread::Thread);
    impl std::task::Wake for Unpark {
        fn wake(self: Arc<Self>) {
            self.0.unpark();
        }
    }
    let waker = std::task::Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut cx = std::task::Context::from_waker(&waker);
    let mut f = std::pin::pin!(f);
    loop {
        match f.as_mut().poll(&mut cx) {
            std::task::Poll::Ready(v) => return v,
            std::task::Poll::Pending => std::thread::park(),
        }
    }
}

/// Pipelines and layouts, created once per device.
pub(crate) struct Pipelines {
    pub(crate) view_layout: wgpu::BindGroupLayout,
    pub(crate) shadow_layout: wgpu::BindGroupLayout,
    pub(crate) opaque: wgpu::RenderPipeline,
    pub(crate) markers: wgpu::RenderPipeline,
    pub(crate) overlays: wgpu::RenderPipeline,
    pub(crate) shadow: wgpu::RenderPipeline,
    pub(crate) compare_sampler: wgpu::Sampler,
}

/// A graphics device shared by every env and camera of a process (or a window's own).
pub struct RenderDevice {
    pub(crate) instance: wgpu::Instance,
    pub(crate) adapter: wgpu::Adapter,
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) pipelines: Pipelines,
    info: wgpu::AdapterInfo,
}

fn rank(info: &wgpu::AdapterInfo) -> (u8, u8) {
    let kind = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    };
    let backend = match info.backend {
        wgpu::Backend::Vulkan => 0,
        wgpu::Backend::Metal | wgpu::Backend::Dx12 => 1,
        _ => 2,
    };
    (kind, backend)
}

impl RenderDevice {
    /// The process-wide headless device, created on first use (GPU when there is one, else a
    /// software driver). Every env of the process shares it.
    pub fn shared() -> Result<Arc<RenderDevice>, RenderError> {
        static SHARED: OnceLock<Result<Arc<RenderDevice>, String>> = OnceLock::new();
        SHARED
            .get_or_init(|| {
                // Vulkan first (GPU drivers or lavapipe); GL (llvmpipe) only when Vulkan has no
                // adapter, which also keeps GL's EGL probing quiet. WGPU_BACKEND overrides.
                let from_env = wgpu::Backends::from_env();
                let order = match from_env {
                    Some(b) => vec![b],
                    None => vec![wgpu::Backends::VULKAN, wgpu::Backends::GL],
                };
                let mut last = String::new();
                for backends in order {
                    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
                        backends,
                        ..wgpu::InstanceDescriptor::new_without_display_handle_from_env()
                    });
                    match RenderDevice::new(instance, None) {
                        Ok(d) => return Ok(Arc::new(d)),
                        Err(e) => last = e.to_string(),
                    }
                }
                Err(last)
            })
            .clone()
            .map_err(RenderError::NoAdapter)
    }

    /// A device on the best adapter of `instance` (discrete > integrated > virtual > CPU;
    /// Vulkan first), able to present to `surface` when one is given.
    pub fn new(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<RenderDevice, RenderError> {
        let mut adapters = block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        if let Some(s) = surface {
            adapters.retain(|a| a.is_surface_supported(s));
        }
        adapters.sort_by_key(|a| rank(&a.get_info()));
        let Some(adapter) = adapters.into_iter().next() else {
            return Err(RenderError::NoAdapter(format!(
                "no graphics adapter found (tried Vulkan and OpenGL{}). On a machine without a GPU install a software driver: {SOFTWARE_DRIVER_PACKAGES}; scripts/setup.sh installs them on Debian/Ubuntu",
                if surface.is_some() { " with a window surface" } else { "" }
            )));
        };
        let info = adapter.get_info();
        let (device, queue) = block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("modesuite-render"),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| RenderError::Device(format!("{} ({:?}): {e}", info.name, info.backend)))?;
        let pipelines = Pipelines::new(&device);
        Ok(RenderDevice {
            instance,
            adapter,
            device,
            queue,
            pipelines,
            info,
        })
    }

    /// The wgpu instance the adapter came from (a window's surface must be created from it).
    pub fn instance(&self) -> &wgpu::Instance {
        &self.instance
    }

    /// Adapter name and backend, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)`.
    pub fn adapter_name(&self) -> String {
        format!("{} ({:?})", self.info.name, self.info.backend)
    }

    /// Whether the adapter is a software rasteriser.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }
}

fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    const ATTRS: [wgpu::VertexAttribute; 5] = wgpu::vertex_attr_array![
        0 => Float32x3, 1 => Float32x3, 2 => Unorm8x4, 3 => Uint32, 4 => Uint32
    ];
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &ATTRS,
    }
}

impl Pipelines {
    fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("modesuite-render shader"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let uniform_entry = wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let view_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[
                uniform_entry,
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
                    count: None,
                },
            ],
        });
        let shadow_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shadow view"),
            entries: &[uniform_entry],
        });
        let main_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("main"),
            bind_group_layouts: &[Some(&view_layout)],
            immediate_size: 0,
        });
        let shadow_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("shadow"),
            bind_group_layouts: &[Some(&shadow_layout)],
            immediate_size: 0,
        });
        let primitive = wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        };
        let depth = |write: bool, bias: wgpu::DepthBiasState| wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(write),
            depth_compare: Some(wgpu::CompareFunction::LessEqual),
            stencil: wgpu::StencilState::default(),
            bias,
        };
        let layouts = [Some(vertex_layout())];
        let vertex = |entry: &'static str| wgpu::VertexState {
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            buffers: &layouts,
        };
        let opaque = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("opaque"),
            layout: Some(&main_layout),
            vertex: vertex("vs_main"),
            primitive,
            depth_stencil: Some(depth(true, Default::default())),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[
                    Some(COLOR_FORMAT.into()),
                    Some(wgpu::ColorTargetState {
                        format: DATA_FORMAT,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    }),
                ],
            }),
            multiview_mask: None,
            cache: None,
        });
        // Translucent markers: colour only, tested against but not written to the z-buffer.
        // Contact and grasp markers: flat colour drawn over everything (they are often inside
        // or under the bodies that touch).
        let marker_pipeline = |label: &'static str, entry: &'static str, compare| {
            let mut depth_stencil = depth(false, Default::default());
            depth_stencil.depth_compare = Some(compare);
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&main_layout),
                vertex: vertex("vs_main"),
                primitive,
                depth_stencil: Some(depth_stencil),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: COLOR_FORMAT,
                        blend: Some(wgpu::BlendState::ALPHA_BLENDING),
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let markers = marker_pipeline("markers", "fs_marker", wgpu::CompareFunction::LessEqual);
        let overlays = marker_pipeline("overlays", "fs_overlay", wgpu::CompareFunction::Always);
        let shadow = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("shadow"),
            layout: Some(&shadow_pl),
            vertex: vertex("vs_shadow"),
            primitive,
            depth_stencil: Some(depth(
                true,
                wgpu::DepthBiasState {
                    constant: 2,
                    slope_scale: 2.0,
                    clamp: 0.0,
                },
            )),
            multisample: Default::default(),
            fragment: None,
            multiview_mask: None,
            cache: None,
        });
        let compare_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shadow"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        });
        Self {
            view_layout,
            shadow_layout,
            opaque,
            markers,
            overlays,
            shadow,
            compare_sampler,
        }
    }
}

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

    /// Uploads `geom` and records the shadow pass and, per `(slot, view)`, the camera passes and
    /// readback copies (`readback = false`: render only, e.g. for a window).
    pub(crate) fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        geom: &FrameGeometry,
        views: &[(usize, ViewSetup)],
        readback: bool,
    ) {
        self.fit_shadow_map(views);
        for (slot, _) in views {
            if self.cameras[*slot].1.bind.0 != self.generation {
                let bind = self.camera_bind(&self.cameras[*slot].1.uniform);
                self.cameras[*slot].1.bind = (self.generation, bind);
            }
        }
        let dev = self.device.clone();
        let (d, q) = (&dev.device, &dev.queue);
        let vbytes: &[u8] = bytemuck::cast_slice(&geom.vertices);
        let ibytes: &[u8] = bytemuck::cast_slice(&geom.indices);
        grow_buffer(
            d,
            &mut self.vertices,
            vbytes.len() as u64,
            wgpu::BufferUsages::VERTEX,
        );
        grow_buffer(
            d,
            &mut self.indices,
            ibytes.len() as u64,
            wgpu::BufferUsages::INDEX,
        );
        let (Some((vb, _)), Some((ib, _))) = (&self.vertices, &self.indices) else {
            return;
        };
        if !vbytes.is_empty() {
            q.write_buffer(vb, 0, vbytes);
        }
        if !ibytes.is_empty() {
            q.write_buffer(ib, 0, ibytes);
        }
        let shadows = self.shadow.size > 1;
        let (light_vp, r) = self.light_view_proj(geom);
        let texel_world = 2.0 * r / self.shadow.size as f64;
        let light_dir = Vector3::from(self.light.direction).normalize();
        let mut uniform = ViewUniform {
            view_proj: columns(&Matrix4::identity()),
            light_view_proj: columns(&light_vp),
            cam_pos: [0.0; 4],
            cam_fwd: [0.0, 0.0, 1.0, 0.0],
            light_dir: [
                light_dir.x as f32,
                light_dir.y as f32,
                light_dir.z as f32,
                self.light.ambient,
            ],
            params: [
                if shadows { 1.0 } else { 0.0 },
                1.0 / self.shadow.size as f32,
                (1.5 * texel_world) as f32,
                (0.5 / self.shadow.size as f64) as f32,
            ],
        };
        let opaque = 0..geom.opaque_indices;
        let target_range = geom.opaque_indices..geom.target_indices;
        let overlay_range = geom.target_indices..geom.indices.len() as u32;
        if shadows {
            q.write_buffer(&self.shadow.uniform, 0, bytemuck::bytes_of(&uniform));
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.shadow.view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            if !opaque.is_empty() {
                pass.set_pipeline(&dev.pipelines.shadow);
                pass.set_bind_group(0, &self.shadow.bind, &[]);
                pass.set_vertex_buffer(0, vb.slice(..));
                pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(opaque.clone(), 0, 0..1);
            }
        }
        let bg = self.background.map(|x| x as f64);
        for (slot, view) in views {
            let t = &mut self.cameras[*slot].1;
            t.last = Some(*view);
            let p = projection(t.width, t.height, view.pinhole, view.near, view.far);
            let vp = p * view.world_from_camera.inverse().to_homogeneous();
            let pos = view.world_from_camera.translation.vector;
            let fwd = view.world_from_camera.rotation * Vector3::z();
            uniform.view_proj = columns(&vp);
            uniform.cam_pos = [pos.x as f32, pos.y as f32, pos.z as f32, 1.0];
            uniform.cam_fwd = [fwd.x as f32, fwd.y as f32, fwd.z as f32, 0.0];
            q.write_buffer(&t.uniform, 0, bytemuck::bytes_of(&uniform));
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("camera"),
                    color_attachments: &[
                        Some(wgpu::RenderPassColorAttachment {
                            view: &t.color_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color {
                                    r: bg[0],
                                    g: bg[1],
                                    b: bg[2],
                                    a: 1.0,
                                }),
                                store: wgpu::StoreOp::Store,
                            },
                        }),
                        Some(wgpu::RenderPassColorAttachment {
                            view: &t.data_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                                store: wgpu::StoreOp::Store,
                            },
                        }),
                    ],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &t.depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                if !opaque.is_empty() {
                    pass.set_pipeline(&dev.pipelines.opaque);
                    pass.set_bind_group(0, &t.bind.1, &[]);
                    pass.set_vertex_buffer(0, vb.slice(..));
                    pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(opaque.clone(), 0, 0..1);
                }
            }
            let ranges = [
                (view.markers, &target_range),
                (view.overlays, &overlay_range),
            ];
            if ranges.iter().any(|(on, r)| *on && !r.is_empty()) {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("markers"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &t.color_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &t.depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                pass.set_bind_group(0, &t.bind.1, &[]);
                pass.set_vertex_buffer(0, vb.slice(..));
                pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                let pipelines = [&dev.pipelines.markers, &dev.pipelines.overlays];
                for ((on, r), pipeline) in ranges.iter().zip(pipelines) {
                    if *on && !r.is_empty() {
                        pass.set_pipeline(pipeline);
                        pass.draw_indexed((*r).clone(), 0, 0..1);
                    }
                }
            }
            if readback {
                let size = wgpu::Extent3d {
                    width: t.width,
                    height: t.height,
                    depth_or_array_layers: 1,
                };
                for (tex, offset, row) in [
                    (&t.color, 0, t.color_row),
                    (&t.data, t.data_offset, t.data_row),
                ] {
                    encoder.copy_texture_to_buffer(
                        tex.as_image_copy(),
                        wgpu::TexelCopyBufferInfo {
                            buffer: &t.readback,
                            layout: wgpu::TexelCopyBufferLayout {
                                offset,
                                bytes_per_row: Some(row),
                                rows_per_image: Some(t.height),
                            },
                        },
                        size,
                    );
                }
            }
        }
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
