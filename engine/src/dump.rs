//! `--dump-state`: the state of every object by name, as JSON.
//!
//! Format `modesuite.state.v1` (a public interface; outside checks parse it):
//! ```json
//! {"format": "modesuite.state.v1", "step": 240, "time": 4.0,
//!  "objects": {
//!    "box": {"kind": "dynamic", "position": [x, y, z], "quat_wxyz": [w, x, y, z],
//!            "linear_velocity": [vx, vy, vz], "angular_velocity": [wx, wy, wz]},
//!    "rod": {"kind": "fem.solid", "position": [...], "quat_wxyz": [...],
//!            "nodes": [[x, y, z], ...]}}}
//! ```
//! Positions in metres, world frame (z up); `nodes` lists every FEM node or cloth particle.
//! Robots appear as one entry per rapier body (`"robot/link"`, kind `robot.link`) and a root
//! entry (kind `robot`) whose `joints` maps each joint name to `{"position", "velocity"}`.
//! `objects` is keyed by object name (sorted); velocities only for rigid bodies.

use bevy_ecs::prelude::*;
use serde_json::{json, Map, Value};

use crate::components::{DeformableNodes, JointState, Object, Pose, Velocity};
use crate::SimClock;

fn v3(v: &nalgebra::Vector3<f64>) -> Value {
    json!([v.x, v.y, v.z])
}

/// The state of every object of `world` as a `modesuite.state.v1` JSON value.
pub fn dump_state(world: &World) -> Value {
    let mut items: Vec<(u32, String, Value)> = Vec::new();
    if let Some(mut q) = world.try_query::<(
        &Object,
        &Pose,
        Option<&Velocity>,
        Option<&DeformableNodes>,
        Option<&JointState>,
    )>() {
        for (obj, pose, vel, nodes, joints) in q.iter(world) {
            let t = pose.0.translation.vector;
            let r = pose.0.rotation.quaternion();
            let mut m = Map::new();
            m.insert("kind".into(), json!(obj.kind));
            m.insert("position".into(), v3(&t));
            m.insert("quat_wxyz".into(), json!([r.w, r.i, r.j, r.k]));
            if let Some(v) = vel {
                m.insert("linear_velocity".into(), v3(&v.linear));
                m.insert("angular_velocity".into(), v3(&v.angular));
            }
            if let Some(n) = nodes {
                m.insert("nodes".into(), Value::Array(n.0.iter().map(v3).collect()));
            }
            if let Some(j) = joints {
                let mut jm = Map::new();
                for (i, name) in j.names.iter().enumerate() {
                    jm.insert(
                        name.clone(),
                        json!({"position": j.positions[i], "velocity": j.velocities[i]}),
                    );
                }
                m.insert("joints".into(), Value::Object(jm));
            }
            items.push((obj.index, obj.name.clone(), Value::Object(m)));
        }
    }
    items.sort_by_key(|(i, _, _)| *i);
    let mut objects = Map::new();
    for (_, name, v) in items {
        objects.insert(name, v);
    }
    let clock = world
        .get_resource::<SimClock>()
        .copied()
        .unwrap_or_default();
    json!({
        "format": "modesuite.state.v1",
        "step": clock.episode_steps,
        "time": clock.time,
        "objects": Value::Object(objects),
    })
}
