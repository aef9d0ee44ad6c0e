//! Task terms: small functions registered by name and configured from RON parameters.
//!
//! A [`TaskTermFactory`] is registered in the engine registry ([`register_task_term`]) and
//! configured once per scene into a [`TaskTerm`]; points it mentions are interned in the
//! [`Configure`] table and resolved per env at spawn. Every term returns `dim` finite values;
//! rewards, success and terminations use the first.

use std::sync::Arc;

use modesuite_engine::registry::{TermEntry, TermKind};
use modesuite_engine::state::PluginStates;
use modesuite_engine::surface::{Region, Surface};
use modesuite_engine::terms::{ConfiguredTerm, Term, TermContext, WorldView};
use modesuite_engine::SimApp;
use modesuite_robots::RobotObservation;
use nalgebra::{UnitQuaternion, Vector3};
use serde::de::DeserializeOwned;
use serde::Deserialize;

use crate::desc::{CameraChannels, CameraObsDesc, PointRef};

/// Index of a point in a task's point table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointId(pub usize);

/// What a term sees when it is configured: the task's names and its point table.
pub struct Configure<'a> {
    /// Named points of the section.
    pub named: &'a std::collections::BTreeMap<String, PointRef>,
    /// Target names, in index order.
    pub targets: &'a [String],
    /// Scene object names.
    pub objects: &'a [String],
    /// The point table (terms add their points with [`Configure::point`]).
    pub table: Vec<PointRef>,
    /// Cameras of the scene's render section: name -> (width, height), px.
    pub cameras: &'a std::collections::BTreeMap<String, (u32, u32)>,
}

impl Configure<'_> {
    /// Checks a point reference and interns it; named points are replaced by their definition.
    pub fn point(&mut self, p: &PointRef) -> Result<PointId, String> {
        let mut p = p.clone();
        let mut depth = 0;
        while let PointRef::Point(name) = p.clone() {
            p = self.named.get(&name).cloned().ok_or_else(|| {
                format!(
                    "Point(\"{name}\"): no such point; the section's points are {:?}",
                    self.named.keys().collect::<Vec<_>>()
                )
            })?;
            depth += 1;
            if depth > 16 {
                return Err(format!(
                    "Point(\"{name}\"): the points refer to each other in a loop"
                ));
            }
        }
        match &p {
            PointRef::Target(t) if !self.targets.contains(t) => {
                return Err(format!(
                    "Target(\"{t}\"): no such target; the section's targets are {:?}",
                    self.targets
                ))
            }
            PointRef::Object(o)
            | PointRef::Centroid(o)
            | PointRef::Nodes { object: o, .. }
            | PointRef::Tracked { object: o, .. }
                if !self.objects.contains(o) =>
            {
                return Err(format!("object \"{o}\" is not in the scene"))
            }
            PointRef::Nodes { select, .. } => {
                select.validate("select").map_err(|e| e.to_string())?
            }
            PointRef::Tracked { i, k, .. } if *i >= *k => {
                return Err(format!("Tracked(i: {i}, k: {k}): i in 0..k"))
            }
            PointRef::Const(c) if !(c.0.is_finite() && c.1.is_finite() && c.2.is_finite()) => {
                return Err(format!("Const({c:?}): finite coordinates"))
            }
            PointRef::Stages { stages, by, reach } => {
                if stages.is_empty() || !(reach.is_finite() && *reach > 0.0) {
                    return Err(format!(
                        "Stages(reach: {reach}, {} stages): at least one stage and a positive reach, m",
                        stages.len()
                    ));
                }
                // The parts are interned first (they are resolved before the stages point)
                // and stored in their canonical form.
                let mut canon = |q: &PointRef| -> Result<PointRef, String> {
                    let id = self.point(q)?;
                    Ok(self.table[id.0].clone())
                };
                p = PointRef::Stages {
                    stages: stages.iter().map(&mut canon).collect::<Result<_, _>>()?,
                    by: Box::new(canon(by)?),
                    reach: *reach,
                };
            }
            _ => {}
        }
        if let Some(i) = self.table.iter().position(|q| *q == p) {
            return Ok(PointId(i));
        }
        self.table.push(p);
        Ok(PointId(self.table.len() - 1))
    }

    /// Checks that `name` is a scene object.
    pub fn object(&self, name: &str) -> Result<(), String> {
        if self.objects.iter().any(|o| o == name) {
            Ok(())
        } else {
            Err(format!("object \"{name}\" is not in the scene"))
        }
    }
}

