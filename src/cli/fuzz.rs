//! `modesuite fuzz`: runs fuzz campaigns on the input parsers and loaders ([`crate::fuzz`]).

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::Duration;

use serde_json::json;

use super::{io, CliError};
use crate::fuzz::{run_campaign, target, Campaign, TARGETS};

/// Arguments of `fuzz`.
#[derive(clap::Args, Debug)]
pub struct FuzzArgs {
    /// A target name, or `all` (see `modesuite fuzz --list`).
    #[arg(default_value = "all")]
    pub target: String,
    /// Mutated inputs per target after its corpus.
    #[arg(long, default_value_t = 1000)]
    pub iterations: u64,
    /// Seed of the mutator (same seed, same inputs).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stop making mutants of a target after this many seconds.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// An input running longer than this many seconds is a hang (the process exits with 3).
    #[arg(long, default_value_t = 60.0)]
    pub hang_seconds: f64,
    /// Folder failing inputs are written to (`DIR/<target>/panic-N`, `hang-N`).
    #[arg(long, default_value = "fuzz/out")]
    pub out: PathBuf,
    /// Print the scene the `generated` target makes from this seed (a failing input's first 8
    /// bytes, little-endian) and exit.
    #[arg(long)]
    pub show_generated: Option<u64>,
    /// List the targets and exit.
    #[arg(long)]
    pub list: bool,
    /// Print every refusal message (what the inputs hit).
    #[arg(long)]
    pub verbose: bool,
    /// One JSON object per target.
    #[arg(long)]
    pub json: bool,
}

fn seconds(flag: &str, s: f64) -> Result<Duration, CliError> {
    if s.is_finite() && s > 0.0 && s < 1e9 {
        Ok(Duration::from_secs_f64(s))
    } else {
        Err(CliError::input(format!(
            "{flag} = {s}: a positive number of seconds"
        )))
    }
}

/// Runs `fuzz`; exit code 1 when any target panicked.
pub(super) fn fuzz(args: &FuzzArgs, out: &mut dyn Write) -> Result<(), CliError> {
    if let Some(seed) = args.show_generated {
        write!(out, "{}", crate::fuzz::generated::random_scene(seed)).map_err(io)?;
        return Ok(());
    }
    if args.list {
        for t in TARGETS {
            writeln!(out, "{:<8} {}", t.name, t.about).map_err(io)?;
        }
        return Ok(());
    }
    let chosen: Vec<_> = if args.target == "all" {
        TARGETS.iter().collect()
    } else {
        vec![target(&args.target).ok_or_else(|| {
            CliError::input(format!(
                "fuzz target {:?}: one of all, {}",
                args.target,
                TARGETS
                    .iter()
                    .map(|t| t.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?]
    };
    let campaign = Campaign {
        iterations: args.iterations,
        seed: args.seed,
        time_limit: args.seconds.map(|s| seconds("--seconds", s)).transpose()?,
        hang_limit: seconds("--hang-seconds", args.hang_seconds)?,
        out: Some(args.out.clone()),
    };
    let mut panics = 0;
    for t in chosen {
        let tty = std::io::stderr().is_terminal();
        let mut refused = 0;
        let verbose = args.verbose;
        let r = run_campaign(t, &campaign, &mut |r| {
            if verbose && r.refused > refused {
                refused = r.refused;
                eprintln!("refused: {}", r.last_refusal.as_deref().unwrap_or_default());
            }
            if tty && r.tried % 50 == 0 {
                eprint!(
                    "\r{}: {} inputs, {} panics",
                    r.target,
                    r.tried,
                    r.panics.len()
                );
            }
        });
        if tty {
            eprintln!();
        }
        panics += r.panics.len();
        if args.json {
            let line = json!({
                "target": r.target, "tried": r.tried, "accepted": r.accepted,
                "refused": r.refused, "panics": r.panics.len(), "hangs": 0,
                "slowest_s": r.slowest_s, "wall_s": r.wall_s, "seed": args.seed,
            });
            writeln!(out, "{line}").map_err(io)?;
        } else {
            writeln!(out, "{}", r.line()).map_err(io)?;
        }
        for (msg, file) in &r.panics {
            let at = file
                .as_ref()
                .map_or_else(|| "not written".into(), |p| p.display().to_string());
            writeln!(out, "  panic: {msg} (input: {at})").map_err(io)?;
        }
    }
    if panics > 0 {
        return Err(CliError::runtime(format!("fuzz: {panics} inputs panicked")));
    }
    Ok(())
}
