//! Material and solver parameters.

use crate::error::{check_param, PbdError};

/// Physical parameters of a cloth sheet (SI units).
///
/// Compliances are inverse stiffnesses as in XPBD (Macklin, Müller, Chentanez 2016). They are
/// given per unit of material, not per constraint, so that refining the mesh keeps the behaviour:
/// * an edge of rest length `L` whose adjacent triangles have total rest area `A` gets the
///   constraint compliance `alpha_e = c * L^2 / A` (m/N), which for the axis edges of a square
///   grid is exactly `c` (the inverse membrane modulus `1 / (E t)`, m/N) at any resolution;
/// * an interior edge gets an isometric bending constraint (Bergou et al. 2006) with compliance
///   `alpha_b = A * bending_compliance / 3`, `A` again the two triangles' area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClothMaterial {
    /// Mass per area, kg/m^2 (lumped to particles: a third of each triangle's mass per vertex).
    pub areal_density: f64,
    /// Inverse membrane stretch modulus for the structural edges, m/N (0 = inextensible).
    pub stretch_compliance: f64,
    /// Inverse membrane modulus for the shear edges (an edge opposite a near-right angle, e.g.
    /// the diagonals of a grid sheet), m/N.
    pub shear_compliance: f64,
    /// Inverse bending stiffness, 1/(N m) (larger = floppier).
    pub bending_compliance: f64,
    /// Linear velocity damping rate, 1/s (v is scaled by `1 / (1 + damping * h)` per substep).
    pub damping: f64,
    /// Coulomb friction coefficient of the cloth; a contact uses `sqrt(mu_cloth * mu_collider)`.
    pub friction: f64,
    /// Collision thickness, m: particle centres stay `thickness / 2` away from rigid surfaces and
    /// `thickness` away from other layers of the same cloth.
    pub thickness: f64,
}

impl Default for ClothMaterial {
    /// A light cotton-like sheet: 0.2 kg/m^2, membrane modulus 1e4 N/m, 4 mm collision thickness.
    fn default() -> Self {
        ClothMaterial {
            areal_density: 0.2,
            stretch_compliance: 1e-4,
            shear_compliance: 1e-3,
            bending_compliance: 1e4,
            damping: 0.1,
            friction: 0.5,
            thickness: 0.004,
        }
    }
}

impl ClothMaterial {
    /// Checks every field (finite, in range); the error names the field and what is valid.
    pub fn validate(&self) -> Result<(), PbdError> {
        check_param(
            "material.areal_density",
            self.areal_density,
            0.0,
            true,
            "a finite value > 0 kg/m^2",
        )?;
        check_param(
            "material.stretch_compliance",
            self.stretch_compliance,
            0.0,
            false,
            "a finite value >= 0 m/N",
        )?;
        check_param(
            "material.shear_compliance",
            self.shear_compliance,
            0.0,
            false,
            "a finite value >= 0 m/N",
        )?;
        check_param(
            "material.bending_compliance",
            self.bending_compliance,
            0.0,
            false,
            "a finite value >= 0 1/(N m)",
        )?;
        check_param(
            "material.damping",
            self.damping,
            0.0,
            false,
            "a finite value >= 0 1/s",
        )?;
        check_param(
            "material.friction",
            self.friction,
            0.0,
            false,
            "a finite value >= 0",
        )?;
        check_param(
            "material.thickness",
            self.thickness,
            0.0,
            true,
            "a finite value > 0 m",
        )?;
        Ok(())
    }
}

/// How the rest length of a long-range attachment (tether) is measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TetherMetric {
    /// Shortest path along mesh edges (Dijkstra over rest lengths). Always an upper bound of the
    /// true geodesic distance, so tethers never over-constrain; on a grid it overestimates
    /// off-axis distances by up to ~8 %.
    Graph,
    /// Straight-line rest distance. Exact geodesic for flat convex sheets (e.g. grid sheets);
    /// over-constrains non-convex or curved rest shapes.
    RestEuclidean,
}

