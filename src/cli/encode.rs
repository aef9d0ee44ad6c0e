//! `modesuite encode`: image features of PNG files with an image encoder (the features that
//! `record --encoder` caches and image policies use), for checking a weights file or comparing
//! with another implementation.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;
use modesuite_learn::encoder::{encoder_by_name, Image, ImageEncoder};
use modesuite_learn::LearnError;
use modesuite_render::video::read_png;
use serde_json::json;

use super::{io, CliError};

/// Arguments of `encode`.
#[derive(Args, Debug)]
pub struct EncodeArgs {
    /// PNG images (RGB or RGBA, 8 bits per channel).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// The encoder: `pooled` (weights-free) or `dinov2` (needs --weights).
    #[arg(long, default_value = "pooled")]
    pub encoder: String,
    /// Weights of the encoder (`dinov2`: DINOv2 ViT-S/14 as safetensors, the Hugging Face
    /// `facebook/dinov2-small` or the original/timm key names).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// One JSON object per image (`file`, `encoder`, `dim`, `feature`).
    #[arg(long)]
    pub json: bool,
}

/// A learning-crate error as a CLI error: unreadable files are runtime errors, the rest input.
pub(crate) fn learn_err(e: LearnError) -> CliError {
    match e {
        LearnError::Io(m) => CliError::runtime(m),
        e => CliError::input(e.to_string()),
    }
}

/// Makes the encoder `name` with its optional weights file.
pub(crate) fn make_encoder(
    name: &str,
    weights: Option<&Path>,
) -> Result<Box<dyn ImageEncoder>, CliError> {
    encoder_by_name(name, weights).map_err(learn_err)
}

/// Runs `encode`.
pub fn encode(args: &EncodeArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let enc = make_encoder(&args.encoder, args.weights.as_deref())?;
    for path in &args.images {
        let (w, h, rgb) =
            read_png(path).map_err(|e| CliError::input(format!("{}: {e}", path.display())))?;
        let image = Image::rgb(w as usize, h as usize, &rgb).map_err(learn_err)?;
        let f = enc.encode(&image).map_err(learn_err)?;
        if args.json {
            let line = json!({"file": path.display().to_string(), "encoder": enc.name(),
                              "dim": f.len(), "feature": f});
            writeln!(out, "{line}").map_err(io)?;
        } else {
            let head: Vec<String> = f.iter().take(6).map(|v| format!("{v:.5}")).collect();
            writeln!(
                out,
                "{}: {} {} values [{}, ...]",
                path.display(),
                enc.name(),
                f.len(),
                head.join(", ")
            )
            .map_err(io)?;
        }
    }
    Ok(())
}
