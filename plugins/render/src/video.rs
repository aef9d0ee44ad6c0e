//! Episode videos and still frames: GIF (Rust encoder, always available), MP4 (an `ffmpeg`
//! subprocess fed raw RGB; a clear error when ffmpeg is missing) and PNG files.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

use crate::gpu::CameraFrame;
use crate::RenderError;

/// Whether an `ffmpeg` executable runs.
pub fn ffmpeg_available() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn out_err(path: &Path, what: impl std::fmt::Display) -> RenderError {
    RenderError::Output(format!("{}: {what}", path.display()))
}

enum Sink {
    Gif(gif::Encoder<BufWriter<File>>),
    Ffmpeg {
        child: Child,
        stdin: Option<ChildStdin>,
    },
    /// Finished (the sink was taken by `finish`).
    Done,
}

/// Writes frames of one size into a video file chosen by its extension (`.gif` or `.mp4`).
/// The frames go to a temporary file beside it (`.NAME.PID.partial.EXT`), renamed into place by
/// [`VideoWriter::finish`]; a writer dropped unfinished (an error, a full disk) removes it, so
/// `path` is either the complete video or untouched.
pub struct VideoWriter {
    path: PathBuf,
    /// Where the frames are written until `finish`.
    tmp: PathBuf,
    width: u32,
    height: u32,
    fps: f64,
    frames: usize,
    sink: Sink,
}

impl VideoWriter {
    /// Creates `path` for `width x height` frames at `fps` frames per second.
    pub fn create(path: &Path, width: u32, height: u32, fps: f64) -> Result<Self, RenderError> {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(out_err(path, format!("frame rate {fps}: must be > 0")));
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let tmp = modesuite_engine::fsio::partial_path(
            path,
            &format!(".{}", ext.as_deref().unwrap_or("video")),
        );
        let sink = match ext.as_deref() {
            Some("gif") => {
                if width > u16::MAX as u32 || height > u16::MAX as u32 {
                    return Err(out_err(
                        path,
                        "GIF frames are at most 65535 px wide and high",
                    ));
                }
                let file = File::create(&tmp).map_err(|e| out_err(path, e))?;
                let started =
                    gif::Encoder::new(BufWriter::new(file), width as u16, height as u16, &[])
                        .and_then(|mut enc| enc.set_repeat(gif::Repeat::Infinite).map(|()| enc));
                match started {
                    Ok(enc) => Sink::Gif(enc),
                    Err(e) => {
                        let _ = std::fs::remove_file(&tmp);
                        return Err(out_err(path, e));
                    }
                }
            }
            Some("mp4") => {
                if !ffmpeg_available() {
                    return Err(out_err(
                        path,
                        "MP4 needs ffmpeg, which was not found on PATH (Debian: apt-get install ffmpeg); or write a GIF instead (--video out.gif)",
                    ));
                }
                let mut child = Command::new("ffmpeg")
                    .args([
                        "-y",
                        "-loglevel",
                        "error",
                        "-f",
                        "rawvideo",
                        "-pix_fmt",
                        "rgb24",
                    ])
                    .args(["-s", &format!("{width}x{height}"), "-r", &format!("{fps}")])
                    .args(["-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
                    .args(["-pix_fmt", "yuv420p", "-movflags", "+faststart"])
                    .arg(&tmp)
                    .stdin(Stdio::piped())
                    .stdout(Stdio::null())
                    .stderr(Stdio::piped())
                    .spawn()
                    .map_err(|e| out_err(path, format!("starting ffmpeg: {e}")))?;
                let stdin = child.stdin.take();
                Sink::Ffmpeg { child, stdin }
            }
            _ => {
                return Err(out_err(
                    path,
                    "unknown video format; use a .gif or .mp4 file name",
                ))
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            width,
            height,
            fps,
            frames: 0,
            sink,
        })
    }

    /// Appends one frame (its size must match the video's).
    pub fn push(&mut self, frame: &CameraFrame) -> Result<(), RenderError> {
        if frame.width != self.width || frame.height != self.height {
            return Err(out_err(
                &self.path,
                format!(
                    "frame of {}x{} in a {}x{} video",
                    frame.width, frame.height, self.width, self.height
                ),
            ));
        }
        match &mut self.sink {
            Sink::Gif(enc) => {
                let mut f = gif::Frame::from_rgb_speed(
                    self.width as u16,
                    self.height as u16,
                    &frame.rgb,
                    10,
                );
                f.delay = (100.0 / self.fps).round().clamp(1.0, 65535.0) as u16;
                enc.write_frame(&f).map_err(|e| out_err(&self.path, e))?;
            }
            Sink::Ffmpeg { stdin, .. } => {
                let pipe = stdin
                    .as_mut()
                    .ok_or_else(|| out_err(&self.path, "ffmpeg input closed"))?;
                pipe.write_all(&frame.rgb)
                    .map_err(|e| out_err(&self.path, format!("ffmpeg: {e}")))?;
            }
            Sink::Done => return Err(out_err(&self.path, "the video is finished")),
        }
        self.frames += 1;
        Ok(())
    }

    /// Number of frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Finishes the file and moves it into place; returns the number of frames. On an error
    /// the temporary file is removed and the video's path is left as it was.
    pub fn finish(mut self) -> Result<usize, RenderError> {
        let path = self.path.clone();
        let sink = std::mem::replace(&mut self.sink, Sink::Done);
        match sink {
            Sink::Gif(enc) => {
                let w = enc.into_inner().map_err(|e| out_err(&path, e))?;
                let file = w.into_inner().map_err(|e| out_err(&path, e.error()))?;
                file.sync_all().map_err(|e| out_err(&path, e))?;
            }
            Sink::Ffmpeg { child, stdin } => {
                drop(stdin);
                let out = child
                    .wait_with_output()
                    .map_err(|e| out_err(&path, format!("ffmpeg: {e}")))?;
                if !out.status.success() {
                    return Err(out_err(
                        &path,
                        format!(
                            "ffmpeg failed ({}): {}",
                            out.status,
                            String::from_utf8_lossy(&out.stderr).trim()
                        ),
                    ));
                }
            }
            Sink::Done => {}
        }
        std::fs::rename(&self.tmp, &path)
            .map_err(|e| out_err(&path, format!("cannot move the video into place: {e}")))?;
        Ok(self.frames)
    }
}

impl Drop for VideoWriter {
    fn drop(&mut self) {
        if let Sink::Ffmpeg { child, stdin } = &mut self.sink {
            drop(stdin.take());
            let _ = child.kill();
            let _ = child.wait();
        }
        // After a successful `finish` the temporary file was renamed: nothing to remove.
        let _ = std::fs::remove_file(&self.tmp);
    }
}

/// Writes an RGB image (`height x width x 3` u8) as a PNG file.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), RenderError> {
    if rgb.len() != (width * height * 3) as usize {
        return Err(out_err(
            path,
            format!("{} bytes for a {width}x{height} RGB image", rgb.len()),
        ));
    }
    // Encoded in memory, then written atomically: a full disk or a kill leaves no half image.
    let mut bytes = Vec::with_capacity(rgb.len() / 2 + 1024);
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut w = enc.write_header().map_err(|e| out_err(path, e))?;
        w.write_image_data(rgb).map_err(|e| out_err(path, e))?;
        w.finish().map_err(|e| out_err(path, e))?;
    }
    modesuite_engine::fsio::write_atomic(path, &bytes).map_err(|e| out_err(path, e))
}

