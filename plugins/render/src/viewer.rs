//! The interactive viewer (`modesuite view`): a winit window showing an env through an orbit
//! camera, with pause/step/reset, keyboard teleoperation and episode recording.
//!
//! Keys: `space` pause, `n` one step while paused, `r` reset (next seed), arrows / left-drag
//! orbit, `+`/`-` / wheel zoom, `m` target markers, `x` contact (red) and grasp (yellow) markers,
//! `t` heads-up text, `c` cycle the scene's cameras and the orbit camera, `p` screenshot (PNG, as
//! the window shows it), `esc` quit. Teleoperation ([`TeleopAction`]): `w a s d` body, `q e`
//! turn, `i k j l` hand forward/back/left/right, `u o` hand up/down, `g` grasp, `h` release.
//! The heads-up text (top left) and the window title show time, step, reward, return, success,
//! the last action and frame rate.
//!
//! The scene is rendered by the same [`EnvRenderer`] as the headless cameras (into an offscreen
//! texture) and drawn to the window with a full-screen triangle, the heads-up text (an RGBA
//! texture rasterised by [`crate::hud`]) composited in the same pass.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use modesuite_engine::env::Space;
use modesuite_engine::{Env, SimClock};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::config::CameraDesc;
use crate::gpu::RenderDevice;
use crate::renderer::{EnvRenderer, Orbit};
use crate::teleop::{Recording, TeleopAction, TeleopCommand, TeleopKeys};
use crate::RenderError;

/// Options of [`run_viewer`].
#[derive(Debug, Clone)]
pub struct ViewerOptions {
    /// Shown in the title and written into recordings.
    pub label: String,
    /// Seed of the first episode (each reset uses the next).
    pub seed: u64,
    /// Write the teleoperation recording here on exit.
    pub record: Option<PathBuf>,
    /// Folder for screenshots (`p`), default the current folder.
    pub screenshot_dir: PathBuf,
    /// Initial window size, px.
    pub size: (u32, u32),
    /// Start paused.
    pub paused: bool,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        Self {
            label: "scene".into(),
            seed: 0,
            record: None,
            screenshot_dir: PathBuf::from("."),
            size: (960, 640),
            paused: false,
        }
    }
}

/// What a viewer session did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ViewerSummary {
    /// Env steps taken.
    pub steps: u64,
    /// Frames drawn.
    pub frames: u64,
    /// Screenshots written.
    pub screenshots: Vec<PathBuf>,
    /// Teleoperation actions issued.
    pub actions: u64,
}

struct Gpu {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    renderer: EnvRenderer,
    blit: wgpu::RenderPipeline,
    blit_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// The heads-up text image and its size (1 x 1 transparent when the text is off).
    hud: Option<(wgpu::Texture, u32, u32)>,
}

struct Viewer {
    env: Env,
    opts: ViewerOptions,
    gpu: Option<Gpu>,
    error: Option<RenderError>,
    orbit: Orbit,
    /// Scene bounds at start (the orbit's centre and scale stay fixed while things move).
    bounds: Option<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)>,
    markers: bool,
    /// Contact and grasp markers.
    overlays: bool,
    /// The heads-up text (reward, success, step, action).
    hud: bool,
    /// 0 = orbit camera, i = scene camera i - 1.
    camera: usize,
    paused: bool,
    step_once: bool,
    reset: bool,
    pending: std::collections::VecDeque<TeleopAction>,
    last_action: Option<TeleopAction>,
    screenshot: bool,
    discrete: bool,
    act_dim: usize,
    seed: u64,
    recording: Recording,
    episode_return: f64,
    last_reward: f64,
    success: Option<bool>,
    sim_clock: Instant,
    sim_debt: f64,
    fps: (Instant, u64, f64),
    drag: Option<(f64, f64)>,
    cursor: (f64, f64),
    summary: ViewerSummary,
    on_episode: Option<EpisodeHook>,
}

/// Called with each teleoperated episode that ended (by the env, by a reset, or by closing the
/// viewer) and has at least one key; an error is printed and the viewer goes on.
pub type EpisodeHook = Box<dyn FnMut(&crate::teleop::RecordedEpisode) -> Result<(), String>>;

