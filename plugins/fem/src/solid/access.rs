//! Building a solid, its accessors and setters, and derived quantities (energies, momentum,
//! volume, strains, embedded points).

use super::{finite3, FemConfig, FemSolid, PointEmbedding};
use crate::element::{shape_values, NQ};
use crate::error::FemError;
use crate::material::Material;
use crate::model::SolidModel;
use crate::warp::Warp;
use nalgebra::{Matrix3, Vector3};
use std::sync::Arc;

impl FemSolid {
    /// Builds a solid from a positively oriented linear tet mesh (`nodes` in m, world frame); the
    /// 10-node elements are created here. Starts at rest with zero velocity and no constraints.
    pub fn new(
        nodes: &[Vector3<f64>],
        tets: &[[u32; 4]],
        material: Material,
        config: FemConfig,
    ) -> Result<Self, FemError> {
        config.validate()?;
        let model = SolidModel::new(nodes, tets, material)?;
        Ok(Self::from_model(Arc::new(model), config))
    }

    /// Builds a solid from an already compiled model, shared (e.g. by all environments of a
    /// vectorised env); the solid starts at the rest shape.
    pub fn from_model(model: Arc<SolidModel>, config: FemConfig) -> Self {
        let n = model.n_nodes();
        let nb = model.pattern.cols.len();
        let z = vec![Vector3::zeros(); n];
        FemSolid {
            pos: model.mesh.rest.clone(),
            vel: z.clone(),
            ext_force: z.clone(),
            impulse: Vec::new(),
            fric: z.clone(),
            steps: 0,
            world: Vec::new(),
            attachments: Vec::new(),
            grasps: Vec::new(),
            poses: Vec::new(),
            poses_start: Vec::new(),
            next_id: 1,
            precond_at: None,
            precond: None,
            profile_costs: model.profile.costs(),
            precond_mat: Vec::new(),
            factor_anchor: Vec::new(),
            precond_mat_key: None,
            precond_gen: 0,
            constraint_version: 0,
            stiffness_scale: 1.0,
            hess: vec![Matrix3::zeros(); nb],
            grad: z.clone(),
            egrad: z.clone(),
            delta: z.clone(),
            trial: z.clone(),
            xhat: z.clone(),
            xprev: z.clone(),
            vprev: z,
            cg: [Vec::new(), Vec::new(), Vec::new()],
            active: Vec::new(),
            candidates: Vec::new(),
            penalties: Vec::new(),
            penalty_factor: Vec::new(),
            normals: Vec::new(),
            con_forces: Vec::new(),
            contact_memory: Vec::new(),
            trial_egrad: vec![Vector3::zeros(); n],
            trial_grad: vec![Vector3::zeros(); n],
            grad_at_pos: None,
            last_linear_iterations: 0,
            warp: Warp::default(),
            model,
            config,
        }
    }

    // ----------------------------------------------------------------- accessors

    /// The compiled model (mesh, masses, quadrature data).
    pub fn model(&self) -> &SolidModel {
        &self.model
    }

    /// The shared handle of the compiled model (to build more solids from it).
    pub fn shared_model(&self) -> Arc<SolidModel> {
        Arc::clone(&self.model)
    }

    /// Solver settings.
    pub fn config(&self) -> &FemConfig {
        &self.config
    }

    /// Replaces the solver settings.
    pub fn set_config(&mut self, config: FemConfig) -> Result<(), FemError> {
        config.validate()?;
        self.config = config;
        Ok(())
    }

    /// Number of nodes (corners first, then edge nodes).
    pub fn n_nodes(&self) -> usize {
        self.pos.len()
    }