/// Writes a frame's colour image as a PNG file.
pub fn write_frame_png(path: &Path, frame: &CameraFrame) -> Result<(), RenderError> {
    write_png(path, frame.width, frame.height, &frame.rgb)
}

/// Reads a PNG file written by [`write_png`] back as `(width, height, rgb)` (tests, tools).
pub fn read_png(path: &Path) -> Result<(u32, u32, Vec<u8>), RenderError> {
    let file = File::open(path).map_err(|e| out_err(path, e))?;
    let dec = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = dec.read_info().map_err(|e| out_err(path, e))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| out_err(path, "image too large"))?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(|e| out_err(path, e))?;
    buf.truncate(info.buffer_size());
    let rgb = match info.color_type {
        png::ColorType::Rgb => buf,
        png::ColorType::Rgba => buf
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
        other => {
            return Err(out_err(
                path,
                format!("unsupported PNG colour type {other:?}"),
            ))
        }
    };
    Ok((info.width, info.height, rgb))
}

/// Counts the frames of a GIF file and returns `(width, height, frames)` (tests, tools).
pub fn gif_info(path: &Path) -> Result<(u32, u32, usize), RenderError> {
    let file = File::open(path).map_err(|e| out_err(path, e))?;
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::Indexed);
    let mut dec = opts
        .read_info(std::io::BufReader::new(file))
        .map_err(|e| out_err(path, e))?;
    let (w, h) = (dec.width() as u32, dec.height() as u32);
    let mut n = 0;
    while dec
        .read_next_frame()
        .map_err(|e| out_err(path, e))?
        .is_some()
    {
        n += 1;
    }
    Ok((w, h, n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: u32, h: u32, shade: u8) -> CameraFrame {
        CameraFrame {
            width: w,
            height: h,
            rgb: (0..w * h * 3)
                .map(|i| (i as u8).wrapping_add(shade))
                .collect(),
            ..Default::default()
        }
    }

    #[test]
    fn gif_round_trip_counts_frames() {
        let dir = std::env::temp_dir().join(format!("modesuite-render-gif-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("t.gif");
        let mut v = VideoWriter::create(&path, 20, 10, 30.0).expect("create");
        for i in 0..5 {
            v.push(&frame(20, 10, i * 40)).expect("push");
        }
        assert!(v.push(&frame(10, 10, 0)).is_err(), "wrong size accepted");
        assert_eq!(v.finish().expect("finish"), 5);
        let (w, h, n) = gif_info(&path).expect("decode");
        assert_eq!((w, h, n), (20, 10, 5), "decoded size and frame count");
        let e = VideoWriter::create(&dir.join("t.avi"), 4, 4, 30.0)
            .err()
            .expect("avi");
        assert!(e.to_string().contains(".gif or .mp4"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn png_round_trip() {
        let dir = std::env::temp_dir().join(format!("modesuite-render-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("t.png");
        let f = frame(7, 5, 3);
        write_frame_png(&path, &f).expect("write");
        let (w, h, rgb) = read_png(&path).expect("read");
        assert_eq!((w, h), (7, 5));
        assert_eq!(rgb, f.rgb, "pixels survive the round trip");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
