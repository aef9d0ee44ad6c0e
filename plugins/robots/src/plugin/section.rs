//! The `robots` scene section: the robot descriptions and scripts as written, and compiling
//! them (checks of scripts and action modes).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bevy_ecs::prelude::*;

use modesuite_engine::components::Object;
use modesuite_engine::deps::ron;
use modesuite_engine::registry::{
    CameraMount, CompiledSection, SceneSection, SectionCompileContext,
};
use modesuite_engine::{SceneError, SimApp, Space, Spaces};

use super::model::{BrokenRobot, CompiledRobot, RobotDesc, Script};
use super::runtime::Robots;
use super::spawn::spawn_one;
use crate::actions::{ActionConfig, ActionModes, ArmMode, BaseMode, GripperMode};
use crate::error::RobotError;
use crate::gait::TrotParams;
use crate::models::RobotSpec;

/// The `robots` scene section.
pub struct RobotsSection;

fn robot_err(path: &str, e: RobotError) -> SceneError {
    SceneError::semantic(path, "(robot)", e.to_string())
}

impl SceneSection for RobotsSection {
    fn name(&self) -> &str {
        "robots"
    }

    fn description(&self) -> &str {
        "robots of the scene: [(name, model, pose, actions, grasp_force_limit, script, start_closed, gait)]"
    }

    fn compile(&self, ctx: &SectionCompileContext) -> Result<CompiledSection, SceneError> {
        let descs: Vec<RobotDesc> = ctx.parse()?;
        let mut out = Vec::with_capacity(descs.len());
        let mut discrete = false;
        for (i, d) in descs.into_iter().enumerate() {
            let path = format!("{}[{i}] \"{}\"", ctx.path(), d.name);
            if d.name.is_empty() || d.name.contains('/') {
                return Err(SceneError::semantic(
                    format!("{path}.name"),
                    format!("{:?}", d.name),
                    "a non-empty name without '/'",
                ));
            }
            if ctx.objects.iter().any(|o| o.name == d.name)
                || out.iter().any(|r: &CompiledRobot| r.desc.name == d.name)
            {
                return Err(SceneError::semantic(
                    format!("{path}.name"),
                    format!("{:?}", d.name),
                    "a name no object or other robot has",
                ));
            }
            let spec = model_spec(ctx, &path, &d.model)?;
            if !(d.pose.pos.iter().chain(&d.pose.rpy).all(|x| x.is_finite())) {
                return Err(SceneError::semantic(
                    format!("{path}.pose"),
                    format!("{:?}", d.pose),
                    "finite position (m) and roll, pitch, yaw (rad)",
                ));
            }
            let modes = resolve_modes(&path, &spec, &d.actions)?;
            let limit = d.grasp_force_limit.unwrap_or(spec.grasp_force_limit);
            if !(limit.is_finite() && limit > 0.0) {
                return Err(SceneError::semantic(
                    format!("{path}.grasp_force_limit"),
                    limit.to_string(),
                    "a finite force > 0, N",
                ));
            }
            let gait = match (&d.gait, spec.walking) {
                (None, walking) => walking,
                (Some(g), None) => {
                    return Err(SceneError::semantic(
                        format!("{path}.gait"),
                        g.get_ron(),
                        format!(
                            "no gait field: only legged robots with a walking controller walk (robot `{}` has none)",
                            spec.id
                        ),
                    ))
                }
                (Some(g), Some(walking)) => {
                    let bad = |expected: String| {
                        SceneError::semantic(format!("{path}.gait"), g.get_ron(), expected)
                    };
                    let p = overlay_gait(&walking, g.get_ron()).map_err(bad)?;
                    p.check().map_err(bad)?;
                    Some(p)
                }
            };
            if let Some(s) = &d.script {
                check_script(&path, s)?;
            } else if modes.discrete {
                discrete = true;
            }
            let model = spec.load().map_err(|e| {
                SceneError::semantic(
                    format!("{path}.model"),
                    format!("{:?}", d.model),
                    e.to_string(),
                )
            })?;
            out.push(CompiledRobot {
                desc: d,
                spec,
                model,
                modes,
                grasp_force_limit: limit,
                gait,
            });
        }
        let acting = out.iter().filter(|r| r.desc.script.is_none()).count();
        if discrete && acting > 1 {
            return Err(SceneError::semantic(
                ctx.path(),
                "(robots)",
                "discrete actions with one acting robot only (the env's action is one Discrete(14) value)",
            ));
        }
        Ok(Arc::new(out))
    }