/// Everything a term reads when it is evaluated (one env, read-only).
pub struct TaskCtx<'a> {
    /// Objects, clock.
    pub world: &'a WorldView<'a>,
    /// The task robot's state.
    pub robot: &'a RobotObservation,
    /// The task robot's arm joint indices (into `robot.q`), gripper last.
    pub arm_joints: &'a [usize],
    /// The task robot's leg joint indices.
    pub leg_joints: &'a [usize],
    /// Resolved points, by [`PointId`].
    pub points: &'a [Vector3<f64>],
    /// The action of this step and of the previous one.
    pub action: &'a [f32],
    /// The previous step's action (zeros at the start of an episode).
    pub prev_action: &'a [f32],
    /// Deformable objects with a surface (cloths, solids), by name.
    pub surfaces: &'a [(&'a str, Surface<'a>)],
    /// Nominal base height of the robot (stability terms).
    pub base_height: f64,
    /// Names of the scene objects the robot touches.
    pub touching: &'a [&'a str],
    /// The frames of the cameras rendered in this env's `Sense` pass (`None` without the
    /// render plugin).
    pub images: Option<&'a modesuite_render::CameraImages>,
    /// State slots of plugins, for engine terms used in the task (compiled plugins keep their
    /// state there).
    pub states: &'a std::cell::RefCell<PluginStates>,
}

/// An engine term ([`modesuite_engine::terms::Term`], e.g. from a compiled C-ABI plugin) used in
/// a task section: the task evaluates it through the engine's term context, so one registry of
/// terms serves scenes and tasks alike.
struct EngineTerm(Arc<dyn ConfiguredTerm>);

impl TaskTerm for EngineTerm {
    fn dim(&self, _: &Dims) -> usize {
        self.0.dim()
    }
    fn evaluate(&self, ctx: &TaskCtx, out: &mut [f64]) -> Result<(), String> {
        let mut states = ctx
            .states
            .try_borrow_mut()
            .map_err(|_| "plugin states are in use".to_string())?;
        let mut tc = TermContext {
            world: ctx.world,
            states: &mut states,
        };
        self.0.evaluate(&mut tc, out)
    }
}

/// Configures a registered term for a task: a task term through its factory, an engine term
/// (scene terms, compiled plugins' terms) through a wrapper that evaluates it with the
/// engine's `TermContext`. `None`: the payload is neither.
pub fn configure_any(
    payload: &(dyn std::any::Any + Send + Sync),
    params: &str,
    cfg: &mut Configure,
) -> Option<Result<Arc<dyn TaskTerm>, String>> {
    if let Some(f) = payload.downcast_ref::<TaskTermEntry>() {
        return Some(f.0.configure(params, cfg));
    }
    let term = payload.downcast_ref::<Arc<dyn Term>>()?;
    Some(
        term.configure(params)
            .map(|c| Arc::new(EngineTerm(c)) as Arc<dyn TaskTerm>),
    )
}

impl TaskCtx<'_> {
    /// A resolved point.
    pub fn point(&self, id: PointId) -> Vector3<f64> {
        self.points[id.0]
    }

    /// The surface of a deformable object by name.
    pub fn surface(&self, name: &str) -> Result<&Surface<'_>, String> {
        self.surfaces
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, s)| s)
            .ok_or_else(|| {
                format!("object \"{name}\" is not a deformable object with a surface (a cloth or a solid)")
            })
    }
}

/// Robot facts some terms' sizes depend on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Dims {
    /// Arm joints including the gripper.
    pub arm: usize,
    /// Leg joints.
    pub legs: usize,
}

/// A configured term (immutable, shared by every env).
pub trait TaskTerm: Send + Sync + 'static {
    /// Number of values for a robot of these dimensions.
    fn dim(&self, dims: &Dims) -> usize;
    /// Writes `dim` values.
    fn evaluate(&self, ctx: &TaskCtx, out: &mut [f64]) -> Result<(), String>;
    /// An image term: the camera it reads, its channels and its shape (height, width,
    /// channels); the task requests the camera and the observation space gets an image box.
    fn image(&self) -> Option<(&str, CameraChannels, [usize; 3])> {
        None
    }
}

