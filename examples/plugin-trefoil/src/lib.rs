//! An example compiled modesuite plugin (`acme`), loaded at run time:
//!
//! ```text
//! cargo build -p plugin-trefoil
//! modesuite run examples/plugin-trefoil/trefoil.scene.ron --plugin target/debug/libplugin_trefoil.so --json
//! ```
//!
//! It links only `modesuite-plugin-abi` (plus serde and ron for its parameters) and declares:
//! - the shape generator `acme.trefoil`: a tube of tetrahedra along a trefoil knot ([`trefoil`]);
//! - the reward term `acme.centroid_height`: height of an object's centroid, m;
//! - the reward term `acme.fall_progress`: how far the centroid fell since the last step, m
//!   (keeps the previous height in the plugin's state slots, so it is reset with the env);
//! - the observation term `acme.centroid`: the centroid (x, y, z), m;
//! - the termination term `acme.below`: 1 when the centroid is below a height;
//! - the passive force `acme.wind`: a uniform force spread over the nodes, plus linear drag;
//! - the task event `acme.nudge`: pushes an object with a random horizontal velocity (a task
//!   section's `Event(event: "acme.nudge", params: (object, speed))`, at reset or on an interval).
//!
//! See README.md for how to write such a plugin.

pub mod trefoil;

use modesuite_plugin_abi::guest::{
    EventContext, EventDef, ForceContext, ForceDef, Mesh, MeshWant, PluginDef, ShapeDef,
    TermContext, TermDef, TermKind, World,
};
use serde::Deserialize;

/// Parses RON parameters with the scene's conventions (optional fields may omit `Some`).
fn parse<T: for<'de> Deserialize<'de>>(params: &str) -> Result<T, String> {
    ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str(params)
        .map_err(|e| format!("{} (at {})", e.code, e.span.start))
}

fn generate_trefoil(params: &str, _want: MeshWant) -> Result<Mesh, String> {
    let p: trefoil::TrefoilParams = parse(params)?;
    trefoil::validate(&p)?;
    let (nodes, tets) = trefoil::mesh(&p);
    // A volume also serves when a surface is asked for (the host takes its boundary).
    Ok(Mesh::Volume { nodes, tets })
}

/// Parameters of the terms that look at one object.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectParams {
    /// The object's name in the scene.
    object: String,
}

/// Parameters of `acme.below`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BelowParams {
    object: String,
    /// Height, m.
    z: f64,
}

fn centroid_of(world: &World, object: &str) -> Result<[f64; 3], String> {
    world
        .object(object)
        .map(|o| o.centroid())
        .ok_or_else(|| format!("no object named {object:?} in the scene"))
}

fn configure_object(params: &str) -> Result<usize, String> {
    parse::<ObjectParams>(params).map(|_| 1)
}

fn centroid_height(ctx: &mut TermContext) -> Result<(), String> {
    let p: ObjectParams = parse(ctx.params)?;
    ctx.out[0] = centroid_of(&ctx.world, &p.object)?[2];
    Ok(())
}

/// State slots: `[0]` the centroid height at the previous evaluation, `[1]` 1 once it is set.
fn fall_progress(ctx: &mut TermContext) -> Result<(), String> {
    let p: ObjectParams = parse(ctx.params)?;
    let z = centroid_of(&ctx.world, &p.object)?[2];
    ctx.out[0] = if ctx.state[1] == 1.0 {
        ctx.state[0] - z
    } else {
        0.0
    };
    ctx.state[0] = z;
    ctx.state[1] = 1.0;
    Ok(())
}

fn centroid(ctx: &mut TermContext) -> Result<(), String> {
    let p: ObjectParams = parse(ctx.params)?;
    ctx.out
        .copy_from_slice(&centroid_of(&ctx.world, &p.object)?);
    Ok(())
}

fn configure_below(params: &str) -> Result<usize, String> {
    let p: BelowParams = parse(params)?;
    if !p.z.is_finite() {
        return Err(format!("z = {}: a finite height, m", p.z));
    }
    Ok(1)
}

fn below(ctx: &mut TermContext) -> Result<(), String> {
    let p: BelowParams = parse(ctx.params)?;
    let z = centroid_of(&ctx.world, &p.object)?[2];
    ctx.out[0] = if z < p.z { 1.0 } else { 0.0 };
    Ok(())
}