    fn spawn(&self, app: &mut SimApp, compiled: &CompiledSection) -> Result<(), SceneError> {
        let robots = compiled
            .downcast_ref::<Vec<CompiledRobot>>()
            .ok_or_else(|| {
                SceneError::semantic("extensions[\"robots\"]", "(compiled)", "robots")
            })?;
        let mut next_index = {
            let mut q = app.world.query::<&Object>();
            q.iter(&app.world).map(|o| o.index + 1).max().unwrap_or(0)
        };
        let mut runtime = Vec::with_capacity(robots.len());
        let mut spaces = Vec::new();
        for (i, c) in robots.iter().enumerate() {
            let path = format!("extensions[\"robots\"][{i}] \"{}\"", c.desc.name);
            let r = spawn_one(app, c, &mut next_index).map_err(|e| robot_err(&path, e))?;
            if c.desc.script.is_none() {
                spaces.extend(c.modes.space(
                    &c.desc.name,
                    c.spec.arm_joints.len(),
                    c.spec.leg_joints.len(),
                ));
            }
            runtime.push(r);
        }
        app.world.insert_resource(Robots { robots: runtime });
        let mut s = app.world.get_resource_or_insert_with(Spaces::default);
        s.action = match spaces.len() {
            0 => Space::unbounded(0),
            1 => spaces
                .pop()
                .map(|(_, sp)| sp)
                .unwrap_or(Space::unbounded(0)),
            _ => Space::Dict(spaces),
        };
        Ok(())
    }

    fn cameras(&self, compiled: &CompiledSection) -> Vec<CameraMount> {
        compiled
            .downcast_ref::<Vec<CompiledRobot>>()
            .map_or_else(Vec::new, |robots| robot_cameras(robots))
    }
}

/// The cameras of the robots' files on `<robot name>/<link>`, named `<robot name>` (the robot's
/// own camera) or `<robot name>/<camera>`.
fn robot_cameras(robots: &[CompiledRobot]) -> Vec<CameraMount> {
    robots
        .iter()
        .flat_map(|c| {
            c.spec.cameras.iter().map(|m| CameraMount {
                name: match &m.name {
                    Some(n) => format!("{}/{n}", c.desc.name),
                    None => c.desc.name.clone(),
                },
                attach: format!("{}/{}", c.desc.name, m.link),
                pose: m.pose,
                look_at: m.look_at,
                width: m.width,
                height: m.height,
                fov_y_deg: m.fov,
            })
        })
        .collect()
}

fn check_script(path: &str, s: &Script) -> Result<(), SceneError> {
    let sorted =
        |ts: Vec<f64>| ts.windows(2).all(|w| w[0] <= w[1]) && ts.iter().all(|t| t.is_finite());
    if !sorted(s.base.iter().map(|b| b.t).collect())
        || s.base
            .iter()
            .any(|b| b.v.iter().any(|x| !x.is_finite() || x.abs() > 1.0))
    {
        return Err(SceneError::semantic(
            format!("{path}.script.base"),
            format!("{:?}", s.base),
            "entries sorted by finite t, each v in [-1, 1]^3",
        ));
    }
    if !sorted(s.ee.iter().map(|e| e.t).collect())
        || s.ee
            .iter()
            .any(|e| e.pos.iter().any(|x| !(x.is_finite() && x.abs() <= 100.0)))
    {
        return Err(SceneError::semantic(
            format!("{path}.script.ee"),
            format!("{:?}", s.ee),
            "waypoints sorted by finite t with positions within 100 m of the base (base frame, m)",
        ));
    }
    if !sorted(s.gripper.iter().map(|g| g.t).collect()) {
        return Err(SceneError::semantic(
            format!("{path}.script.gripper"),
            format!("{:?}", s.gripper),
            "entries sorted by finite t",
        ));
    }
    if let Some(p) = s.period {
        if !(p.is_finite() && p > 0.0) {
            return Err(SceneError::semantic(
                format!("{path}.script.period"),
                p.to_string(),
                "a finite period > 0, s",
            ));
        }
    }
    Ok(())
}