/// A registered term: validates its parameters and returns the configured term.
pub trait TaskTermFactory: Send + Sync + 'static {
    /// Configures from RON parameters (`()` when none were given).
    fn configure(&self, params: &str, cfg: &mut Configure) -> Result<Arc<dyn TaskTerm>, String>;
}

/// The registry payload of a task term.
#[derive(Clone)]
pub struct TaskTermEntry(pub Arc<dyn TaskTermFactory>);

/// Registers a task term under `name` (shown by `modesuite list`).
pub fn register_task_term(
    app: &mut SimApp,
    name: &str,
    kind: TermKind,
    description: &str,
    factory: Arc<dyn TaskTermFactory>,
) {
    app.register_term(TermEntry {
        name: name.to_string(),
        kind,
        description: description.to_string(),
        payload: Arc::new(TaskTermEntry(factory)),
    });
}

fn parse<T: DeserializeOwned>(params: &str) -> Result<T, String> {
    crate::ron_options()
        .from_str(params)
        .map_err(|e| format!("params: {e}"))
}

/// A term from a closure over parsed parameters.
struct FnFactory<P, F>(F, std::marker::PhantomData<fn() -> P>);

impl<P, F> TaskTermFactory for FnFactory<P, F>
where
    P: DeserializeOwned + 'static,
    F: Fn(P, &mut Configure) -> Result<Arc<dyn TaskTerm>, String> + Send + Sync + 'static,
{
    fn configure(&self, params: &str, cfg: &mut Configure) -> Result<Arc<dyn TaskTerm>, String> {
        (self.0)(parse::<P>(params)?, cfg)
    }
}

fn factory<P, F>(f: F) -> Arc<dyn TaskTermFactory>
where
    P: DeserializeOwned + 'static,
    F: Fn(P, &mut Configure) -> Result<Arc<dyn TaskTerm>, String> + Send + Sync + 'static,
{
    Arc::new(FnFactory(f, std::marker::PhantomData))
}

/// A term from a closure.
struct Fun<F> {
    dim: usize,
    f: F,
}

impl<F> TaskTerm for Fun<F>
where
    F: Fn(&TaskCtx, &mut [f64]) -> Result<(), String> + Send + Sync + 'static,
{
    fn dim(&self, _: &Dims) -> usize {
        self.dim
    }
    fn evaluate(&self, ctx: &TaskCtx, out: &mut [f64]) -> Result<(), String> {
        (self.f)(ctx, out)
    }
}

fn term<F>(dim: usize, f: F) -> Arc<dyn TaskTerm>
where
    F: Fn(&TaskCtx, &mut [f64]) -> Result<(), String> + Send + Sync + 'static,
{
    Arc::new(Fun { dim, f })
}

/// The `camera` term: one camera's latest frame, row-major `height x width x channels`.
struct CameraTerm {
    camera: String,
    channels: CameraChannels,
    shape: [usize; 3],
}

impl TaskTerm for CameraTerm {
    fn dim(&self, _: &Dims) -> usize {
        self.shape.iter().product()
    }
    fn evaluate(&self, ctx: &TaskCtx, out: &mut [f64]) -> Result<(), String> {
        let frame = ctx
            .images
            .and_then(|i| i.0.get(&self.camera))
            .ok_or_else(|| {
                format!(
                    "camera \"{}\" was not rendered this step (image observations need a renderer attached to the env: modesuite_render::prepare, done by the CLI's env builders)",
                    self.camera
                )
            })?;
        let [h, w, c] = self.shape;
        if (frame.height as usize, frame.width as usize) != (h, w) {
            return Err(format!(
                "camera \"{}\": a {}x{} frame, expected {w}x{h}",
                self.camera, frame.width, frame.height
            ));
        }
        let colour = self.channels != CameraChannels::Depth;
        let depth = self.channels != CameraChannels::Rgb;
        for (k, px) in out.chunks_exact_mut(c).enumerate() {
            if colour {
                for (o, v) in px.iter_mut().zip(&frame.rgb[3 * k..3 * k + 3]) {
                    *o = f64::from(*v) / 255.0;
                }
            }
            if depth {
                px[c - 1] = f64::from(frame.depth[k]);
            }
        }
        Ok(())
    }
    fn image(&self) -> Option<(&str, CameraChannels, [usize; 3])> {
        Some((&self.camera, self.channels, self.shape))
    }
}

