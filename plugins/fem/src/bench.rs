//! The reference-rod benchmark the CLI runs (`modesuite bench`): a 1.0 x 0.04 x 0.04 m rod,
//! nu = 0.3, rho = 1000 kg/m^3, clamped at x = 0, gravity -z, dt = 1/60 s.

use crate::coupling::{NoContacts, Reaction};
use crate::error::FemError;
use crate::material::Material;
use crate::solid::{FemConfig, FemSolid, PointEmbedding};
use crate::testing::box_mesh;
use nalgebra::Vector3;
use std::time::Instant;

/// Rod length (m).
pub const ROD_LENGTH: f64 = 1.0;
/// Rod cross-section side (m).
pub const ROD_SIDE: f64 = 0.04;
/// Rod density (kg/m^3).
pub const ROD_DENSITY: f64 = 1000.0;
/// Rod Poisson ratio.
pub const ROD_POISSON: f64 = 0.3;
/// Gravity magnitude (m/s^2).
pub const GRAVITY: f64 = 9.81;

/// The reference rod on a Kuhn-split `cells` grid (the box spans `[0, L] x [0, a] x [0, a]`),
/// with the nodes at `x = 0` fixed, and the embedded centroid of the free end face.
pub fn reference_rod(
    youngs_modulus: f64,
    poisson_ratio: f64,
    cells: [usize; 3],
    config: FemConfig,
) -> Result<(FemSolid, PointEmbedding), FemError> {
    let (nodes, tets) = box_mesh(
        Vector3::zeros(),
        Vector3::new(ROD_LENGTH, ROD_SIDE, ROD_SIDE),
        cells,
    );
    let mut solid = FemSolid::new(
        &nodes,
        &tets,
        Material::new(youngs_modulus, poisson_ratio, ROD_DENSITY)?,
        config,
    )?;
    let clamp = solid.rest_nodes_where(|p| p.x.abs() < 1e-12);
    solid.fix_nodes(&clamp)?;
    let tip = solid.embed_point(&Vector3::new(ROD_LENGTH, 0.5 * ROD_SIDE, 0.5 * ROD_SIDE))?;
    Ok((solid, tip))
}

/// Euler-Bernoulli tip deflection of a cantilever under its own weight, `q L^4 / (8 E I)` (m).
pub fn cantilever_theory(youngs_modulus: f64) -> f64 {
    let a = ROD_SIDE;
    let q = ROD_DENSITY * a * a * GRAVITY;
    let i = a.powi(4) / 12.0;
    q * ROD_LENGTH.powi(4) / (8.0 * youngs_modulus * i)
}

/// Benchmark settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodBench {
    /// Young's modulus (Pa), 1e6 or 1e8 in the issue.
    pub youngs_modulus: f64,
    /// Kuhn grid cells along x, y, z.
    pub cells: [usize; 3],
    /// Number of timed steps.
    pub steps: usize,
    /// Step size (s).
    pub dt: f64,
}

impl Default for RodBench {
    fn default() -> Self {
        RodBench {
            youngs_modulus: 1e8,
            cells: [10, 1, 1],
            steps: 600,
            dt: 1.0 / 60.0,
        }
    }
}

/// Benchmark figures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodBenchReport {
    /// Nodes (corners + edge nodes).
    pub nodes: usize,
    /// 10-node elements.
    pub elements: usize,
    /// Timed steps.
    pub steps: usize,
    /// Wall time of the timed steps (s).
    pub seconds: f64,
    /// Steps per second (single thread).
    pub steps_per_second: f64,
    /// Mean Newton iterations per step.
    pub newton_per_step: f64,
    /// Mean PCG iterations per step.
    pub pcg_per_step: f64,
    /// Tip deflection (m, downwards positive) of the linear static solve (`K_rest u = f`).
    pub linear_static_deflection: f64,
    /// Tip deflection (m) of the nonlinear static equilibrium (Stable Neo-Hookean).
    pub nonlinear_static_deflection: f64,
    /// Tip deflection (m) at the end of the timed dynamic run (still oscillating unless damped).
    pub final_dynamic_deflection: f64,
    /// Euler-Bernoulli `q L^4 / (8 E I)` (m).
    pub theory: f64,
}

/// Runs the benchmark: static solves for the deflections, then `steps` timed dynamic steps from
/// rest (default solver settings, no contacts).
pub fn run_rod_bench(b: &RodBench) -> Result<RodBenchReport, FemError> {
    let g = Vector3::new(0.0, 0.0, -GRAVITY);
    let (mut solid, tip) =
        reference_rod(b.youngs_modulus, ROD_POISSON, b.cells, FemConfig::default())?;
    let z0 = solid.embedded_position(&tip).z;
    let u = solid.solve_linear_static(g)?;
    let el = &solid.model().mesh.elements[tip.element as usize];
    let lin = -(0..10)
        .map(|a| u[el[a] as usize].z * tip.weights[a])
        .sum::<f64>();
    let state0 = solid.get_state();
    solid.solve_static(g, 100)?;
    let nonlin = z0 - solid.embedded_position(&tip).z;
    solid.set_state(&state0)?;
    let mut reactions: Vec<Reaction> = Vec::new();
    let (mut newton, mut pcg) = (0usize, 0usize);
    let t0 = Instant::now();
    for _ in 0..b.steps {
        reactions.clear();
        let s = solid.step(b.dt, g, &NoContacts, &mut reactions)?;
        newton += s.newton_iterations;
        pcg += s.linear_iterations;
    }
    let seconds = t0.elapsed().as_secs_f64();
    Ok(RodBenchReport {
        nodes: solid.n_nodes(),
        elements: solid.model().n_elements(),
        steps: b.steps,
        seconds,
        steps_per_second: b.steps as f64 / seconds,
        newton_per_step: newton as f64 / b.steps as f64,
        pcg_per_step: pcg as f64 / b.steps as f64,
        linear_static_deflection: lin,
        nonlinear_static_deflection: nonlin,
        final_dynamic_deflection: z0 - solid.embedded_position(&tip).z,
        theory: cantilever_theory(b.youngs_modulus),
    })
}