impl Viewer {
    /// Hands the current episode to the hook, if it has keys.
    fn episode_ended(&mut self) {
        let (Some(hook), Some(ep)) = (self.on_episode.as_mut(), self.recording.episodes.last())
        else {
            return;
        };
        if ep.actions.is_empty() {
            return;
        }
        if let Err(e) = hook(ep) {
            eprintln!("modesuite view: episode of seed {} not saved: {e}", ep.seed);
        }
    }
}

/// Opens a window on `env` (its scene spawned) and runs until the window closes or `esc`;
/// returns what happened and the env in its final state.
pub fn run_viewer(env: Env, opts: ViewerOptions) -> Result<(ViewerSummary, Env), RenderError> {
    run_viewer_with(env, opts, None)
}

/// [`run_viewer`], handing each teleoperated episode to `on_episode` when it ends (`view
/// --record-dataset` appends it to a dataset).
pub fn run_viewer_with(
    mut env: Env,
    opts: ViewerOptions,
    on_episode: Option<EpisodeHook>,
) -> Result<(ViewerSummary, Env), RenderError> {
    if env.app.scene().is_none() {
        return Err(RenderError::Device(
            "view: the env has no spawned scene".into(),
        ));
    }
    let event_loop = EventLoop::new().map_err(|e| {
        RenderError::Device(format!(
            "cannot open a window ({e}); the viewer needs a display (X11: set DISPLAY, or run under Xvfb: xvfb-run modesuite view ...)"
        ))
    })?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let spaces = env.spaces();
    let discrete = matches!(spaces.action, Space::Discrete { n } if n >= 14);
    env.autoreset = false;
    env.reset(Some(opts.seed));
    env.app.world.insert_resource(TeleopCommand::default());
    let mut recording = Recording::new(&opts.label);
    recording.start_episode(opts.seed);
    let mut viewer = Viewer {
        act_dim: spaces.action.flat_dim(),
        discrete,
        seed: opts.seed,
        paused: opts.paused,
        env,
        opts,
        gpu: None,
        error: None,
        orbit: Orbit::default(),
        bounds: None,
        markers: true,
        overlays: true,
        hud: true,
        camera: 0,
        step_once: false,
        reset: false,
        pending: Default::default(),
        last_action: None,
        screenshot: false,
        recording,
        episode_return: 0.0,
        last_reward: 0.0,
        success: None,
        sim_clock: Instant::now(),
        sim_debt: 0.0,
        fps: (Instant::now(), 0, 0.0),
        drag: None,
        cursor: (0.0, 0.0),
        summary: ViewerSummary::default(),
        on_episode,
    };
    event_loop
        .run_app(&mut viewer)
        .map_err(|e| RenderError::Device(format!("window event loop: {e}")))?;
    viewer.episode_ended();
    if let Some(path) = &viewer.opts.record {
        viewer.recording.save(path)?;
    }
    match viewer.error.take() {
        Some(e) => Err(e),
        None => Ok((viewer.summary, viewer.env)),
    }
}

/// A filterable 2-D texture sampled by the blit's fragment shader.
fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: true },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// Distance of the heads-up text box from the window's top-left corner, px.
const HUD_MARGIN: u32 = 6;

/// Size of a heads-up text pixel for a window `width` px wide.
fn hud_scale(width: u32) -> u32 {
    if width >= 900 {
        2
    } else {
        1
    }
}

impl Gpu {
    /// Rasterises the heads-up text into an RGBA texture the size of its box (plus the
    /// margin), reusing the last texture when the size is the same; 1 x 1 transparent when
    /// there is no text.
    fn upload_hud(&mut self, lines: &[String]) -> &wgpu::Texture {
        let scale = hud_scale(self.config.width);
        let (bw, bh) = crate::hud::text_box_size(lines, scale);
        let (w, h) = if bw == 0 {
            (1, 1)
        } else {
            (bw + HUD_MARGIN, bh + HUD_MARGIN)
        };
        let mut pixels = vec![0u8; (w * h * 4) as usize];
        if bw > 0 {
            crate::hud::draw_text(
                &mut pixels,
                w,
                h,
                4,
                (HUD_MARGIN, HUD_MARGIN),
                scale,
                lines,
                [255; 3],
            );
        }
        let dev = self.renderer.device().clone();
        if !matches!(&self.hud, Some((_, tw, th)) if (*tw, *th) == (w, h)) {
            let tex = crate::gpu::texture(
                &dev.device,
                "hud",
                w,
                h,
                wgpu::TextureFormat::Rgba8Unorm,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            );
            self.hud = Some((tex, w, h));
        }
        let (tex, _, _) = self.hud.as_ref().expect("set above");
        dev.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: tex,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &pixels,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * w),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        tex
    }
}

