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
//! Contacts use the colliders' friction.
//!
//! The compiled [`SolidModel`] (quadrature data, sparsity, ordering) is built once per scene and
//! shared by every env through `Arc`; each env's [`FemContext`] holds only the state, which is
//! part of the snapshot.

use std::any::Any;
use std::sync::Arc;

use bevy_ecs::prelude::*;
use modesuite_engine::app::SimErrors;
use modesuite_engine::components::DeformableNodes;
use modesuite_engine::coupling::{ContactQuery, NoColliders, Reaction};
use modesuite_engine::registry::{BodyCompileContext, BodyKind, CompiledBody};
use modesuite_engine::scene::{plugin_params_error, ron_options, NodeSelect, SceneError};
use modesuite_engine::state::{StateHasher, Stateful};
use modesuite_engine::{DeformableSystems, Plugin, RigidContext, SimApp, SimSettings};
use nalgebra::Point3;
use serde::Deserialize;

use crate::{FemConfig, FemSolid, Material, SolidModel};

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

/// One solid in an env.
pub struct SolidBody {
    /// The scene object.
    pub entity: Entity,
    /// The solver state.
    pub solid: FemSolid,
}

/// Every solid of one env (a resource, part of the env state).
#[derive(Resource, Default)]
pub struct FemContext {
    /// Solids in spawn order.
    pub solids: Vec<SolidBody>,
}

impl FemContext {
    /// The solid of an entity.
    pub fn solid_of(&self, entity: Entity) -> Option<&FemSolid> {
        self.solids
            .iter()
            .find(|s| s.entity == entity)
            .map(|s| &s.solid)
    }

    /// The solid of an entity, mutable (grasps, attachments).
    pub fn solid_of_mut(&mut self, entity: Entity) -> Option<&mut FemSolid> {
        self.solids
            .iter_mut()
            .find(|s| s.entity == entity)
            .map(|s| &mut s.solid)
    }
}

impl Stateful for FemContext {
    fn save_state(&self) -> Box<dyn Any + Send + Sync> {
        Box::new(
            self.solids
                .iter()
                .map(|s| s.solid.get_state())
                .collect::<Vec<_>>(),
        )
    }

    fn load_state(&mut self, state: &(dyn Any + Send + Sync)) {
        if let Some(states) = state.downcast_ref::<Vec<Vec<f64>>>() {
            for (s, st) in self.solids.iter_mut().zip(states) {
                // A state taken from this same context always has the right size.
                let _ = s.solid.set_state(st);
            }
        }
    }

    fn hash_state(&self, h: &mut StateHasher) {
        for s in &self.solids {
            for x in s.solid.get_state() {
                h.write_f64(x);
            }
        }
    }
}

/// Adds the `fem.solid` body kind and the solid systems.
pub struct FemPlugin;

impl Plugin for FemPlugin {
    fn name(&self) -> &str {
        "modesuite.fem"
    }

    fn build(&self, app: &mut SimApp) {
        app.insert_resource(FemContext::default());
        app.register_stateful::<FemContext>();
        app.register_stateful_component::<DeformableNodes>();
        app.register_body_kind(Arc::new(SolidKind));
        app.add_systems(
            modesuite_engine::Substep,
            fem_step.in_set(DeformableSystems::Elastic),
        );
        app.add_systems(
            modesuite_engine::PhysicsStep,
            fem_writeback.in_set(DeformableSystems::Elastic),
        );
    }
}

/// The `fem.solid` body kind.
pub struct SolidKind;

impl BodyKind for SolidKind {
    fn name(&self) -> &str {
        "fem.solid"
    }

    fn description(&self) -> &str {
        "elastic solid: 10-node tetrahedra, Stable Neo-Hookean, implicit (rods, belts, tori)"
    }

    fn compile(&self, ctx: &BodyCompileContext) -> Result<CompiledBody, SceneError> {
        let path = format!("{}.body.params", ctx.path);
        let params: SolidParams = ron_options()
            .from_str(ctx.params_ron)
            .map_err(|e| plugin_params_error(ctx.source, ctx.params_ron, &path, &e))?;
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
        let pose = ctx.object.pose.isometry();
        let nodes: Vec<_> = mesh
            .nodes
            .iter()
            .map(|p| (pose * Point3::from(*p)).coords)
            .collect();
        let config = FemConfig {
            rayleigh_mass: params.rayleigh_mass.unwrap_or(0.0),
            rayleigh_stiffness: params.rayleigh_stiffness.unwrap_or(0.0),
            ..FemConfig::default()
        };
        config
            .validate()
            .map_err(|e| SceneError::semantic(path.clone(), "(damping)", e.to_string()))?;
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
        app.world
            .entity_mut(entity)
            .insert(DeformableNodes(solid.positions().to_vec()));
        app.world
            .resource_mut::<FemContext>()
            .solids
            .push(SolidBody { entity, solid });
        Ok(())
    }
}

fn fem_step(
    mut ctx: ResMut<FemContext>,
    rigid: Option<ResMut<RigidContext>>,
    settings: Res<SimSettings>,
    mut errors: ResMut<SimErrors>,
) {
    let dt = settings.substep_dt();
    let mut reactions: Vec<Reaction> = Vec::new();
    let mut rigid = rigid;
    for body in &mut ctx.solids {
        let query: &dyn ContactQuery = match rigid.as_deref() {
            Some(r) => r,
            None => &NoColliders,
        };
        if let Err(e) = body.solid.step(dt, settings.gravity, query, &mut reactions) {
            errors.raise(format!("solid {:?}: {e}", body.entity));
        }
    }
    if let Some(r) = rigid.as_deref_mut() {
        for re in reactions {
            if re.body != u32::MAX {
                r.push_reaction(re);
            }
        }
    }
}

fn fem_writeback(ctx: Res<FemContext>, mut q: Query<&mut DeformableNodes>) {
    for body in &ctx.solids {
        if let Ok(mut nodes) = q.get_mut(body.entity) {
            nodes.0.clear();
            nodes.0.extend_from_slice(body.solid.positions());
        }
    }
}
