//! Fuzzing of every input modesuite reads from users: scene, task, robot and URDF files, action
//! modes, OBJ/STL/gmsh/medit meshes and state files (`modesuite fuzz`, and the bounded CI tier
//! in `tests/fuzz.rs`).
//!
//! A campaign runs a target's seed corpus and its committed regression inputs
//! (`fuzz/regressions/<target>/`), then `iterations` inputs mutated from them
//! ([`mutate::Mutator`]: byte edits plus RON- and mesh-aware edits), each input in the calling
//! thread under a panic catcher and a watchdog. A panic is a defect: the campaign records it and
//! writes the input to `<out>/<target>/panic-<n>`; an input running longer than the hang limit
//! is a defect too: the watchdog writes it to `<out>/<target>/hang-<n>` and ends the process
//! with exit code 3 (a hung thread cannot be stopped). Same seed, same inputs.
//!
//! This is structure-aware mutation on the stable toolchain, without coverage feedback; see
//! `docs/reliability.md` for what it found and how to run longer campaigns.

pub mod generated;
pub mod mutate;
pub mod targets;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub use targets::{target, Target, TARGETS};

/// What a campaign did.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// Target name.
    pub target: String,
    /// Inputs run (corpus, regressions and mutants).
    pub tried: u64,
    /// Inputs accepted (parsed, and stepped where the target builds an env).
    pub accepted: u64,
    /// Inputs refused with an error message.
    pub refused: u64,
    /// Panics: the message and the file the input was written to.
    pub panics: Vec<(String, Option<PathBuf>)>,
    /// The message of the last refused input.
    pub last_refusal: Option<String>,
    /// Longest single input, s.
    pub slowest_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
}

impl Report {
    /// One line: inputs, accepted, refused, panics, slowest input, wall time.
    pub fn line(&self) -> String {
        format!(
            "{:<8} {:>7} inputs ({} accepted, {} refused), {} panics, slowest {:.2} s, {:.1} s",
            self.target,
            self.tried,
            self.accepted,
            self.refused,
            self.panics.len(),
            self.slowest_s,
            self.wall_s
        )
    }
}

/// How to run a campaign.
#[derive(Debug, Clone)]
pub struct Campaign {
    /// Mutated inputs after the corpus.
    pub iterations: u64,
    /// Seed of the mutator.
    pub seed: u64,
    /// Stop making mutants after this much time (the corpus always runs).
    pub time_limit: Option<Duration>,
    /// An input running longer than this is a hang.
    pub hang_limit: Duration,
    /// Where failing inputs are written (`<out>/<target>/`); `None`: not written.
    pub out: Option<PathBuf>,
}

impl Default for Campaign {
    fn default() -> Self {
        Self {
            iterations: 1000,
            seed: 0,
            time_limit: None,
            hang_limit: Duration::from_secs(60),
            out: None,
        }
    }
}

/// The committed regression inputs of a target (`fuzz/regressions/<target>/*`), sorted.
pub fn regressions(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/regressions")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.sort();
    files
        .into_iter()
        .filter_map(|p| std::fs::read(&p).ok().map(|b| (p, b)))
        .collect()
}

/// Runs one input: `Ok(Ok)` accepted, `Ok(Err)` refused, `Err(message)` panicked.
pub fn run_one(t: &Target, input: &[u8]) -> Result<Result<(), String>, String> {
    crate::engine::catch_panic(|| (t.run)(input)).map_err(|m| {
        if m.is_empty() {
            "panic without a message".into()
        } else {
            m
        }
    })
}

/// Writes `input` to `<out>/<target>/<kind>-<n>` (first free n); the path, or `None`.
fn save(out: Option<&Path>, target: &str, kind: &str, input: &[u8]) -> Option<PathBuf> {
    let dir = out?.join(target);
    std::fs::create_dir_all(&dir).ok()?;
    let path = (0..)
        .map(|n| dir.join(format!("{kind}-{n}")))
        .find(|p| !p.exists())?;
    crate::engine::fsio::write_atomic(&path, input).ok()?;
    Some(path)
}

/// The input running now and when it started (shared with the watchdog).
type Running = Arc<Mutex<Option<(Instant, Vec<u8>)>>>;

/// The watchdog: after each input starts, it waits for it to end within the hang limit.
struct Watchdog {
    current: Running,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Watchdog {
    fn start(target: &'static str, limit: Duration, out: Option<PathBuf>) -> Self {
        let current: Running = Arc::new(Mutex::new(None));
        let stop = Arc::new(AtomicBool::new(false));
        let (c, s) = (current.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            while !s.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(100));
                let guard = c.lock().unwrap_or_else(|e| e.into_inner());
                if let Some((started, input)) = guard.as_ref() {
                    if started.elapsed() > limit {
                        let saved = save(out.as_deref(), target, "hang", input);
                        eprintln!(
                            "fuzz {target}: an input ran longer than {:.0} s (a hang); input {}",
                            limit.as_secs_f64(),
                            saved.map_or_else(
                                || format!("{:?}", String::from_utf8_lossy(input)),
                                |p| format!("written to {}", p.display())
                            )
                        );
                        std::process::exit(3);
                    }
                }
            }
        });
        Self {
            current,
            stop,
            thread: Some(thread),
        }
    }

    fn begin(&self, input: &[u8]) {
        *self.current.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((Instant::now(), input.to_vec()));
    }

    fn end(&self) {
        *self.current.lock().unwrap_or_else(|e| e.into_inner()) = None;
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs a campaign on `t`; `progress` is called after each input with the report so far.
pub fn run_campaign(t: &'static Target, c: &Campaign, progress: &mut dyn FnMut(&Report)) -> Report {
    let started = Instant::now();
    let mut report = Report {
        target: t.name.to_string(),
        ..Report::default()
    };
    let mut corpus = (t.seeds)();
    corpus.extend(regressions(t.name).into_iter().map(|(_, b)| b));
    let dog = Watchdog::start(t.name, c.hang_limit, c.out.clone());
    let mut mutator =
        mutate::Mutator::new(c.seed ^ modesuite_learn::checkpoint::fnv1a(t.name.as_bytes()));
    let one = |input: &[u8], report: &mut Report| {
        dog.begin(input);
        let t0 = Instant::now();
        // an input's panic is reported, not printed (unless MODESUITE_FUZZ_LOUD is set)
        let r = modesuite_engine::with_quiet_panics(|| run_one(t, input));
        report.slowest_s = report.slowest_s.max(t0.elapsed().as_secs_f64());
        dog.end();
        report.tried += 1;
        match r {
            Ok(Ok(())) => report.accepted += 1,
            Ok(Err(m)) => {
                report.refused += 1;
                report.last_refusal = Some(m);
            }
            Err(msg) => {
                let saved = save(c.out.as_deref(), t.name, "panic", input);
                report.panics.push((msg, saved));
            }
        }
    };
    for input in &corpus {
        one(input, &mut report);
        progress(&report);
    }
    for _ in 0..c.iterations {
        if c.time_limit.is_some_and(|l| started.elapsed() > l) || corpus.is_empty() {
            break;
        }
        let parent = &corpus[mutator.below(corpus.len())];
        let input = mutator.mutate(parent, &corpus);
        one(&input, &mut report);
        progress(&report);
    }
    drop(dog);
    report.wall_s = started.elapsed().as_secs_f64();
    report
}
