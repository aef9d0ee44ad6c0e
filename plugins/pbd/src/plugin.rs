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
//! handle, tracked points); `fold: Some((at: 0.0, radius: 0.01))` starts the sheet folded onto
//! itself ([`crate::fold_positions`]); `drags: [(select: ..., velocity: (0.1, 0.0, 0.0), start:
//! 1.0, stop: 4.0)]` moves particle sets at constant velocity (scripted handles). Selections
//! apply to the flat rest shape.
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
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::lanes::RowCache;
use crate::{Cloth, ClothMaterial, OrientedBox, SolverSettings};

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
    /// Tethers anchored at grasped particles too (default off, see
    /// [`SolverSettings::grasp_tethers`]).
    #[serde(default)]
    pub grasp_tethers: Option<bool>,
    /// Particles pinned to the world.
    #[serde(default)]
    pub pins: Vec<NodeSelect>,
    /// Named particle groups.
    #[serde(default)]
    pub groups: BTreeMap<String, NodeSelect>,
    /// Start folded onto itself (the flat shape stays the rest shape).
    #[serde(default)]
    pub fold: Option<FoldParams>,
    /// Particle sets moved at constant velocity during a time window (scripted handles).
    #[serde(default)]
    pub drags: Vec<DragParams>,
}

/// A fold of the sheet in its own (object) frame, see [`crate::fold_positions`]: the material
/// beyond the line `x = at` wraps around a half-cylinder of radius `radius` and lies on top.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FoldParams {
    /// Where the fold starts along the object's x axis, m.
    pub at: f64,
    /// Fold radius, m (> 0; at least the thickness keeps the layers apart).
    pub radius: f64,
}

/// Particles pinned to a handle that moves at constant velocity during a time window and holds
/// still before and after ([`Cloth::drive_particles`]).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DragParams {
    /// The particles (object frame, selected in the flat rest shape).
    pub select: NodeSelect,
    /// Velocity, m/s, world frame.
    pub velocity: (f64, f64, f64),
    /// Start of the motion, s of simulated time.
    #[serde(default)]
    pub start: f64,
    /// End of the motion, s.
    pub stop: f64,
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
    /// Initial positions when they differ from the rest shape (a folded start), world frame, m.
    pub initial: Option<Vec<Vector3<f64>>>,
    /// Driven particle sets: particles, velocity m/s, start s, stop s.
    pub drags: Vec<(Vec<u32>, Vector3<f64>, f64, f64)>,
    /// Solver rows shared by the envs' cloths (a cache).
    rows: Arc<RowCache>,
}

/// Every cloth of one env (part of the env state).
pub type PbdContext = DeformableContext<Cloth>;

impl DeformableSolver for Cloth {
    /// The particles move; their velocities are kept as they are.
    fn move_rigidly(
        &mut self,
        positions: &[Vector3<f64>],
        rotation: &UnitQuaternion<f64>,
    ) -> Result<(), String> {
        let _ = rotation;
        self.set_positions(positions).map_err(|e| e.to_string())
    }

    fn add_velocity(&mut self, dv: &Vector3<f64>) -> Result<(), String> {
        let vel: Vec<Vector3<f64>> = self.velocities().iter().map(|v| v + dv).collect();
        self.set_velocities(&vel).map_err(|e| e.to_string())
    }

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
    fn node_masses(&self) -> Option<&[f64]> {
        Some(self.masses())
    }
    /// Pinned and held particles keep their velocities.
    fn add_node_impulses(&mut self, impulses: &[Vector3<f64>]) -> Result<(), String> {
        if impulses.len() != self.masses().len() {
            return Err(format!(
                "{} impulses for {} particles",
                impulses.len(),
                self.masses().len()
            ));
        }
        let vel: Vec<Vector3<f64>> = self
            .velocities()
            .iter()
            .zip(impulses)
            .zip(self.masses())
            .map(|((v, j), &m)| if m > 0.0 { v + j / m } else { *v })
            .collect();
        self.set_velocities(&vel).map_err(|e| e.to_string())
    }
    fn follow_bodies(
        &mut self,
        pose_of: &dyn Fn(u32) -> Option<Isometry3<f64>>,
    ) -> Result<(), String> {
        for (frame, body) in self.body_frames() {
            if let Some(p) = pose_of(body) {
                self.set_frame_pose(frame, p).map_err(|e| e.to_string())?;
            }
        }
        Ok(())
    }
    fn grasped_by(&self, body: u32) -> bool {
        self.frame_of_body(body)
            .is_some_and(|f| !self.grasps_on(f).is_empty())
    }
    fn grasp_volume(
        &mut self,
        body: u32,
        pose: &Isometry3<f64>,
        volume: &OrientedBox,
        force_limit: f64,
    ) -> Result<(), String> {
        let err = |e: crate::PbdError| e.to_string();
        let frame = match self.frame_of_body(body) {
            Some(f) => f,
            // A frame only once something is inside, so grippers that never touch the cloth
            // leave its state alone.
            None if self.positions().iter().any(|p| volume.contains(p)) => {
                self.add_frame(*pose, body).map_err(err)?
            }
            None => return Ok(()),
        };
        self.grasp(frame, volume, force_limit)
            .map(|_| ())
            .map_err(err)
    }
    fn release_body(&mut self, body: u32) -> Result<(), String> {
        if let Some(f) = self.frame_of_body(body) {
            for id in self.grasps_on(f) {
                self.release(id).map_err(|e| e.to_string())?;
            }
        }
        Ok(())
    }
    fn grasped_nodes(&self, out: &mut Vec<u32>) {
        self.grasped_particles(out);
    }
    fn contact_nodes(&self, out: &mut Vec<u32>) {
        self.contact_particles(out);
    }
}