/// Numerical settings of the solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverSettings {
    /// Substeps per step ("small steps", Macklin et al. 2019). Must be >= 1.
    pub substeps: u32,
    /// Gauss-Seidel iterations per substep. Must be >= 1. Lagrange multipliers accumulate over
    /// the iterations of a substep and restart at zero each substep.
    pub iterations: u32,
    /// Particle-versus-cloth collisions (spatial hash, point-triangle and point-point).
    pub self_collision: bool,
    /// Extra distance, m, within which self-collision pairs are gathered at the start of a step
    /// (bounds how far two layers may approach each other during one step).
    pub self_collision_margin: f64,
    /// Long-range attachments (Kim, Chentanez, Müller 2012): no particle may be farther from
    /// its nearest pinned (kinematic) particle than its rest distance. Limits stretch of hanging
    /// cloth at no visible cost.
    pub tethers: bool,
    /// Rest distance measure for tethers.
    pub tether_metric: TetherMetric,
    /// Tethers are also anchored at grasped particles (force-limited attachments on a frame):
    /// every particle nearer (along the rest mesh) to a grasped particle than to a pin is kept,
    /// edge by edge along its shortest path to the grasp, within `1 + grasp_tether_slack` times
    /// the path's rest length ("follow the leader", see `Cloth::step`). Without them a few
    /// grasped particles drag a large sheet only through the distance constraints, which one
    /// Gauss-Seidel iteration per substep carries a few particles per substep, so the sheet
    /// stretches into a strand. The sweep limits stretch only: its corrections are not part of
    /// the grasp's reaction or force limit, so they are off by default (with them, the grip
    /// force of a hanging grasped sheet read below its weight); scenes that drag large sheets
    /// turn them on (`grasp_tethers: true`). Needs `tethers`.
    pub grasp_tethers: bool,
    /// Strain a grasp tether allows before it acts (fraction of the edge's rest length, >= 0).
    pub grasp_tether_slack: f64,
    /// Extra distance, m, added to `thickness / 2 + |v| dt` when querying rigid colliders once per
    /// step.
    pub contact_margin: f64,
    /// Compliance of grasp/frame attachments, m/N (0 = rigid until the force limit).
    pub attachment_compliance: f64,
    /// Also keep the midpoints of mesh edges outside rigid colliders where the edge's two
    /// particles touch the same body through differently oriented surfaces (a box corner). This
    /// stops edges from cutting collider corners and particles from locking there by friction,
    /// at the price of stronger corrections during fast impacts. Off by default (see the crate
    /// docs for the measured trade-off).
    pub edge_contacts: bool,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            substeps: 8,
            iterations: 1,
            self_collision: false,
            self_collision_margin: 0.01,
            tethers: true,
            tether_metric: TetherMetric::Graph,
            grasp_tethers: false,
            grasp_tether_slack: 0.05,
            contact_margin: 0.01,
            attachment_compliance: 0.0,
            edge_contacts: false,
        }
    }
}

impl SolverSettings {
    /// Checks every field; the error names the field and what is valid.
    pub fn validate(&self) -> Result<(), PbdError> {
        if self.substeps == 0 {
            return Err(PbdError::InvalidParameter {
                field: "settings.substeps",
                value: "0".into(),
                expected: "an integer >= 1",
            });
        }
        if self.iterations == 0 {
            return Err(PbdError::InvalidParameter {
                field: "settings.iterations",
                value: "0".into(),
                expected: "an integer >= 1",
            });
        }
        check_param(
            "settings.self_collision_margin",
            self.self_collision_margin,
            0.0,
            false,
            "a finite value >= 0 m",
        )?;
        check_param(
            "settings.grasp_tether_slack",
            self.grasp_tether_slack,
            0.0,
            false,
            "a finite fraction >= 0 of the rest length",
        )?;
        check_param(
            "settings.contact_margin",
            self.contact_margin,
            0.0,
            false,
            "a finite value >= 0 m",
        )?;
        check_param(
            "settings.attachment_compliance",
            self.attachment_compliance,
            0.0,
            false,
            "a finite value >= 0 m/N",
        )?;
        Ok(())
    }
}