/// The robot a scene's `model` names: a registered robot, else a description file
/// (`*.robot.ron`) tried against the scene's folder and then its asset roots.
fn model_spec(
    ctx: &SectionCompileContext,
    path: &str,
    model: &str,
) -> Result<RobotSpec, SceneError> {
    let field = format!("{path}.model");
    let value = format!("{model:?}");
    if let Some(entry) = ctx.registry.robots.get(model) {
        if let Some(spec) = entry.payload.downcast_ref::<RobotSpec>() {
            return Ok(spec.clone());
        }
        let expected = match entry.payload.downcast_ref::<BrokenRobot>() {
            Some(BrokenRobot(m)) => m.clone(),
            None => "a robot registered with a RobotSpec (the robots plugin's model type)".into(),
        };
        return Err(SceneError::semantic(field, value, expected));
    }
    if !model.ends_with(".robot.ron") {
        let names: Vec<&str> = ctx.registry.robots.keys().map(String::as_str).collect();
        return Err(SceneError::semantic(
            field,
            value,
            format!(
                "a registered robot: [{}], or a robot description file *.robot.ron (relative to the scene's folder)",
                names.join(", ")
            ),
        ));
    }
    let source = ctx.source;
    let roots: Vec<PathBuf> = std::iter::once(source.base_dir.clone())
        .chain(source.asset_roots.iter().cloned())
        .collect();
    let written = Path::new(model);
    let candidates: Vec<PathBuf> = if written.is_absolute() {
        vec![written.to_path_buf()]
    } else {
        roots.iter().map(|r| r.join(written)).collect()
    };
    let Some(file) = candidates.iter().find(|c| c.is_file()) else {
        return Err(SceneError::semantic(
            field,
            value,
            format!(
                "a registered robot or an existing robot description file; tried {}",
                candidates
                    .iter()
                    .map(|c| c.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    };
    RobotSpec::from_file(file, &roots)
        .map_err(|e| SceneError::semantic(field, value, e.to_string()))
}

/// The trot parameters `walking` with the fields a scene's `gait` (RON text) gives in their
/// place; errors say which field is unknown or of the wrong type.
fn overlay_gait(walking: &TrotParams, gait: &str) -> Result<TrotParams, String> {
    let gait: ron::Value = modesuite_engine::scene::ron_options()
        .from_str(gait)
        .map_err(|e| e.to_string())?;
    let gait = match &gait {
        ron::Value::Option(Some(g)) => g.as_ref(),
        g => g,
    };
    let fields = match gait {
        ron::Value::Map(m) => m.clone(),
        // `gait: ()`: no field replaced
        ron::Value::Unit => ron::Map::new(),
        _ => return Err("a struct of trot parameters, e.g. (period: 0.35, kp: 900.0)".into()),
    };
    let text = ron::to_string(walking).map_err(|e| e.to_string())?;
    let mut merged = match ron::from_str::<ron::Value>(&text) {
        Ok(ron::Value::Map(m)) => m,
        _ => return Err("the robot's walking parameters do not read back".into()),
    };
    for (k, v) in fields.iter() {
        merged.insert(k.clone(), v.clone());
    }
    ron::Value::Map(merged)
        .into_rust::<TrotParams>()
        .map_err(|e| format!("trot parameters (locomotion::TrotParams): {e}"))
}

fn resolve_modes(
    path: &str,
    spec: &RobotSpec,
    c: &ActionConfig,
) -> Result<ActionModes, SceneError> {
    let base = c
        .base
        .or(spec.base_modes.first().copied())
        .unwrap_or(BaseMode::Off);
    let arm = c
        .arm
        .or(spec.arm_modes.first().copied())
        .unwrap_or(ArmMode::Off);
    let gripper = c
        .gripper
        .or(spec.gripper_modes.first().copied())
        .unwrap_or(GripperMode::Off);
    let refuse = |part: &str, mode: String, valid: String| {
        SceneError::semantic(
            format!("{path}.actions.{part}"),
            mode,
            format!("one of the {part} modes of robot `{}`: {valid}", spec.id),
        )
    };
    let list = |v: Vec<String>| v.join(", ");
    if !spec.base_modes.contains(&base) {
        let valid = list(spec.base_modes.iter().map(|m| format!("{m:?}")).collect());
        return Err(refuse("base", format!("{base:?}"), valid));
    }
    if !spec.arm_modes.contains(&arm) {
        let valid = list(spec.arm_modes.iter().map(|m| format!("{m:?}")).collect());
        return Err(refuse("arm", format!("{arm:?}"), valid));
    }
    if !spec.gripper_modes.contains(&gripper) {
        let valid = list(
            spec.gripper_modes
                .iter()
                .map(|m| format!("{m:?}"))
                .collect(),
        );
        return Err(refuse("gripper", format!("{gripper:?}"), valid));
    }
    for (field, v) in [
        ("joint_delta_scale", c.joint_delta_scale),
        ("ee_speed", c.ee_speed),
        ("ee_angular_speed", c.ee_angular_speed),
        ("leg_scale", c.leg_scale),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(SceneError::semantic(
                format!("{path}.actions.{field}"),
                v.to_string(),
                "a finite number > 0",
            ));
        }
    }
    Ok(ActionModes {
        base,
        arm,
        gripper,
        discrete: c.discrete,
        joint_delta_scale: c.joint_delta_scale,
        ee_speed: c.ee_speed,
        ee_angular_speed: c.ee_angular_speed,
        leg_scale: c.leg_scale,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scene_gait_replaces_only_the_fields_it_gives() {
        let walking = TrotParams {
            period: 0.37,
            kp: 812.5,
            ..TrotParams::default()
        };
        assert_eq!(overlay_gait(&walking, "()").unwrap(), walking);
        let p = overlay_gait(&walking, "(kp: 900, max_command: (0.25, 0.5, 1.0))").unwrap();
        assert_eq!(
            p,
            TrotParams {
                kp: 900.0,
                max_command: [0.25, 0.5, 1.0],
                ..walking
            }
        );
        let e = overlay_gait(&walking, "(perod: 0.3)").unwrap_err();
        assert!(e.contains("perod"), "{e}");
        let e = overlay_gait(&walking, "0.3").unwrap_err();
        assert!(e.contains("struct"), "{e}");
    }
}
