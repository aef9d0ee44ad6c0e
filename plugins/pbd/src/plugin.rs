//! The `pbd.cloth` body kind: cloth objects in scenes, stepped inside the engine's substeps.
//!
//! ```ron
//! (name: "sheet", shape: Grid(size: (1.0, 1.0), resolution: (25, 25)), pose: (pos: (0.0, 0.0, 1.0)),
//!  body: Kind(kind: "pbd.cloth", params: (
//!      areal_density: 0.2, stretch_compliance: 1e-4, bending_compliance: 1e4,
//!      pins: [Near(at: (-0.5, 0.5, 0.0), radius: 0.01)],
//!      groups: {"handle": Near(at: (0.0, -0.5, 0.0), radius: 0.05)},
//!  )))
//! ```
//! Every material and solver field is optional (defaults of [`ClothMaterial`] and
//! [`SolverSettings`]; `friction` defaults to the object's material). `pins` fix the selected
//! particles ([`NodeSelect`], object frame) to the world; `groups` name particle sets (a task's
//! handle, tracked points).
//!
//! State: [`PbdContext`] holds every cloth of the env and is part of the snapshot. The cloth step
//! runs once per engine substep in `SubstepSystems::Solve`, before the rigid step, queries the
//! rigid world through the engine's coupling API and pushes its reactions to the rigid bodies.

use std::collections::BTreeMap;
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::coupling::{ContactQuery, Reaction};
use modesuite_engine::deformable::{add_deformable_systems, DeformableContext, DeformableSolver};
use modesuite_engine::registry::{BodyCompileContext, BodyKind, CompiledBody};
use modesuite_engine::scene::{NodeSelect, SceneError};
use modesuite_engine::{DeformableSystems, Plugin, SimApp};
use nalgebra::{Point3, Vector3};
use serde::Deserialize;

use crate::{Cloth, ClothMaterial, SolverSettings};

/// The RON parameters of a `pbd.cloth` object.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClothParams {
    /// Mass per area, kg/m^2.
    #[serde(default)]
    pub areal_density: Option<f64>,
    /// Stretch compliance (see [`ClothMaterial`]).
    #[serde(default)]
    pub stretch_compliance: Option<f64>,
    /// Shear compliance.
    #[serde(default)]
    pub shear_compliance: Option<f64>,
    /// Bending compliance.
    #[serde(default)]
    pub bending_compliance: Option<f64>,
    /// Velocity damping.
    #[serde(default)]
    pub damping: Option<f64>,
    /// Coulomb friction against colliders (default: the object's material).
    #[serde(default)]
    pub friction: Option<f64>,
    /// Collision thickness, m.
    #[serde(default)]
    pub thickness: Option<f64>,
    /// Cloth substeps per engine substep.
    #[serde(default)]
    pub substeps: Option<u32>,
    /// Solver iterations per cloth substep.
    #[serde(default)]
    pub iterations: Option<u32>,
    /// Self-collision on or off (default off).
    #[serde(default)]
    pub self_collision: Option<bool>,
    /// Particles pinned to the world.
    #[serde(default)]
    pub pins: Vec<NodeSelect>,
    /// Named particle groups.
    #[serde(default)]
    pub groups: BTreeMap<String, NodeSelect>,
}

/// A compiled cloth object (shared by all envs).
#[derive(Debug, Clone)]
pub struct CompiledCloth {
    /// Rest positions in the world frame, m.
    pub positions: Vec<Vector3<f64>>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Material.
    pub material: ClothMaterial,
    /// Solver settings.
    pub settings: SolverSettings,
    /// Pinned particle sets.
    pub pins: Vec<Vec<u32>>,
    /// Named groups.
    pub groups: Vec<(String, Vec<u32>)>,
}

/// Every cloth of one env (part of the env state).
pub type PbdContext = DeformableContext<Cloth>;

