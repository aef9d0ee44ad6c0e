//! Recording a run: video (GIF, or MP4 through ffmpeg) and PNG frames of a camera, with
//! optional overlays (`run --video`, `--frames`, `--camera`, `--video-size`, `--overlays`).

use std::io::Write;
use std::path::PathBuf;

use modesuite_engine::prelude::*;
use modesuite_engine::scene::SceneModel;
use modesuite_render::video::{write_frame_png, VideoWriter};
use modesuite_render::{CameraDesc, EnvRenderer, Orbit, RenderError};

use super::{io, CliError, RunArgs};
use crate::make::MakeError;

/// Parses `WIDTHxHEIGHT`.
pub(super) fn parse_size(flag: &str, s: &str) -> Result<(u32, u32), CliError> {
    let bad = || {
        CliError::input(format!(
            "{flag} = {s:?}: WIDTHxHEIGHT in pixels, each in 1..=8192, e.g. 480x320"
        ))
    };
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}

pub(super) fn render_err(e: RenderError) -> CliError {
    MakeError::from(e).into()
}

/// Records frames of a run into a video and/or PNG files.
pub(super) struct Recorder {
    renderer: EnvRenderer,
    camera: Option<CameraDesc>,
    camera_name: Option<String>,
    size: (u32, u32),
    video_path: Option<PathBuf>,
    video: Option<VideoWriter>,
    frames_dir: Option<PathBuf>,
    every: u64,
    fps: f64,
    written: u64,
    overlays: bool,
}

impl Recorder {
    pub(super) fn new(
        model: &std::sync::Arc<SceneModel>,
        args: &RunArgs,
    ) -> Result<Option<Self>, CliError> {
        if args.video.is_none() && args.frames.is_none() {
            if args.camera.is_some() {
                return Err(CliError::input(
                    "--camera: only used with --video or --frames",
                ));
            }
            return Ok(None);
        }
        let size = parse_size("--video-size", &args.video_size)?;
        if let Some(dir) = &args.frames {
            std::fs::create_dir_all(dir).map_err(|e| {
                CliError::runtime(format!("--frames {}: cannot create: {e}", dir.display()))
            })?;
        }
        let renderer = EnvRenderer::for_scene(model.clone()).map_err(render_err)?;
        if let Some(name) = &args.camera {
            renderer.scene_camera(name).map_err(render_err)?;
        }
        // About 30 frames per second of simulated time.
        let step_dt = model.settings.dt * model.settings.decimation as f64;
        let every = ((1.0 / (30.0 * step_dt)).round() as u64).max(1);
        Ok(Some(Self {
            renderer,
            camera: None,
            camera_name: args.camera.clone(),
            size,
            video_path: args.video.clone(),
            video: None,
            frames_dir: args.frames.clone(),
            every,
            fps: 1.0 / (every as f64 * step_dt),
            written: 0,
            overlays: args.overlays,
        }))
    }

    /// Renders and writes the current frame when `step` is on the recording stride; with
    /// `--overlays` also the markers and the text `status` makes (only called then).
    pub(super) fn capture(
        &mut self,
        world: &World,
        step: u64,
        status: impl FnOnce() -> String,
    ) -> Result<(), CliError> {
        if !step.is_multiple_of(self.every) {
            return Ok(());
        }
        let mut cam = match (&self.camera, &self.camera_name) {
            (Some(c), _) => c.clone(),
            (None, Some(name)) => self
                .renderer
                .scene_camera(name)
                .map_err(render_err)?
                .clone(),
            (None, None) => {
                let c = self.renderer.orbit_camera(
                    world,
                    "orbit",
                    self.size.0,
                    self.size.1,
                    Orbit::default(),
                );
                self.camera = Some(c.clone());
                c
            }
        };
        cam.overlays = self.overlays;
        let frames = self
            .renderer
            .render_cameras(world, std::slice::from_ref(&cam))
            .map_err(render_err)?;
        let Some(mut frame) = frames.into_iter().next() else {
            return Ok(());
        };
        if self.overlays {
            let (w, h) = (frame.width, frame.height);
            let lines = [status()];
            modesuite_render::hud::draw_text(&mut frame.rgb, w, h, 3, (4, 4), 1, &lines, [255; 3]);
        }
        let frame = &frame;
        if let Some(dir) = &self.frames_dir {
            let path = dir.join(format!("frame_{:05}.png", self.written));
            write_frame_png(&path, frame).map_err(render_err)?;
        }
        if let Some(path) = &self.video_path {
            if self.video.is_none() {
                self.video = Some(
                    VideoWriter::create(path, frame.width, frame.height, self.fps)
                        .map_err(render_err)?,
                );
            }
            if let Some(v) = self.video.as_mut() {
                v.push(frame).map_err(render_err)?;
            }
        }
        self.written += 1;
        Ok(())
    }

    pub(super) fn finish(self, out: &mut dyn Write, quiet: bool) -> Result<(), CliError> {
        let frames = match self.video {
            Some(v) => v.finish().map_err(render_err)?,
            None => self.written as usize,
        };
        if !quiet {
            let mut what = Vec::new();
            if let Some(p) = &self.video_path {
                what.push(format!("video {}", p.display()));
            }
            if let Some(d) = &self.frames_dir {
                what.push(format!("PNG frames in {}", d.display()));
            }
            writeln!(
                out,
                "recorded {frames} frames at {:.1} fps ({}; {})",
                self.fps,
                what.join(", "),
                self.renderer.device().adapter_name()
            )
            .map_err(io)?;
        }
        Ok(())
    }
}