/// Configures a `camera` term against the scene's cameras.
pub fn camera_term(p: CameraObsDesc, cfg: &Configure) -> Result<Arc<dyn TaskTerm>, String> {
    let (w, h) = *cfg.cameras.get(&p.camera).ok_or_else(|| {
        format!(
            "camera: \"{}\" is not a camera of the scene (its render section's, extensions[\"render\"].cameras, or a robot file's): [{}]",
            p.camera,
            cfg.cameras.keys().cloned().collect::<Vec<_>>().join(", ")
        )
    })?;
    Ok(Arc::new(CameraTerm {
        shape: [h as usize, w as usize, p.channels.count()],
        camera: p.camera,
        channels: p.channels,
    }))
}

/// Vector norm of a distance term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
pub enum Norm {
    /// Euclidean.
    #[default]
    L2,
    /// Sum of absolute values (Manhattan).
    L1,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DistanceParams {
    a: PointRef,
    b: PointRef,
    /// Only x and y.
    #[serde(default)]
    planar: bool,
    #[serde(default)]
    norm: Norm,
    /// `within` only: the distance below which the term is 1, m.
    #[serde(default)]
    max: Option<f64>,
}

impl DistanceParams {
    fn measure(&self, mut d: Vector3<f64>) -> f64 {
        if self.planar {
            d.z = 0.0;
        }
        match self.norm {
            Norm::L2 => d.norm(),
            Norm::L1 => d.abs().sum(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SumWithinParams {
    pairs: Vec<DistanceParams>,
    max: f64,
}

/// 1 when the summed distances of `pairs` are below `max`, else 0.
fn within_term(
    pairs: Vec<DistanceParams>,
    max: Option<f64>,
    cfg: &mut Configure,
) -> Result<Arc<dyn TaskTerm>, String> {
    let max = match max {
        Some(m) if m.is_finite() && m > 0.0 => m,
        other => return Err(format!("max = {other:?}: a positive distance, m")),
    };
    if pairs.is_empty() || pairs.iter().any(|p| p.max.is_some()) {
        return Err("pairs: at least one (a, b, planar, norm) without its own max".into());
    }
    let ids = pairs
        .iter()
        .map(|p| Ok((cfg.point(&p.a)?, cfg.point(&p.b)?)))
        .collect::<Result<Vec<_>, String>>()?;
    Ok(term(1, move |c, out| {
        let sum: f64 = pairs
            .iter()
            .zip(&ids)
            .map(|(p, (a, b))| p.measure(c.point(*a) - c.point(*b)))
            .sum();
        out[0] = f64::from(u8::from(sum < max));
        Ok(())
    }))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectInBaseBoxParams {
    object: String,
    min: (f64, f64, f64),
    max: (f64, f64, f64),
}

/// The corners of a box, checked: `min` below `max` on every axis.
fn box_bounds(
    min: (f64, f64, f64),
    max: (f64, f64, f64),
) -> Result<(Vector3<f64>, Vector3<f64>), String> {
    let (lo, hi) = (
        Vector3::new(min.0, min.1, min.2),
        Vector3::new(max.0, max.1, max.2),
    );
    if (0..3).any(|i| lo[i].partial_cmp(&hi[i]) != Some(std::cmp::Ordering::Less)) {
        return Err(format!(
            "min {min:?} must be below max {max:?} on every axis"
        ));
    }
    Ok((lo, hi))
}

/// Whether `d` lies strictly inside the box `[lo, hi]`.
fn inside(d: &Vector3<f64>, lo: &Vector3<f64>, hi: &Vector3<f64>) -> bool {
    (0..3).all(|i| d[i] > lo[i] && d[i] < hi[i])
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InBoxParams {
    point: PointRef,
    center: PointRef,
    min: (f64, f64, f64),
    max: (f64, f64, f64),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PointParams {
    point: PointRef,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TrackedParams {
    object: String,
    #[serde(default = "four")]
    k: usize,
}

fn four() -> usize {
    4
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RegionParams {
    object: String,
    min: (f64, f64),
    max: (f64, f64),
    /// Only particles (fraction) or triangles (coverage) higher than this count, m.
    #[serde(default)]
    above: Option<f64>,
    /// Makes the term a predicate: 1 when the fraction is at most this, else 0.
    #[serde(default)]
    at_most: Option<f64>,
    /// Makes the term a predicate: 1 when the fraction is at least this, else 0.
    #[serde(default)]
    at_least: Option<f64>,
}

impl RegionParams {
    /// The fraction, or the predicate when `at_most` / `at_least` is given.
    fn output(&self, fraction: f64) -> f64 {
        match (self.at_most, self.at_least) {
            (Some(hi), _) if fraction > hi => 0.0,
            (_, Some(lo)) if fraction < lo => 0.0,
            (None, None) => fraction,
            _ => 1.0,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ContactParams {
    objects: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StabilityParams {
    /// Nominal base height, m (default: the height at spawn).
    #[serde(default)]
    height: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Unit {}

/// Tracked points of a deformable: `k` nodes spread uniformly along the longest axis of its
/// rest shape (the nodes nearest to the axis at `k` stations), in world coordinates.
pub fn tracked_nodes(rest_local: &[Vector3<f64>], k: usize) -> Vec<u32> {
    if rest_local.is_empty() || k == 0 {
        return Vec::new();
    }
    let mut lo = rest_local[0];
    let mut hi = rest_local[0];
    for p in rest_local {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let ext = hi - lo;
    let axis = ext.imax();
    let centre = (lo + hi) / 2.0;
    (0..k)
        .map(|i| {
            let t = if k == 1 {
                0.5
            } else {
                i as f64 / (k - 1) as f64
            };
            let mut s = centre;
            s[axis] = lo[axis] + t * ext[axis];
            rest_local
                .iter()
                .enumerate()
                .min_by(|(_, a), (_, b)| {
                    (*a - s).norm_squared().total_cmp(&(*b - s).norm_squared())
                })
                .map(|(j, _)| j as u32)
                .unwrap_or(0)
        })
        .collect()
}

/// Roll and pitch of a pose's rotation, rad.
pub fn roll_pitch(q: &UnitQuaternion<f64>) -> (f64, f64) {
    let (r, p, _) = q.euler_angles();
    (r, p)
}

/// Registers the term library.
pub fn register_library(app: &mut SimApp) {
    use TermKind::*;
    let reg = register_task_term;
    reg(
        app,
        "camera",
        Observation,
        "image of a camera of the render section (camera, channels: Rgb | Depth | Rgbd), row-major height x width x channels; RGB in [0, 1], depth in m",
        factory(|p: CameraObsDesc, cfg| camera_term(p, cfg)),
    );
    reg(
        app,
        "distance",
        Reward,
        "distance between two points (a, b, planar: xy only, norm: L2 | L1), m",
        factory(|p: DistanceParams, cfg| {
            if p.max.is_some() {
                return Err("max: only for the `within` term".into());
            }
            let (a, b) = (cfg.point(&p.a)?, cfg.point(&p.b)?);
            Ok(term(1, move |c, out| {
                out[0] = p.measure(c.point(a) - c.point(b));
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "within",
        Termination,
        "1 when the distance between a and b (planar, norm as `distance`) is below max (m), else 0",
        factory(|mut p: DistanceParams, cfg| {
            let max = p.max.take();
            within_term(vec![p], max, cfg)
        }),
    );
    reg(
        app,
        "sum_within",
        Termination,
        "1 when the sum of the distances of `pairs` [(a, b, planar, norm)] is below max (m), else 0",
        factory(|p: SumWithinParams, cfg| within_term(p.pairs, Some(p.max), cfg)),
    );
    reg(
        app,
        "in_box",
        Termination,
        "1 when point - center lies in [min, max] (axis-aligned, m), else 0",
        factory(|p: InBoxParams, cfg| {
            let (a, c0) = (cfg.point(&p.point)?, cfg.point(&p.center)?);
            let (lo, hi) = box_bounds(p.min, p.max)?;
            Ok(term(1, move |c, out| {
                out[0] = f64::from(inside(&(c.point(a) - c.point(c0)), &lo, &hi));
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "object_in_base_box",
        Termination,
        "1 when any node of a deformable object lies in the box [min, max] of the robot's base frame (m; e.g. the body's hull: a collision of the body with a belt), else 0",
        factory(|p: ObjectInBaseBoxParams, cfg| {
            cfg.object(&p.object)?;
            let (lo, hi) = box_bounds(p.min, p.max)?;
            Ok(term(1, move |c, out| {
                let o = c
                    .world
                    .object(&p.object)
                    .ok_or_else(|| format!("object \"{}\" is not in the scene", p.object))?;
                if o.nodes.is_empty() {
                    return Err(format!(
                        "object \"{}\" has no nodes (object_in_base_box needs a deformable)",
                        p.object
                    ));
                }
                let inv = c.robot.base.inverse();
                out[0] = f64::from(
                    o.nodes
                        .iter()
                        .any(|n| inside(&inv.transform_point(&(*n).into()).coords, &lo, &hi)),
                );
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "point",
        Observation,
        "a point's world position (point), 3 values",
        factory(|p: PointParams, cfg| {
            let a = cfg.point(&p.point)?;
            Ok(term(3, move |c, out| {
                out.copy_from_slice(c.point(a).as_slice());
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "base_xy",
        Observation,
        "the robot base's x and y, m",
        factory(|_: Unit, _| {
            Ok(term(2, |c, out| {
                out[0] = c.robot.base.translation.x;
                out[1] = c.robot.base.translation.y;
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "base_quat",
        Observation,
        "the robot base's orientation quaternion (w, x, y, z)",
        factory(|_: Unit, _| {
            Ok(term(4, |c, out| {
                let q = c.robot.base.rotation;
                out.copy_from_slice(&[q.w, q.i, q.j, q.k]);
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "arm_joints",
        Observation,
        "arm joint positions with the gripper last, then their velocities (2 x (n + 1))",
        factory(|_: Unit, _| Ok(Arc::new(JointStates { legs: false }) as Arc<dyn TaskTerm>)),
    );
    reg(
        app,
        "leg_joints",
        Observation,
        "leg joint positions then velocities (24 for Spot, 0 for a wheeled base)",
        factory(|_: Unit, _| Ok(Arc::new(JointStates { legs: true }) as Arc<dyn TaskTerm>)),
    );
    reg(
        app,
        "tracked",
        Observation,
        "k tracked nodes of a deformable along its length (object, k = 4), 3 k values",
        factory(|p: TrackedParams, cfg| {
            cfg.object(&p.object)?;
            if p.k == 0 || p.k > 10_000 {
                return Err(format!("k = {}: 1..=10000 tracked points", p.k));
            }
            let ids: Vec<PointId> = (0..p.k)
                .map(|i| {
                    cfg.point(&PointRef::Tracked {
                        object: p.object.clone(),
                        i,
                        k: p.k,
                    })
                })
                .collect::<Result<_, _>>()?;
            Ok(term(3 * p.k, move |c, out| {
                for (i, id) in ids.iter().enumerate() {
                    out[3 * i..3 * i + 3].copy_from_slice(c.point(*id).as_slice());
                }
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "stability",
        Reward,
        "base roll^2 + pitch^2 + (height - nominal)^2 (height: nominal, default at spawn)",
        factory(|p: StabilityParams, _| {
            Ok(term(1, move |c, out| {
                let (r, pi) = roll_pitch(&c.robot.base.rotation);
                let h = c.robot.base.translation.z - p.height.unwrap_or(c.base_height);
                out[0] = r * r + pi * pi + h * h;
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "action_l2",
        Reward,
        "sum of squared action values",
        factory(|_: Unit, _| {
            Ok(term(1, |c, out| {
                out[0] = c.action.iter().map(|a| f64::from(*a).powi(2)).sum();
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "action_rate",
        Reward,
        "sum of squared changes of the action since the previous step",
        factory(|_: Unit, _| {
            Ok(term(1, |c, out| {
                out[0] = c
                    .action
                    .iter()
                    .zip(c.prev_action)
                    .map(|(a, b)| f64::from(a - b).powi(2))
                    .sum();
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "cloth_fraction_above",
        Termination,
        "fraction of a cloth's particles over the xy rectangle [min, max] (higher than `above`); with `at_most`/`at_least` a 0/1 predicate",
        cloth_region_term(|cloth, region, p| {
            let above = p.above.unwrap_or(f64::NEG_INFINITY);
            let pos = cloth.nodes;
            let k = pos
                .iter()
                .filter(|q| region.contains_xy(q) && q.z > above)
                .count();
            k as f64 / pos.len().max(1) as f64
        }),
    );
    reg(
        app,
        "cloth_coverage",
        Termination,
        "fraction of the xy rectangle [min, max] covered by a cloth's xy projection (only triangles higher than `above`); with `at_most`/`at_least` a 0/1 predicate",
        cloth_region_term(|cloth, region, p| {
            cloth.covered_area_above(region, 40, p.above.unwrap_or(f64::NEG_INFINITY))
                / region.area()
        }),
    );
    reg(
        app,
        "robot_contact",
        Termination,
        "1 when the robot touches any of the named objects (objects: [...]), else 0",
        factory(|p: ContactParams, cfg| {
            for o in &p.objects {
                cfg.object(o)?;
            }
            Ok(term(1, move |c, out| {
                out[0] = f64::from(c.touching.iter().any(|t| p.objects.iter().any(|o| o == t)));
                Ok(())
            }))
        }),
    );
    reg(
        app,
        "time",
        Observation,
        "simulated time since the episode started, s",
        factory(|_: Unit, _| {
            Ok(term(1, |c, out| {
                out[0] = c.world.time;
                Ok(())
            }))
        }),
    );
}

/// A term over a cloth and an xy region: `f` gives the fraction, [`RegionParams::output`] turns
/// it into the term's value.
fn cloth_region_term(
    f: impl Fn(&Surface<'_>, &Region, &RegionParams) -> f64 + Send + Sync + Copy + 'static,
) -> Arc<dyn TaskTermFactory> {
    factory(move |p: RegionParams, cfg| {
        cfg.object(&p.object)?;
        let region = region(&p)?;
        Ok(term(1, move |c, out| {
            out[0] = p.output(f(c.surface(&p.object)?, &region, &p));
            Ok(())
        }))
    })
}

fn region(p: &RegionParams) -> Result<Region, String> {
    if !(p.min.0 < p.max.0 && p.min.1 < p.max.1) {
        return Err(format!(
            "min {:?} max {:?}: min below max on x and y",
            p.min, p.max
        ));
    }
    Ok(Region {
        min: [p.min.0, p.min.1],
        max: [p.max.0, p.max.1],
    })
}

/// Positions then velocities of a set of the robot's joints (arm with gripper, or legs).
struct JointStates {
    legs: bool,
}

impl TaskTerm for JointStates {
    fn dim(&self, d: &Dims) -> usize {
        2 * if self.legs { d.legs } else { d.arm }
    }
    fn evaluate(&self, c: &TaskCtx, out: &mut [f64]) -> Result<(), String> {
        let joints = if self.legs {
            c.leg_joints
        } else {
            c.arm_joints
        };
        let n = joints.len();
        for (i, &j) in joints.iter().enumerate() {
            out[i] = c.robot.q[j];
            out[n + i] = c.robot.qd[j];
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region(at_most: Option<f64>, at_least: Option<f64>) -> RegionParams {
        RegionParams {
            object: "cloth".into(),
            min: (0.0, 0.0),
            max: (1.0, 1.0),
            above: None,
            at_most,
            at_least,
        }
    }

    #[test]
    fn region_terms_are_fractions_or_predicates() {
        assert_eq!(region(None, None).output(0.3), 0.3);
        assert_eq!(region(Some(0.05), None).output(0.04), 1.0);
        assert_eq!(region(Some(0.05), None).output(0.06), 0.0);
        assert_eq!(region(None, Some(0.9)).output(0.95), 1.0);
        assert_eq!(region(None, Some(0.9)).output(0.85), 0.0);
    }

    #[test]
    fn tracked_nodes_spread_along_the_longest_axis() {
        let rest: Vec<Vector3<f64>> = (0..=10)
            .flat_map(|i| [-0.01, 0.01].map(move |y| Vector3::new(i as f64 * 0.1 - 0.5, y, 0.0)))
            .collect();
        let ids = tracked_nodes(&rest, 3);
        let xs: Vec<f64> = ids.iter().map(|&i| rest[i as usize].x).collect();
        assert_eq!(xs, [-0.5, 0.0, 0.5]);
    }
}