impl DeformableSolver for Cloth {
    fn step_coupled(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<(), String> {
        self.step(dt, gravity, query, reactions)
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
}

/// Adds the `pbd.cloth` body kind and the cloth systems.
pub struct PbdPlugin;

impl Plugin for PbdPlugin {
    fn name(&self) -> &str {
        "modesuite.pbd"
    }

    fn build(&self, app: &mut SimApp) {
        add_deformable_systems::<Cloth>(app, DeformableSystems::Cloth);
        app.register_body_kind(Arc::new(ClothKind));
    }
}

/// The `pbd.cloth` body kind.
pub struct ClothKind;

impl BodyKind for ClothKind {
    fn name(&self) -> &str {
        "pbd.cloth"
    }

    fn description(&self) -> &str {
        "XPBD cloth from any triangle surface (Grid sheets, meshes), with pins and named groups"
    }

    fn compile(&self, ctx: &BodyCompileContext) -> Result<CompiledBody, SceneError> {
        let path = format!("{}.body.params", ctx.path);
        let params: ClothParams = ctx.parse_params()?;
        let surface = ctx.object.shape.surface(ctx.shapes).map_err(|e| {
            SceneError::semantic(format!("{}.shape", ctx.path), "(shape)", e.to_string())
        })?;
        if surface.triangles.is_empty() {
            return Err(SceneError::semantic(
                format!("{}.shape", ctx.path),
                "(shape)",
                "a cloth needs a triangle surface (Grid, Plane, Mesh, ...)",
            ));
        }
        let d = ClothMaterial::default();
        let material = ClothMaterial {
            areal_density: params.areal_density.unwrap_or(d.areal_density),
            stretch_compliance: params.stretch_compliance.unwrap_or(d.stretch_compliance),
            shear_compliance: params.shear_compliance.unwrap_or(d.shear_compliance),
            bending_compliance: params.bending_compliance.unwrap_or(d.bending_compliance),
            damping: params.damping.unwrap_or(d.damping),
            friction: params.friction.unwrap_or(ctx.material.friction),
            thickness: params.thickness.unwrap_or(d.thickness),
        };
        material
            .validate()
            .map_err(|e| SceneError::semantic(path.clone(), "(material)", e.to_string()))?;
        let s = SolverSettings::default();
        let settings = SolverSettings {
            substeps: params.substeps.unwrap_or(s.substeps),
            iterations: params.iterations.unwrap_or(s.iterations),
            self_collision: params.self_collision.unwrap_or(s.self_collision),
            ..s
        };
        settings
            .validate()
            .map_err(|e| SceneError::semantic(path.clone(), "(settings)", e.to_string()))?;
        let pose = ctx.object.pose.isometry();
        let pins = params
            .pins
            .iter()
            .enumerate()
            .map(|(i, p)| p.select(&format!("{path}.pins[{i}]"), &surface.positions))
            .collect::<Result<Vec<_>, _>>()?;
        let groups = params
            .groups
            .iter()
            .map(|(name, g)| {
                g.select(&format!("{path}.groups[\"{name}\"]"), &surface.positions)
                    .map(|sel| (name.clone(), sel))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let positions = surface
            .positions
            .iter()
            .map(|p| (pose * Point3::from(*p)).coords)
            .collect();
        let compiled = CompiledCloth {
            positions,
            triangles: surface.triangles,
            material,
            settings,
            pins,
            groups,
        };
        // Build once here so that every construction error is a compile error, not a spawn error.
        Cloth::new(&compiled.positions, &compiled.triangles, material, settings)
            .map_err(|e| SceneError::semantic(path, "(cloth)", e.to_string()))?;
        Ok(Arc::new(compiled))
    }

    fn spawn(
        &self,
        app: &mut SimApp,
        entity: Entity,
        body: &CompiledBody,
    ) -> Result<(), SceneError> {
        let c = body.downcast_ref::<CompiledCloth>().ok_or_else(|| {
            SceneError::semantic(
                "pbd.cloth",
                "(compiled body)",
                "a body compiled by pbd.cloth",
            )
        })?;
        let err = |e: crate::PbdError| SceneError::semantic("pbd.cloth", "(spawn)", e.to_string());
        let mut cloth =
            Cloth::new(&c.positions, &c.triangles, c.material, c.settings).map_err(err)?;
        for pin in &c.pins {
            cloth.pin_to_world(pin).map_err(err)?;
        }
        for (name, g) in &c.groups {
            cloth.add_group(name, g).map_err(err)?;
        }
        PbdContext::spawn_into(app, entity, cloth);
        Ok(())
    }
}