    /// Current node positions (world frame, m).
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.pos
    }

    /// Current node velocities (world frame, m/s).
    pub fn velocities(&self) -> &[Vector3<f64>] {
        &self.vel
    }

    /// Rest node positions (m).
    pub fn rest_positions(&self) -> &[Vector3<f64>] {
        &self.model.mesh.rest
    }

    /// Lumped node masses (kg).
    pub fn masses(&self) -> &[f64] {
        &self.model.mass
    }

    /// Number of completed steps.
    pub fn step_count(&self) -> u64 {
        self.steps
    }

    /// Sets all node positions (m) and velocities (m/s), e.g. for initial conditions.
    pub fn set_positions_velocities(
        &mut self,
        pos: &[Vector3<f64>],
        vel: &[Vector3<f64>],
    ) -> Result<(), FemError> {
        if pos.len() != self.n_nodes() || vel.len() != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "expected {} positions and velocities",
                self.n_nodes()
            )));
        }
        if !pos.iter().chain(vel).all(finite3) {
            return Err(FemError::NonFiniteInput("positions or velocities"));
        }
        self.pos.copy_from_slice(pos);
        self.vel.copy_from_slice(vel);
        self.contact_memory.clear();
        Ok(())
    }

    /// Adds impulses (N s, world frame, one per node) to be applied over the next step, as a
    /// force of impulse / dt (contacts of other deformables push the solid this way; the
    /// implicit step spreads them through the solid, where a velocity kick on a light node
    /// would throw it far off before the solve). They are cleared after that step, failed or
    /// not.
    pub fn add_impulses(&mut self, impulses: &[Vector3<f64>]) -> Result<(), FemError> {
        if impulses.len() != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "expected {} impulses",
                self.n_nodes()
            )));
        }
        if !impulses.iter().all(finite3) {
            return Err(FemError::NonFiniteInput("impulses"));
        }
        if self.impulse.is_empty() {
            self.impulse = impulses.to_vec();
        } else {
            for (a, j) in self.impulse.iter_mut().zip(impulses) {
                *a += j;
            }
        }
        Ok(())
    }

    /// Sets the external dead load on every node (N, world frame), kept until changed.
    pub fn set_external_forces(&mut self, forces: &[Vector3<f64>]) -> Result<(), FemError> {
        if forces.len() != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "expected {} forces",
                self.n_nodes()
            )));
        }
        if !forces.iter().all(finite3) {
            return Err(FemError::NonFiniteInput("external forces"));
        }
        self.ext_force.copy_from_slice(forces);
        Ok(())
    }

    /// Indices of nodes whose current position satisfies `pred` (e.g. inside a finger volume).
    pub fn nodes_where(&self, pred: impl Fn(&Vector3<f64>) -> bool) -> Vec<u32> {
        (0..self.n_nodes() as u32)
            .filter(|&i| pred(&self.pos[i as usize]))
            .collect()
    }

    /// Indices of nodes whose rest position satisfies `pred` (e.g. the clamped end face).
    pub fn rest_nodes_where(&self, pred: impl Fn(&Vector3<f64>) -> bool) -> Vec<u32> {
        (0..self.n_nodes() as u32)
            .filter(|&i| pred(&self.model.mesh.rest[i as usize]))
            .collect()
    }

    pub(super) fn check_nodes(&self, nodes: &[u32]) -> Result<(), FemError> {
        for &n in nodes {
            if n as usize >= self.n_nodes() {
                return Err(FemError::NodeOutOfRange {
                    node: n,
                    count: self.n_nodes(),
                });
            }
        }
        Ok(())
    }

    // ----------------------------------------------------------------- derived quantities

    /// Elastic energy (J).
    pub fn elastic_energy(&self) -> f64 {
        self.model.energy_only(&self.pos, None).energy * self.stiffness_scale
    }

    /// This solid's Young's modulus (Pa): the model's times [`FemSolid::set_youngs_modulus`]'s
    /// scale.
    pub fn youngs_modulus(&self) -> f64 {
        self.model.material.youngs_modulus * self.stiffness_scale
    }

    /// Sets this solid's Young's modulus (Pa, finite and > 0; the Poisson ratio and density stay
    /// the model's): a per-env material randomisation. Takes effect from the next step.
    pub fn set_youngs_modulus(&mut self, youngs_modulus: f64) -> Result<(), FemError> {
        if !(youngs_modulus.is_finite() && youngs_modulus > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "youngs_modulus",
                value: youngs_modulus,
                expected: "finite and > 0 Pa",
            });
        }
        self.stiffness_scale = youngs_modulus / self.model.material.youngs_modulus;
        self.precond = None;
        self.constraint_version += 1;
        Ok(())
    }

    /// Kinetic energy (J) with the lumped masses.
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * self
            .vel
            .iter()
            .zip(&self.model.mass)
            .map(|(v, m)| m * v.norm_squared())
            .sum::<f64>()
    }

    /// Gravitational potential energy `-sum m g . x` (J).
    pub fn gravity_energy(&self, gravity: &Vector3<f64>) -> f64 {
        -self
            .pos
            .iter()
            .zip(&self.model.mass)
            .map(|(x, m)| m * gravity.dot(x))
            .sum::<f64>()
    }

    /// Linear momentum (kg m/s).
    pub fn momentum(&self) -> Vector3<f64> {
        self.vel
            .iter()
            .zip(&self.model.mass)
            .map(|(v, m)| v * *m)
            .sum()
    }

    /// Number of quadrature points with `det F <= 0`.
    pub fn inverted_count(&self) -> usize {
        self.model.energy_only(&self.pos, None).inverted
    }

    /// Current volume (m^3) as the sum of signed volumes of the corner tetrahedra.
    pub fn volume(&self) -> f64 {
        self.model
            .mesh
            .elements
            .iter()
            .map(|e| {
                let x = [0, 1, 2, 3].map(|k| self.pos[e[k] as usize]);
                (x[1] - x[0]).cross(&(x[2] - x[0])).dot(&(x[3] - x[0])) / 6.0
            })
            .sum()
    }

    /// Green strain `E = (F^T F - I) / 2` at every quadrature point, `[element * 4 + q]`.
    pub fn green_strains(&self) -> Vec<Matrix3<f64>> {
        let mut out = Vec::with_capacity(self.model.n_elements() * NQ);
        for e in 0..self.model.n_elements() {
            for q in 0..NQ {
                let f = self.model.deformation_gradient(e, q, &self.pos);
                out.push((f.transpose() * f - Matrix3::identity()) * 0.5);
            }
        }
        out
    }

    /// Largest absolute principal Green strain over all quadrature points.
    pub fn max_strain(&self) -> f64 {
        self.green_strains()
            .iter()
            .map(|e| {
                e.symmetric_eigenvalues()
                    .iter()
                    .fold(0.0f64, |m, v| m.max(v.abs()))
            })
            .fold(0.0, f64::max)
    }

    /// Embeds a rest-frame point (m) in the element that contains it (the most interior one when
    /// on a shared face).
    pub fn embed_point(&self, rest_point: &Vector3<f64>) -> Result<PointEmbedding, FemError> {
        let mut best: Option<(f64, usize, [f64; 4])> = None;
        for (e, el) in self.model.mesh.elements.iter().enumerate() {
            let x = [0, 1, 2, 3].map(|k| self.model.mesh.rest[el[k] as usize]);
            let dm = Matrix3::from_columns(&[x[1] - x[0], x[2] - x[0], x[3] - x[0]]);
            let Some(inv) = dm.try_inverse() else {
                continue;
            };
            let b = inv * (rest_point - x[0]);
            let l = [1.0 - b.x - b.y - b.z, b.x, b.y, b.z];
            let worst = l.iter().cloned().fold(f64::INFINITY, f64::min);
            if best.is_none_or(|(w, _, _)| worst > w) {
                best = Some((worst, e, l));
            }
        }
        match best {
            Some((w, e, l)) if w >= -1e-9 => Ok(PointEmbedding {
                element: e as u32,
                weights: shape_values(&l),
            }),
            _ => Err(FemError::PointOutsideMesh {
                point: [rest_point.x, rest_point.y, rest_point.z],
            }),
        }
    }

    /// Embeds `k >= 2` equally spaced rest points from `a` to `b` (e.g. a rod's centre line).
    pub fn embed_line(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
        k: usize,
    ) -> Result<Vec<PointEmbedding>, FemError> {
        let k = k.max(2);
        (0..k)
            .map(|i| self.embed_point(&(a + (b - a) * (i as f64 / (k - 1) as f64))))
            .collect()
    }

    /// Current position (m) of an embedded point.
    pub fn embedded_position(&self, p: &PointEmbedding) -> Vector3<f64> {
        let el = &self.model.mesh.elements[p.element as usize];
        (0..10)
            .map(|a| self.pos[el[a] as usize] * p.weights[a])
            .sum()
    }

    /// Current velocity (m/s) of an embedded point.
    pub fn embedded_velocity(&self, p: &PointEmbedding) -> Vector3<f64> {
        let el = &self.model.mesh.elements[p.element as usize];
        (0..10)
            .map(|a| self.vel[el[a] as usize] * p.weights[a])
            .sum()
    }
}