impl Viewer {
    fn init_gpu(&mut self, event_loop: &ActiveEventLoop) -> Result<Gpu, RenderError> {
        let (w, h) = self.opts.size;
        let attrs = Window::default_attributes()
            .with_title(format!("modesuite view - {}", self.opts.label))
            .with_inner_size(winit::dpi::PhysicalSize::new(w, h));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .map_err(|e| RenderError::Device(format!("cannot create a window: {e}")))?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
                Box::new(event_loop.owned_display_handle()),
            ));
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| RenderError::Device(format!("window surface: {e}")))?;
        let device = Arc::new(RenderDevice::new(instance, Some(&surface))?);
        let caps = surface.get_capabilities(&device.adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| RenderError::Device("the window surface offers no format".into()))?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps
                .alpha_modes
                .first()
                .copied()
                .unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: vec![],
            color_space: Default::default(),
        };
        surface.configure(&device.device, &config);
        let d = &device.device;
        let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("blit"),
            source: wgpu::ShaderSource::Wgsl(include_str!("blit.wgsl").into()),
        });
        let blit_layout = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("blit"),
            entries: &[
                texture_entry(0),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                texture_entry(2),
            ],
        });
        let layout = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("blit"),
            bind_group_layouts: &[Some(&blit_layout)],
            immediate_size: 0,
        });
        let blit = d.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("blit"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_blit"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_blit"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let sampler = d.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("blit"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let model = self
            .env
            .app
            .scene()
            .cloned()
            .ok_or_else(|| RenderError::Device("view: no scene".into()))?;
        let cfg = crate::config::RenderConfig::from_scene(&model)?;
        let renderer = EnvRenderer::new(device, model, cfg);
        Ok(Gpu {
            window,
            surface,
            config,
            renderer,
            blit,
            blit_layout,
            sampler,
            hud: None,
        })
    }

    fn current_camera(&mut self, width: u32, height: u32) -> Option<CameraDesc> {
        let gpu = self.gpu.as_mut()?;
        let n_scene = gpu.renderer.config().cameras.len();
        if self.camera > 0 && self.camera <= n_scene {
            let mut cam = gpu.renderer.config().cameras[self.camera - 1].clone();
            cam.markers = self.markers;
            cam.overlays = self.overlays;
            return Some(cam);
        }
        let (lo, hi) = *self
            .bounds
            .get_or_insert_with(|| gpu.renderer.scene_bounds(&self.env.app.world));
        let mut cam = self.orbit.camera("viewer", width, height, &lo, &hi);
        cam.markers = self.markers;
        cam.overlays = self.overlays;
        Some(cam)
    }

    fn advance(&mut self) {
        let settings = *self
            .env
            .app
            .world
            .resource::<modesuite_engine::SimSettings>();
        let step_dt = settings.dt * settings.decimation as f64;
        let now = Instant::now();
        let elapsed = now.duration_since(self.sim_clock).as_secs_f64();
        self.sim_clock = now;
        if self.reset {
            self.reset = false;
            self.episode_ended();
            self.seed = self.seed.wrapping_add(1);
            self.env.reset(Some(self.seed));
            self.recording.start_episode(self.seed);
            self.episode_return = 0.0;
            self.success = None;
            self.sim_debt = 0.0;
            return;
        }
        let mut n = 0;
        if self.discrete {
            // One env step per key press.
            if !self.pending.is_empty() {
                n = 1;
            }
        } else if self.paused {
            if self.step_once {
                n = 1;
            }
            self.sim_debt = 0.0;
        } else {
            self.sim_debt = (self.sim_debt + elapsed).min(4.0 * step_dt);
            while self.sim_debt >= step_dt && n < 4 {
                self.sim_debt -= step_dt;
                n += 1;
            }
        }
        self.step_once = false;
        for _ in 0..n {
            let action = self.pending.pop_front();
            let step = self.env.app.world.resource::<SimClock>().episode_steps;
            {
                let mut cmd = self.env.app.world.resource_mut::<TeleopCommand>();
                cmd.action = action;
                if action.is_some() {
                    cmd.count += 1;
                }
            }
            let mut a = vec![0.0f32; self.act_dim];
            if let Some(act) = action {
                self.recording.record(step, act);
                self.summary.actions += 1;
                self.last_action = Some(act);
                if self.discrete {
                    if let Some(x) = a.first_mut() {
                        *x = act.index() as f32;
                    }
                }
            }
            let o = self.env.step(&a);
            self.summary.steps += 1;
            self.last_reward = o.reward;
            self.episode_return += o.reward;
            self.success = o.info.success;
            self.recording
                .set_length(self.env.app.world.resource::<SimClock>().episode_steps);
            if o.terminated || o.truncated {
                self.reset = true;
                break;
            }
        }
        // Continuous envs: keys pressed while paused or beyond this frame's steps are published
        // and recorded now (discrete envs keep them queued, one step each).
        while !self.discrete {
            let Some(act) = self.pending.pop_front() else {
                break;
            };
            let step = self.env.app.world.resource::<SimClock>().episode_steps;
            let mut cmd = self.env.app.world.resource_mut::<TeleopCommand>();
            cmd.action = Some(act);
            cmd.count += 1;
            self.recording.record(step, act);
            self.summary.actions += 1;
            self.last_action = Some(act);
        }
    }

    fn title(&self) -> String {
        let clock = self.env.app.world.resource::<SimClock>();
        format!(
            "modesuite view - {} | t {:.2} s | step {} | reward {:.3} | return {:.3} | success {} | {}{} | {:.0} fps",
            self.opts.label,
            clock.time,
            clock.episode_steps,
            self.last_reward,
            self.episode_return,
            self.success.map_or("-".to_string(), |s| s.to_string()),
            if self.paused { "PAUSED | " } else { "" },
            self.last_action
                .map_or("no action".to_string(), |a| format!("action: {}", a.label())),
            self.fps.2,
        )
    }

    /// The heads-up text: what the title says, on two lines (empty when the text is off).
    fn hud_lines(&self) -> Vec<String> {
        if !self.hud {
            return Vec::new();
        }
        let clock = self.env.app.world.resource::<SimClock>();
        vec![
            format!(
                "t {:.2} s  step {}  reward {:.3}  return {:.3}  success {}",
                clock.time,
                clock.episode_steps,
                self.last_reward,
                self.episode_return,
                self.success.map_or("-".to_string(), |s| s.to_string()),
            ),
            format!(
                "{}{}  {:.0} fps",
                if self.paused { "PAUSED  " } else { "" },
                self.last_action
                    .map_or("no action".to_string(), |a| format!(
                        "action: {}",
                        a.label()
                    )),
                self.fps.2,
            ),
        ]
    }

    fn redraw(&mut self) -> Result<(), RenderError> {
        self.advance();
        let Some((w, h)) = self.gpu.as_ref().map(|g| (g.config.width, g.config.height)) else {
            return Ok(());
        };
        let Some(cam) = self.current_camera(w, h) else {
            return Ok(());
        };
        let title = self.title();
        let hud = self.hud_lines();
        let shot = std::mem::take(&mut self.screenshot);
        let Some(gpu) = self.gpu.as_mut() else {
            return Ok(());
        };
        if shot {
            let frames = gpu
                .renderer
                .render_cameras(&self.env.app.world, std::slice::from_ref(&cam))?;
            if let Some(mut f) = frames.into_iter().next() {
                // The screenshot shows what the window shows, heads-up text included.
                crate::hud::draw_text(
                    &mut f.rgb,
                    f.width,
                    f.height,
                    3,
                    (HUD_MARGIN, HUD_MARGIN),
                    hud_scale(f.width),
                    &hud,
                    [255; 3],
                );
                let path = self.opts.screenshot_dir.join(format!(
                    "modesuite-view-{:04}.png",
                    self.summary.screenshots.len()
                ));
                crate::video::write_frame_png(&path, &f)?;
                self.summary.screenshots.push(path);
            }
        }
        let surface_tex = match gpu.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                gpu.surface
                    .configure(&gpu.renderer.device().device, &gpu.config);
                return Ok(());
            }
            _ => return Ok(()),
        };
        let dev = gpu.renderer.device().clone();
        let src = gpu.renderer.render_to_texture(&self.env.app.world, &cam)?;
        let src_view = src.create_view(&Default::default());
        let hud_view = gpu.upload_hud(&hud).create_view(&Default::default());
        let bind = dev.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("blit"),
            layout: &gpu.blit_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&src_view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&gpu.sampler),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&hud_view),
                },
            ],
        });
        let target = surface_tex.texture.create_view(&Default::default());
        let mut encoder = dev
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("blit"),
            });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("blit"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            });
            pass.set_pipeline(&gpu.blit);
            pass.set_bind_group(0, &bind, &[]);
            pass.draw(0..3, 0..1);
        }
        dev.queue.submit([encoder.finish()]);
        dev.queue.present(surface_tex);
        gpu.window.set_title(&title);
        self.summary.frames += 1;
        let (t0, n, _) = self.fps;
        let dt = t0.elapsed().as_secs_f64();
        if dt >= 0.5 {
            self.fps = (Instant::now(), 0, (n + 1) as f64 / dt);
        } else {
            self.fps.1 += 1;
        }
        Ok(())
    }

    fn key(&mut self, key: &Key, event_loop: &ActiveEventLoop) {
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::Space) => self.paused = !self.paused,
            Key::Named(NamedKey::ArrowLeft) => self.orbit.azimuth -= 10.0,
            Key::Named(NamedKey::ArrowRight) => self.orbit.azimuth += 10.0,
            Key::Named(NamedKey::ArrowUp) => {
                self.orbit.elevation = (self.orbit.elevation + 5.0).min(89.0)
            }
            Key::Named(NamedKey::ArrowDown) => {
                self.orbit.elevation = (self.orbit.elevation - 5.0).max(-89.0)
            }
            Key::Character(s) => {
                let Some(c) = s.chars().next() else {
                    return;
                };
                match c.to_ascii_lowercase() {
                    'n' => self.step_once = true,
                    'r' => self.reset = true,
                    'm' => self.markers = !self.markers,
                    'x' => self.overlays = !self.overlays,
                    't' => self.hud = !self.hud,
                    'p' => self.screenshot = true,
                    'c' => {
                        let n = self
                            .gpu
                            .as_ref()
                            .map_or(0, |g| g.renderer.config().cameras.len());
                        self.camera = (self.camera + 1) % (n + 1);
                    }
                    '+' | '=' => self.orbit.zoom = (self.orbit.zoom / 1.15).max(0.05),
                    '-' | '_' => self.orbit.zoom = (self.orbit.zoom * 1.15).min(50.0),
                    other => {
                        if let Some(a) = TeleopAction::from_key(other) {
                            self.pending.push_back(a);
                        }
                    }
                }
            }
            _ => {}
        }
    }
}

impl ApplicationHandler for Viewer {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gpu.is_some() {
            return;
        }
        match self.init_gpu(event_loop) {
            Ok(g) => {
                g.window.request_redraw();
                self.gpu = Some(g);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(g) = self.gpu.as_mut() {
                    g.config.width = size.width.max(1);
                    g.config.height = size.height.max(1);
                    g.surface.configure(&g.renderer.device().device, &g.config);
                }
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(&event.logical_key, event_loop);
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.drag = (state == ElementState::Pressed).then_some(self.cursor);
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                if let Some((x0, y0)) = self.drag {
                    self.orbit.azimuth -= 0.3 * (position.x - x0);
                    self.orbit.elevation =
                        (self.orbit.elevation + 0.3 * (position.y - y0)).clamp(-89.0, 89.0);
                    self.drag = Some(self.cursor);
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let y = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                self.orbit.zoom = (self.orbit.zoom * 0.9f64.powf(y)).clamp(0.05, 50.0);
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw() {
                    self.error = Some(e);
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(g) = &self.gpu {
            g.window.request_redraw();
        }
    }
}
