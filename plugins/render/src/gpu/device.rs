//! The graphics device: adapter choice, the device and queue, and the pipelines created once per
//! device.

use std::future::Future;
use std::sync::{Arc, OnceLock};

use crate::RenderError;

/// Depth format of the z-buffer and the shadow map.
pub(super) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Colour target format (the shader writes linear colour; the target stores sRGB).
pub(crate) const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Depth bits and segmentation id.
pub(super) const DATA_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rg32Uint;

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