/// Largest `pbd.cloth` a scene may ask for, in particles (surface vertices).
pub const MAX_PARTICLES: usize = 100_000;

/// Adds the `pbd.cloth` body kind and the cloth systems.
pub struct PbdPlugin;

impl Plugin for PbdPlugin {
    fn name(&self) -> &str {
        "modesuite.pbd"
    }

    fn build(&self, app: &mut SimApp) {
        add_deformable_systems::<Cloth>(app, DeformableSystems("pbd.cloth"));
        app.register_body_kind(Arc::new(ClothKind));
    }
}

/// The `pbd.cloth` body kind.
pub struct ClothKind;

impl BodyKind for ClothKind {
    fn name(&self) -> &str {
        "pbd.cloth"
    }

    /// The cloth's own triangles.
    fn surface_triangles(&self, body: &CompiledBody) -> Option<Vec<[u32; 3]>> {
        Some(body.downcast_ref::<CompiledCloth>()?.triangles.clone())
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
        if surface.positions.len() > MAX_PARTICLES {
            return Err(SceneError::semantic(
                format!("{}.shape", ctx.path),
                format!("{} particles", surface.positions.len()),
                format!("at most {MAX_PARTICLES} particles (surface vertices) for a pbd.cloth; use a coarser resolution"),
            ));
        }
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
            grasp_tethers: params.grasp_tethers.unwrap_or(s.grasp_tethers),
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
        let drags = params
            .drags
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let sel = d
                    .select
                    .select(&format!("{path}.drags[{i}].select"), &surface.positions)?;
                Ok((
                    sel,
                    Vector3::new(d.velocity.0, d.velocity.1, d.velocity.2),
                    d.start,
                    d.stop,
                ))
            })
            .collect::<Result<Vec<_>, SceneError>>()?;
        let to_world = |local: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
            local
                .iter()
                .map(|p| (pose * Point3::from(*p)).coords)
                .collect()
        };
        let positions = to_world(&surface.positions);
        let initial = match &params.fold {
            None => None,
            Some(f) if f.at.is_finite() && f.radius.is_finite() && f.radius > 0.0 => Some(
                to_world(&crate::fold_positions(&surface.positions, f.at, f.radius)),
            ),
            Some(f) => {
                return Err(SceneError::semantic(
                    format!("{path}.fold"),
                    format!("(at: {}, radius: {})", f.at, f.radius),
                    "a finite `at` and a finite radius > 0 m",
                ))
            }
        };
        let compiled = CompiledCloth {
            positions,
            triangles: surface.triangles,
            material,
            settings,
            pins,
            groups,
            initial,
            drags,
            rows: Arc::default(),
        };
        // Build once here so that every construction error is a compile error, not a spawn error.
        build_cloth(&compiled).map_err(|e| SceneError::semantic(path, "(cloth)", e.to_string()))?;
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
        let cloth = build_cloth(c)
            .map_err(|e| SceneError::semantic("pbd.cloth", "(spawn)", e.to_string()))?;
        PbdContext::spawn_into(app, entity, cloth);
        Ok(())
    }
}

/// The cloth of a compiled object: rest shape, initial (folded) positions, pins, groups, drags.
fn build_cloth(c: &CompiledCloth) -> Result<Cloth, crate::PbdError> {
    let mut cloth = Cloth::new(&c.positions, &c.triangles, c.material, c.settings)?;
    cloth.share_rows(Arc::clone(&c.rows));
    if let Some(initial) = &c.initial {
        cloth.set_positions(initial)?;
    }
    for pin in &c.pins {
        cloth.pin_to_world(pin)?;
    }
    for (name, g) in &c.groups {
        cloth.add_group(name, g)?;
    }
    for (particles, velocity, start, stop) in &c.drags {
        cloth.drive_particles(particles, *velocity, *start, *stop)?;
    }
    Ok(cloth)
}
