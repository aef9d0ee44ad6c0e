//! The `fem.solid` body kind: elastic solids in scenes, stepped inside the engine's substeps.
//!
//! ```ron
//! (name: "rod", shape: Box(size: (1.0, 0.04, 0.04), divisions: (10, 1, 1)),
//!  pose: (pos: (0.5, 0.0, 1.0)),
//!  body: Kind(kind: "fem.solid", params: (
//!      youngs_modulus: 1e8, poisson_ratio: 0.3, density: 1000.0,
//!      fixed: [Box(min: (-0.51, -1.0, -1.0), max: (-0.499, 1.0, 1.0))],
//!  )))
//! ```
//! The shape must be volume-meshable (Box, Cylinder, Sweep, Revolve, Extrude, volume mesh files,
//! generators returning volumes); its linear tets become 10-node tets. `density` defaults to the
//! object's material; `rayleigh_mass` and `rayleigh_stiffness` damp (see [`FemConfig`]); `fixed`
//! clamps the selected nodes ([`NodeSelect`], object frame, all 10-node nodes) to the world.
//! Contacts use the colliders' friction; `penalty_contacts: s` makes them penalty energies
//! (see [`FemConfig::penalty_contacts`]) instead of active-set constraints.
//!
//! The compiled [`SolidModel`] (quadrature data, sparsity, ordering) is built once per scene and
//! shared by every env through `Arc`; each env's [`FemContext`] holds only the state, which is
//! part of the snapshot.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::coupling::{ContactQuery, Reaction};
use modesuite_engine::deformable::{
    add_deformable_systems, DeformableContext, DeformableSolver, FingerVolume,
};
use modesuite_engine::registry::{BodyCompileContext, BodyKind, CompiledBody};
use modesuite_engine::scene::{NodeSelect, SceneError};
use modesuite_engine::{DeformableSystems, Plugin, SimApp};
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::{FemConfig, FemSolid, GraspParams, Material, SolidModel};

/// The RON parameters of a `fem.solid` object.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolidParams {
    /// Young's modulus, Pa.
    pub youngs_modulus: f64,
    /// Poisson ratio, in (-1, 0.5).
    pub poisson_ratio: f64,
    /// Density, kg/m^3 (default: the object's material).
    #[serde(default)]
    pub density: Option<f64>,
    /// Mass-proportional Rayleigh damping, 1/s.
    #[serde(default)]
    pub rayleigh_mass: Option<f64>,
    /// Stiffness-proportional Rayleigh damping, s.
    #[serde(default)]
    pub rayleigh_stiffness: Option<f64>,
    /// Nodes clamped to the world.
    #[serde(default)]
    pub fixed: Vec<NodeSelect>,
    /// Contacts as penalty energies of this stiffness, in units of a node's `m / dt^2`
    /// ([`FemConfig::penalty_contacts`]); default: exact contacts by active-set rounds.
    #[serde(default)]
    pub penalty_contacts: Option<f64>,
}

/// A compiled solid (shared by all envs).
pub struct CompiledSolid {
    /// Elements, masses, sparsity: immutable.
    pub model: Arc<SolidModel>,
    /// Solver settings.
    pub config: FemConfig,
    /// Clamped nodes.
    pub fixed: Vec<u32>,
}

/// Every solid of one env (part of the env state).
pub type FemContext = DeformableContext<FemSolid>;

impl DeformableSolver for FemSolid {
    fn move_rigidly(
        &mut self,
        positions: &[Vector3<f64>],
        rotation: &UnitQuaternion<f64>,
    ) -> Result<(), String> {
        let vel: Vec<Vector3<f64>> = self.velocities().iter().map(|v| rotation * v).collect();
        self.set_positions_velocities(positions, &vel)
            .map_err(|e| e.to_string())
    }

    fn add_velocity(&mut self, dv: &Vector3<f64>) -> Result<(), String> {
        let vel: Vec<Vector3<f64>> = self.velocities().iter().map(|v| v + dv).collect();
        let pos = self.positions().to_vec();
        self.set_positions_velocities(&pos, &vel)
            .map_err(|e| e.to_string())
    }

    fn set_youngs_modulus(&mut self, youngs_modulus: f64) -> Result<(), String> {
        FemSolid::set_youngs_modulus(self, youngs_modulus).map_err(|e| e.to_string())
    }