/// Parameters of `acme.wind`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WindParams {
    /// Total force on the object, N, world frame (spread evenly over its nodes).
    force: (f64, f64, f64),
    /// Linear drag per node, N s/m (default 0).
    #[serde(default)]
    drag: f64,
}

fn check_wind(p: &WindParams) -> Result<(), String> {
    let f = [p.force.0, p.force.1, p.force.2];
    if !f.iter().all(|x| x.is_finite()) {
        return Err(format!("force = {:?}: three finite numbers, N", p.force));
    }
    if !(p.drag.is_finite() && p.drag >= 0.0) {
        return Err(format!("drag = {}: a finite number >= 0, N s/m", p.drag));
    }
    Ok(())
}

fn configure_wind(params: &str) -> Result<(), String> {
    check_wind(&parse(params)?)
}

fn wind(ctx: &mut ForceContext) -> Result<(), String> {
    let p: WindParams = parse(ctx.params)?;
    let n = ctx.nodes.len().max(1) as f64;
    let share = [p.force.0 / n, p.force.1 / n, p.force.2 / n];
    for (i, f) in ctx.forces.iter_mut().enumerate() {
        let v = ctx.velocities.map_or([0.0; 3], |v| v[i]);
        for k in 0..3 {
            f[k] += share[k] - p.drag * v[k];
        }
    }
    Ok(())
}

/// Parameters of `acme.nudge`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NudgeParams {
    /// The object to push.
    object: String,
    /// Largest horizontal speed, m/s: each component of the push is uniform in [-speed, speed].
    speed: f64,
}

fn configure_nudge(params: &str) -> Result<bool, String> {
    let p: NudgeParams = parse(params)?;
    if !(p.speed.is_finite() && p.speed >= 0.0) {
        return Err(format!(
            "speed = {}: expected a finite speed >= 0, m/s",
            p.speed
        ));
    }
    // a push moves no body by itself: fine during episodes too
    Ok(true)
}

fn nudge(ctx: &mut EventContext) -> Result<(), String> {
    let p: NudgeParams = parse(ctx.params)?;
    let vx = ctx.uniform(-p.speed, p.speed);
    let vy = ctx.uniform(-p.speed, p.speed);
    ctx.push(&p.object, [vx, vy, 0.0])
}

/// The plugin's declaration.
pub fn plugin() -> PluginDef {
    PluginDef {
        name: "acme",
        description: "example compiled plugin: trefoil-knot tube, centroid terms, wind, nudge",
        state_len: 2,
        shapes: vec![ShapeDef {
            name: "acme.trefoil",
            description: "tube of tetrahedra along a trefoil knot (params: scale, radius, segments, stations)",
            generate: generate_trefoil,
        }],
        terms: vec![
            TermDef {
                name: "acme.centroid_height",
                description: "height of an object's centroid, m (params: object)",
                kind: TermKind::Reward,
                configure: configure_object,
                evaluate: centroid_height,
            },
            TermDef {
                name: "acme.fall_progress",
                description: "fall of an object's centroid since the last step, m (params: object; one per scene)",
                kind: TermKind::Reward,
                configure: configure_object,
                evaluate: fall_progress,
            },
            TermDef {
                name: "acme.centroid",
                description: "centroid of an object (x, y, z), m (params: object)",
                kind: TermKind::Observation,
                configure: |p| parse::<ObjectParams>(p).map(|_| 3),
                evaluate: centroid,
            },
            TermDef {
                name: "acme.below",
                description: "1 when an object's centroid is below z (params: object, z)",
                kind: TermKind::Termination,
                configure: configure_below,
                evaluate: below,
            },
        ],
        forces: vec![ForceDef {
            name: "acme.wind",
            description: "uniform force spread over the nodes plus linear drag (params: force, drag)",
            configure: configure_wind,
            apply: wind,
        }],
        events: vec![EventDef {
            name: "acme.nudge",
            description: "pushes an object with a random horizontal velocity (params: object, speed)",
            configure: configure_nudge,
            apply: nudge,
        }],
    }
}

modesuite_plugin_abi::declare_plugin!(plugin);
