//! Task events registered by a plugin (`register_task_event`) and used in a task section as
//! `Event(event: NAME, params: ...)`: configured when the scene compiles (located errors),
//! applied at reset through the same world access as the built-in events, refused inside
//! `Interval(...)` unless they move no body.

use std::sync::Arc;

use modesuite::engine::components::{DeformableNodes, Object};
use modesuite::engine::prelude::*;
use modesuite::engine::scene;
use modesuite::make::default_app;
use modesuite::tasks::{register_task_event, Configure, EventCtx, TaskEvent, TaskEventFactory};
use nalgebra::{Isometry3, Vector3};
use serde::Deserialize;

/// `test.lift`: raises a deformable by `dz` plus a draw in `+- jitter` (m).
struct Lift {
    object: String,
    dz: f64,
    jitter: f64,
}

impl TaskEvent for Lift {
    fn apply(&self, ctx: &mut EventCtx) -> Result<(), String> {
        let j = if self.jitter > 0.0 {
            ctx.uniform(-self.jitter, self.jitter)
        } else {
            0.0
        };
        ctx.move_object(&self.object, &Isometry3::translation(0.0, 0.0, self.dz + j))
    }
}

#[derive(Deserialize)]
struct LiftParams {
    object: String,
    dz: f64,
    #[serde(default)]
    jitter: f64,
}

struct LiftFactory;

impl TaskEventFactory for LiftFactory {
    fn configure(&self, params: &str, cfg: &Configure) -> Result<Arc<dyn TaskEvent>, String> {
        let p: LiftParams = ron::from_str(params).map_err(|e| e.to_string())?;
        cfg.object(&p.object)?;
        if !(p.dz.is_finite() && p.dz.abs() <= 1.0) {
            return Err(format!("dz = {}: within +-1 m", p.dz));
        }
        Ok(Arc::new(Lift {
            object: p.object,
            dz: p.dz,
            jitter: p.jitter,
        }))
    }
}

struct TestEvents;

impl Plugin for TestEvents {
    fn build(&self, app: &mut SimApp) {
        register_task_event(
            app,
            "test.lift",
            "raise a deformable by dz (test)",
            Arc::new(LiftFactory),
        );
    }
    fn name(&self) -> &str {
        "test-events"
    }
}

/// Franka Place with `extra` added to its task's events.
fn place_with(extra: &str) -> Result<Env, String> {
    let file = modesuite::make::scenes_dir().join("place/franka.scene.ron");
    let text = std::fs::read_to_string(&file).unwrap();
    let old = r#"events: {"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"])},"#;
    assert!(text.contains(old));
    let new = format!(
        r#"events: {{"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"]), {extra}}},"#
    );
    let text = text.replace(old, &new);
    let desc = scene::parse_str(&text, "place.scene.ron").map_err(|e| e.to_string())?;
    let mut source = scene::SceneSource::in_memory(file.parent().unwrap());
    source.text = Some(text);
    let mut app = default_app();
    app.add_plugins(TestEvents);
    let model = app
        .compile_scene(&desc, &source)
        .map_err(|e| e.to_string())?;
    app.spawn_scene(model).map_err(|e| e.to_string())?;
    Ok(Env::new(app))
}

fn rod_nodes(env: &mut Env) -> Vec<Vector3<f64>> {
    let mut q = env.app.world.query::<(&Object, &DeformableNodes)>();
    q.iter(&env.app.world)
        .find(|(o, _)| o.name == "rod")
        .map(|(_, n)| n.0.clone())
        .unwrap()
}

#[test]
fn a_registered_event_runs_at_reset() {
    let mut plain =
        place_with(r#""noop": Event(event: "test.lift", params: (object: "rod", dz: 0.0))"#)
            .unwrap();
    let mut lifted =
        place_with(r#""lift": Event(event: "test.lift", params: (object: "rod", dz: 0.05))"#)
            .unwrap();
    for seed in [0, 7] {
        plain.reset(Some(seed));
        lifted.reset(Some(seed));
        let (a, b) = (rod_nodes(&mut plain), rod_nodes(&mut lifted));
        let dz: Vec<f64> = a.iter().zip(&b).map(|(p, q)| q.z - p.z).collect();
        let dxy = a
            .iter()
            .zip(&b)
            .map(|(p, q)| ((q.x - p.x).abs()).max((q.y - p.y).abs()))
            .fold(0.0, f64::max);
        let worst = dz.iter().map(|d| (d - 0.05).abs()).fold(0.0, f64::max);
        println!(
            "seed {seed}: rod raised by 0.05 m within {worst:.1e} m over {} nodes (tol 1e-12), x/y unchanged within {dxy:.1e}",
            dz.len()
        );
        assert!(worst < 1e-12 && dxy < 1e-12);
    }
    // Its draws come from the env's stream: same seed, same result; the episode steps.
    let mut j1 = place_with(
        r#""lift": Event(event: "test.lift", params: (object: "rod", dz: 0.05, jitter: 0.02))"#,
    )
    .unwrap();
    let mut j2 = place_with(
        r#""lift": Event(event: "test.lift", params: (object: "rod", dz: 0.05, jitter: 0.02))"#,
    )
    .unwrap();
    j1.reset(Some(3));
    j2.reset(Some(3));
    assert_eq!(rod_nodes(&mut j1), rod_nodes(&mut j2));
    let zero = vec![0.0; j1.spaces().action.flat_dim()];
    let out = j1.step(&zero);
    assert!(out.info.error.is_none(), "{:?}", out.info.error);
}

#[test]
fn registered_event_errors_are_located() {
    let cases = [
        (
            r#""x": Event(event: "test.fly", params: ())"#,
            r#"events["x"].event = "test.fly": a registered event: [test.lift]"#,
        ),
        (
            r#""x": Event(event: "test.lift", params: (object: "nope", dz: 0.1))"#,
            r#"events["x"].params"#,
        ),
        (
            r#""x": Event(event: "test.lift", params: (object: "rod", dz: 5.0))"#,
            "dz = 5: within +-1 m",
        ),
        (
            r#""x": Interval(every: (1.0, 2.0), event: Event(event: "test.lift", params: (object: "rod", dz: 0.1)))"#,
            "an event that moves no body",
        ),
    ];
    for (extra, want) in cases {
        let e = place_with(extra).err().expect("refused");
        println!("{extra}\n  -> {e}");
        assert!(e.contains(want), "{e}");
    }
}
