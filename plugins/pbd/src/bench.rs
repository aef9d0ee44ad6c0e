//! The reference-sheet benchmark (scene C of the peer harness, `../shared/bench/`): a 1 x 1 m
//! sheet of 40 x 40 particles, 0.2 kg in total, pinned at the two corners of its +y edge, starting
//! horizontal at z = 1 and swinging onto a fixed 0.5 m cube (centre (0, 0, 0.25)), dt = 1/60 s.
//! Metrics match the peers' `cloth_metrics`: edge strain over all triangle edges and the number
//! of particles deeper than 5 mm inside the cube.

use crate::cloth::{Cloth, StretchStats};
use crate::coupling::Reaction;
use crate::error::PbdError;
use crate::material::{ClothMaterial, SolverSettings, TetherMetric};
use crate::mesh::GridSheet;
use crate::testing::{AnalyticCollider, AnalyticColliders, Shape};
use nalgebra::{Isometry3, Vector3};
use std::time::Instant;

/// Frame time of the benchmark, s.
pub const REFERENCE_DT: f64 = 1.0 / 60.0;
/// Depth beyond which a particle counts as inside the cube, m (the peers' definition).
pub const INSIDE_TOLERANCE: f64 = 0.005;

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchConfig {
    /// Self-collision on or off.
    pub self_collision: bool,
    /// Steps to time (after `warmup` untimed steps).
    pub steps: usize,
    /// Untimed steps first.
    pub warmup: usize,
    /// Solver settings (substeps etc.); `self_collision` above overrides its flag.
    pub settings: SolverSettings,
    /// Cloth material (areal density is forced to 0.2 kg/m^2, the reference mass).
    pub material: ClothMaterial,
}

impl BenchConfig {
    /// The settings used for the reported numbers.
    pub fn reference(self_collision: bool) -> Self {
        BenchConfig {
            self_collision,
            steps: 600,
            warmup: 30,
            settings: SolverSettings {
                tether_metric: TetherMetric::RestEuclidean,
                ..SolverSettings::default()
            },
            material: ClothMaterial {
                friction: 0.3,
                ..ClothMaterial::default()
            },
        }
    }
}

/// Outcome of a benchmark run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchResult {
    /// Timed steps.
    pub steps: usize,
    /// Wall time of the timed steps, s.
    pub seconds: f64,
    /// Steps per wall second (single thread).
    pub steps_per_second: f64,
    /// CPU time of the stepping thread during the timed steps, s (Linux
    /// `/proc/thread-self/schedstat`; equals `seconds` elsewhere). On a shared machine
    /// `steps / cpu_seconds` is the less noisy speed figure.
    pub cpu_seconds: f64,
    /// Edge strain at the end.
    pub stretch: StretchStats,
    /// Particles deeper than [`INSIDE_TOLERANCE`] inside the cube at the end.
    pub inside_cube: usize,
    /// Largest number of particles inside the cube seen after any step.
    pub max_inside_cube: usize,
    /// Lowest particle z at the end, m.
    pub min_z: f64,
    /// Rigid contacts in the last step.
    pub contacts: usize,
}

/// The reference sheet and its cube.
pub fn reference_scene(config: &BenchConfig) -> Result<(Cloth, AnalyticColliders), PbdError> {
    let sheet = GridSheet::new(1.0, 1.0, 40, 40, Vector3::new(-0.5, -0.5, 1.0))?;
    let material = ClothMaterial {
        areal_density: 0.2,
        ..config.material
    };
    let settings = SolverSettings {
        self_collision: config.self_collision,
        ..config.settings
    };
    let mut cloth = Cloth::new(&sheet.positions, &sheet.triangles, material, settings)?;
    cloth.pin_to_world(&[sheet.index(0, 39)])?;
    cloth.pin_to_world(&[sheet.index(39, 39)])?;
    let cube = AnalyticCollider::fixed(
        Shape::Box {
            pose: Isometry3::translation(0.0, 0.0, 0.25),
            half_extents: Vector3::repeat(0.25),
        },
        0.5,
    );
    Ok((cloth, AnalyticColliders::new(vec![cube])))
}

/// Builds the reference scene, runs `warmup + steps` steps and reports speed and metrics.
pub fn run_reference(config: &BenchConfig) -> Result<BenchResult, PbdError> {
    let (mut cloth, cube) = reference_scene(config)?;
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut reactions: Vec<Reaction> = Vec::new();
    let mut max_inside = 0;
    for _ in 0..config.warmup {
        reactions.clear();
        cloth.step(REFERENCE_DT, &g, &cube, &mut reactions)?;
        max_inside = max_inside.max(cube.count_inside(cloth.positions(), INSIDE_TOLERANCE));
    }
    let mut contacts = 0;
    let t0 = Instant::now();
    let c0 = thread_cpu_seconds();
    for _ in 0..config.steps {
        reactions.clear();
        contacts = cloth
            .step(REFERENCE_DT, &g, &cube, &mut reactions)?
            .contacts;
    }
    let seconds = t0.elapsed().as_secs_f64();
    let cpu_seconds = match (c0, thread_cpu_seconds()) {
        (Some(a), Some(b)) => b - a,
        _ => seconds,
    };
    max_inside = max_inside.max(cube.count_inside(cloth.positions(), INSIDE_TOLERANCE));
    Ok(BenchResult {
        steps: config.steps,
        seconds,
        steps_per_second: config.steps as f64 / seconds.max(1e-12),
        cpu_seconds,
        stretch: cloth.stretch_stats(),
        inside_cube: cube.count_inside(cloth.positions(), INSIDE_TOLERANCE),
        max_inside_cube: max_inside,
        min_z: cloth
            .positions()
            .iter()
            .map(|p| p.z)
            .fold(f64::INFINITY, f64::min),
        contacts,
    })
}

/// Runs the reference scene step by step, checking the inside count after every step (slower,
/// for validation rather than timing).
pub fn run_reference_checked(config: &BenchConfig) -> Result<BenchResult, PbdError> {
    let (mut cloth, cube) = reference_scene(config)?;
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut reactions: Vec<Reaction> = Vec::new();
    let mut max_inside = 0;
    let mut contacts = 0;
    let t0 = Instant::now();
    for _ in 0..config.warmup + config.steps {
        reactions.clear();
        contacts = cloth
            .step(REFERENCE_DT, &g, &cube, &mut reactions)?
            .contacts;
        max_inside = max_inside.max(cube.count_inside(cloth.positions(), INSIDE_TOLERANCE));
    }
    let seconds = t0.elapsed().as_secs_f64();
    let n = config.warmup + config.steps;
    Ok(BenchResult {
        steps: n,
        seconds,
        cpu_seconds: seconds,
        steps_per_second: n as f64 / seconds.max(1e-12),
        stretch: cloth.stretch_stats(),
        inside_cube: cube.count_inside(cloth.positions(), INSIDE_TOLERANCE),
        max_inside_cube: max_inside,
        min_z: cloth
            .positions()
            .iter()
            .map(|p| p.z)
            .fold(f64::INFINITY, f64::min),
        contacts,
    })
}

/// CPU time consumed by the calling thread, s, where the OS reports it (Linux).
pub fn thread_cpu_seconds() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}