    fn hold_nodes(
        &mut self,
        body: u32,
        pose: &Isometry3<f64>,
        nodes: &[u32],
        grasp_force_limit: Option<f64>,
    ) -> Result<(), String> {
        let held = match grasp_force_limit {
            Some(limit) => {
                let params = GraspParams::for_gripper(limit, nodes.len());
                self.grasp(body, *pose, nodes, params)
            }
            None => self.attach_to_body(body, *pose, nodes),
        };
        held.map(|_| ()).map_err(|e| e.to_string())
    }

    fn step_coupled(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<(), String> {
        self.step_coupled_at(0.0, dt, gravity, query, reactions)
    }
    fn step_coupled_at(
        &mut self,
        t0: f64,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<(), String> {
        self.step_at(t0, dt, *gravity, query, reactions)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }
    fn node_positions(&self) -> &[Vector3<f64>] {
        self.positions()
    }
    fn save(&self) -> Vec<f64> {
        self.get_state()
    }
    fn load(&mut self, state: &[f64]) -> Result<(), String> {
        self.set_state(state).map_err(|e| e.to_string())
    }
    fn node_velocities(&self) -> Option<&[Vector3<f64>]> {
        Some(self.velocities())
    }
    fn node_masses(&self) -> Option<&[f64]> {
        Some(self.masses())
    }
    fn compression_modulus(&self) -> Option<f64> {
        Some(self.youngs_modulus())
    }
    fn add_node_impulses(&mut self, impulses: &[Vector3<f64>]) -> Result<(), String> {
        self.add_impulses(impulses).map_err(|e| e.to_string())
    }
    fn set_passive_forces(&mut self, forces: &[Vector3<f64>]) -> Result<(), String> {
        self.set_external_forces(forces).map_err(|e| e.to_string())
    }
    fn follow_bodies(
        &mut self,
        pose_of: &dyn Fn(u32) -> Option<Isometry3<f64>>,
    ) -> Result<(), String> {
        for b in self.attached_bodies() {
            if let Some(p) = pose_of(b) {
                self.set_body_pose(b, p).map_err(|e| e.to_string())?;
            }
        }
        Ok(())
    }
    fn grasped_by(&self, body: u32) -> bool {
        !self.grasps_of(body).is_empty()
    }
    fn grasp_volume(
        &mut self,
        body: u32,
        pose: &Isometry3<f64>,
        volume: &FingerVolume,
        force_limit: f64,
    ) -> Result<(), String> {
        let nodes = self.nodes_where(|p| volume.contains(p));
        if nodes.is_empty() {
            return Ok(());
        }
        let params = GraspParams::for_gripper(force_limit, nodes.len());
        self.grasp(body, *pose, &nodes, params)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }
    fn release_body(&mut self, body: u32) -> Result<(), String> {
        for id in self.grasps_of(body) {
            self.release_grasp(id).map_err(|e| e.to_string())?;
        }
        Ok(())
    }
    fn grasped_nodes(&self, out: &mut Vec<u32>) {
        FemSolid::grasped_nodes(self, out);
    }
    fn contact_nodes(&self, out: &mut Vec<u32>) {
        FemSolid::contact_nodes(self, out);
    }
}

/// Largest `fem.solid` mesh a scene may ask for, in (linear) tetrahedra.
pub const MAX_TETRAHEDRA: usize = 20_000;

/// Adds the `fem.solid` body kind and the solid systems.
pub struct FemPlugin;

impl Plugin for FemPlugin {
    fn name(&self) -> &str {
        "modesuite.fem"
    }

    fn build(&self, app: &mut SimApp) {
        add_deformable_systems::<FemSolid>(app, DeformableSystems("fem.solid"));
        app.register_body_kind(Arc::new(SolidKind));
    }
}

/// The `fem.solid` body kind.
pub struct SolidKind;

impl BodyKind for SolidKind {
    fn name(&self) -> &str {
        "fem.solid"
    }

    /// The boundary faces, each split at its edge nodes into four (10-node tetrahedra) where
    /// it has them.
    fn surface_triangles(&self, body: &CompiledBody) -> Option<Vec<[u32; 3]>> {
        let solid = body.downcast_ref::<CompiledSolid>()?;
        let mesh = &solid.model.mesh;
        let mut tris = Vec::with_capacity(mesh.boundary_faces.len() * 4);
        for f in &mesh.boundary_faces {
            let [a, b, c] = *f;
            match (
                mesh.edge_node(a, b),
                mesh.edge_node(b, c),
                mesh.edge_node(c, a),
            ) {
                (Some(ab), Some(bc), Some(ca)) => {
                    tris.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
                }
                _ => tris.push(*f),
            }
        }
        Some(tris)
    }

    fn description(&self) -> &str {
        "elastic solid: 10-node tetrahedra, Stable Neo-Hookean, implicit (rods, belts, tori)"
    }

    fn compile(&self, ctx: &BodyCompileContext) -> Result<CompiledBody, SceneError> {
        let path = format!("{}.body.params", ctx.path);
        let params: SolidParams = ctx.parse_params()?;
        let density = params.density.unwrap_or(ctx.material.density);
        let material = Material::new(params.youngs_modulus, params.poisson_ratio, density)
            .map_err(|e| {
                SceneError::semantic(
                    path.clone(),
                    format!(
                        "(youngs_modulus: {}, poisson_ratio: {}, density: {density})",
                        params.youngs_modulus, params.poisson_ratio
                    ),
                    e.to_string(),
                )
            })?;
        let mesh = ctx.object.shape.volume(ctx.shapes).map_err(|e| {
            SceneError::semantic(format!("{}.shape", ctx.path), "(shape)", e.to_string())
        })?;
        if mesh.tets.len() > MAX_TETRAHEDRA {
            return Err(SceneError::semantic(
                format!("{}.shape", ctx.path),
                format!("{} tetrahedra", mesh.tets.len()),
                format!(
                    "at most {MAX_TETRAHEDRA} tetrahedra for a fem.solid (10-node elements and a direct solver: a step of 4,000 already takes seconds); coarsen the mesh (fewer divisions or segments)"
                ),
            ));
        }
        let pose = ctx.object.pose.isometry();
        let nodes: Vec<_> = mesh
            .nodes
            .iter()
            .map(|p| (pose * Point3::from(*p)).coords)
            .collect();
        let config = FemConfig {
            rayleigh_mass: params.rayleigh_mass.unwrap_or(0.0),
            rayleigh_stiffness: params.rayleigh_stiffness.unwrap_or(0.0),
            penalty_contacts: params.penalty_contacts.unwrap_or(0.0),
            ..FemConfig::default()
        };
        config.validate().map_err(|e| {
            SceneError::semantic(path.clone(), "(damping, penalty_contacts)", e.to_string())
        })?;
        let model = Arc::new(
            SolidModel::new(&nodes, &mesh.tets, material)
                .map_err(|e| SceneError::semantic(path.clone(), "(mesh)", e.to_string()))?,
        );
        // Select among all 10-node nodes, in the object frame of the rest shape.
        let probe = FemSolid::from_model(model.clone(), config);
        let inv = pose.inverse();
        let rest_local: Vec<_> = probe
            .rest_positions()
            .iter()
            .map(|p| (inv * Point3::from(*p)).coords)
            .collect();
        let mut fixed = Vec::new();
        for (i, sel) in params.fixed.iter().enumerate() {
            fixed.extend(sel.select(&format!("{path}.fixed[{i}]"), &rest_local)?);
        }
        fixed.sort_unstable();
        fixed.dedup();
        Ok(Arc::new(CompiledSolid {
            model,
            config,
            fixed,
        }))
    }

    fn spawn(
        &self,
        app: &mut SimApp,
        entity: Entity,
        body: &CompiledBody,
    ) -> Result<(), SceneError> {
        let c = body.downcast_ref::<CompiledSolid>().ok_or_else(|| {
            SceneError::semantic(
                "fem.solid",
                "(compiled body)",
                "a body compiled by fem.solid",
            )
        })?;
        let mut solid = FemSolid::from_model(c.model.clone(), c.config);
        if !c.fixed.is_empty() {
            solid
                .fix_nodes(&c.fixed)
                .map_err(|e| SceneError::semantic("fem.solid", "(fixed)", e.to_string()))?;
        }
        FemContext::spawn_into(app, entity, solid);
        Ok(())
    }
}
