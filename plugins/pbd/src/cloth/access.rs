//! Accessors and setters of the cloth's state, named particle groups, and measures (stretch,
//! covered area).

use super::{check_positions, Cloth, Region, StretchStats};
use crate::error::PbdError;
use crate::material::{ClothMaterial, SolverSettings};
use modesuite_engine::surface::Surface;
use nalgebra::Vector3;

impl Cloth {
    // ------------------------------------------------------------------ accessors

    /// Number of particles.
    pub fn num_particles(&self) -> usize {
        self.pos.len()
    }
    /// Triangles, `(t, 3)` particle indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    /// Particle positions, `(n, 3)`, world frame, m.
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.pos
    }
    /// Particle velocities, `(n, 3)`, world frame, m/s.
    pub fn velocities(&self) -> &[Vector3<f64>] {
        &self.vel
    }
    /// Rest positions, `(n, 3)`, m.
    pub fn rest_positions(&self) -> &[Vector3<f64>] {
        &self.rest
    }
    /// Particle masses, `(n)`, kg.
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    /// Total mass, kg.
    pub fn total_mass(&self) -> f64 {
        self.mass.iter().sum()
    }
    /// Material parameters.
    pub fn material(&self) -> &ClothMaterial {
        &self.material
    }
    /// Solver settings.
    pub fn settings(&self) -> &SolverSettings {
        &self.settings
    }
    /// Replaces the solver settings (validated first).
    pub fn set_settings(&mut self, settings: SolverSettings) -> Result<(), PbdError> {
        settings.validate()?;
        self.settings = settings;
        self.rebuild_tethers();
        Ok(())
    }
    /// Simulated time, s.
    pub fn time(&self) -> f64 {
        self.time
    }
    /// Steps taken since construction (restored by [`Cloth::set_state`]).
    pub fn step_count(&self) -> u64 {
        self.steps
    }
    /// Positions of the given particles, world frame, m (tracked points).
    pub fn particle_positions(&self, particles: &[u32]) -> Result<Vec<Vector3<f64>>, PbdError> {
        particles
            .iter()
            .map(|&p| {
                self.pos
                    .get(p as usize)
                    .copied()
                    .ok_or_else(|| PbdError::Unknown(format!("particle {p}")))
            })
            .collect()
    }
    /// Kinetic energy, J.
    pub fn kinetic_energy(&self) -> f64 {
        self.vel
            .iter()
            .zip(&self.mass)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum()
    }

    /// Sets all positions (m) and zeroes the velocities (e.g. to start from a folded shape).
    pub fn set_positions(&mut self, positions: &[Vector3<f64>]) -> Result<(), PbdError> {
        if positions.len() != self.pos.len() {
            return Err(PbdError::InvalidParameter {
                field: "positions",
                value: format!("{} entries", positions.len()),
                expected: "one position per particle",
            });
        }
        check_positions(positions)?;
        self.pos.copy_from_slice(positions);
        self.vel.iter_mut().for_each(|v| *v = Vector3::zeros());
        Ok(())
    }

    /// Sets all velocities (m/s), e.g. a push; pinned and attached particles (zero inverse mass)
    /// keep following their anchors, so their entries are ignored.
    pub fn set_velocities(&mut self, velocities: &[Vector3<f64>]) -> Result<(), PbdError> {
        if velocities.len() != self.vel.len() {
            return Err(PbdError::InvalidParameter {
                field: "velocities",
                value: format!("{} entries", velocities.len()),
                expected: "one velocity per particle",
            });
        }
        if !velocities.iter().all(|v| v.iter().all(|x| x.is_finite())) {
            return Err(PbdError::InvalidParameter {
                field: "velocities",
                value: "a non-finite entry".to_string(),
                expected: "finite velocities, m/s",
            });
        }
        for ((v, new), w) in self.vel.iter_mut().zip(velocities).zip(&self.inv_mass) {
            if *w > 0.0 {
                *v = *new;
            }
        }
        Ok(())
    }

    // ------------------------------------------------------------------ groups

    /// Names a particle group (a handle or a tracked set). Replaces an existing group.
    pub fn add_group(&mut self, name: &str, particles: &[u32]) -> Result<(), PbdError> {
        if let Some(&p) = particles.iter().find(|&&p| p as usize >= self.pos.len()) {
            return Err(PbdError::Unknown(format!("particle {p} in group '{name}'")));
        }
        self.groups.insert(name.to_string(), particles.to_vec());
        Ok(())
    }
    /// The particles of a named group.
    pub fn group(&self, name: &str) -> Result<&[u32], PbdError> {
        self.groups
            .get(name)
            .map(|v| v.as_slice())
            .ok_or_else(|| PbdError::Unknown(format!("particle group '{name}'")))
    }
    /// Positions of a named group's particles, world frame, m.
    pub fn group_positions(&self, name: &str) -> Result<Vec<Vector3<f64>>, PbdError> {
        let g = self.group(name)?;
        self.particle_positions(g)
    }
    /// Names of all groups, sorted.
    pub fn group_names(&self) -> Vec<String> {
        self.groups.keys().cloned().collect()
    }

    // ------------------------------------------------------------------ measures

    /// Mean and maximum strain over the mesh edges (the distance constraints for ropes).
    pub fn stretch_stats(&self) -> StretchStats {
        let mut sum = 0.0;
        let mut sum_abs = 0.0;
        let mut max = f64::NEG_INFINITY;
        for (e, &l0) in self.edge.iter().zip(&self.edge_rest) {
            if l0 <= 0.0 {
                continue;
            }
            let l = (self.pos[e[0] as usize] - self.pos[e[1] as usize]).norm();
            let s = l / l0 - 1.0;
            sum += s;
            sum_abs += s.abs();
            max = max.max(s);
        }
        let m = self.edge.len().max(1) as f64;
        StretchStats {
            mean: sum / m,
            mean_abs: sum_abs / m,
            max,
        }
    }

    /// The cloth's surface (particles and triangles) for the engine's surface measures.
    pub fn surface(&self) -> Surface<'_> {
        Surface {
            nodes: &self.pos,
            triangles: &self.triangles,
        }
    }

    /// Fraction of particles whose xy projection lies inside `region` (Uncover: what is still
    /// covered).
    pub fn fraction_above(&self, region: &Region) -> f64 {
        self.surface().fraction_inside_xy(region)
    }

    /// Area of `region` covered by the cloth's xy projection, m^2 (Cover), estimated on a
    /// `resolution` x `resolution` grid of sample points (cell centres); the error is at most the
    /// region's boundary cells.
    pub fn covered_area(&self, region: &Region, resolution: usize) -> f64 {
        self.covered_area_above(region, resolution, f64::NEG_INFINITY)
    }

    /// [`Cloth::covered_area`] counting only the triangles whose three particles are higher
    /// than `above` (m): Cover's gap is covered by cloth spanning it, not by cloth lying on the
    /// floor under it ([`Surface::covered_area_above`]).
    pub fn covered_area_above(&self, region: &Region, resolution: usize, above: f64) -> f64 {
        self.surface().covered_area_above(region, resolution, above)
    }
}
