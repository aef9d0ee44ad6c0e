//! A static plugin that adds a shape generator, and a scene built in Rust that uses it.
//!
//! Run: `cargo run --example custom_shape`. The generator `example.star_prism` extrudes a star
//! polygon; scenes refer to it by name in RON (`Gen(name: "example.star_prism", params: (...))`)
//! or through `ShapeDesc::generated` in Rust, exactly like the built-in shapes.

use std::sync::Arc;

use modesuite::engine::registry::ShapeGenerator;
use modesuite::engine::scene::{BodyDesc, ObjectDesc, PoseDesc};
use modesuite::engine::shapes::{GeneratedMesh, MeshKind, ShapeContext};
use modesuite::prelude::*;
use serde::{Deserialize, Serialize};

/// Parameters of the star prism, as written in RON.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StarParams {
    points: u32,
    outer: f64,
    inner: f64,
    height: f64,
}

struct StarPrism;

impl ShapeGenerator for StarPrism {
    fn name(&self) -> &str {
        "example.star_prism"
    }
    fn description(&self) -> &str {
        "a star polygon extruded along z (example plugin)"
    }
    fn generate(&self, params_ron: &str, want: MeshKind) -> Result<GeneratedMesh, String> {
        let p: StarParams = ron::from_str(params_ron).map_err(|e| format!("params: {e}"))?;
        if p.points < 3 || p.points > 64 {
            return Err(format!("points = {}: an integer in 3..=64", p.points));
        }
        let n = 2 * p.points as usize;
        let polygon = (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                let r = if i % 2 == 0 { p.outer } else { p.inner };
                (r * a.cos(), r * a.sin())
            })
            .collect();
        // Reuse the built-in Extrude: generators compose the engine's shapes.
        let shape = ShapeDesc::Extrude {
            polygon,
            height: p.height,
            layers: None,
        };
        shape.validate().map_err(|e| e.to_string())?;
        let ctx = ShapeContext::new(std::path::Path::new("."));
        match want {
            MeshKind::Surface => shape.surface(&ctx).map(GeneratedMesh::Surface),
            MeshKind::Volume => shape.volume(&ctx).map(GeneratedMesh::Volume),
        }
        .map_err(|e| e.to_string())
    }
}

/// The plugin: registers the generator.
struct StarPlugin;

impl Plugin for StarPlugin {
    fn name(&self) -> &str {
        "example.star"
    }
    fn build(&self, app: &mut SimApp) {
        app.register_shape(Arc::new(StarPrism));
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut app = SimApp::new();
    app.add_group(modesuite::DefaultPlugins);
    app.add_plugins(StarPlugin);

    // A scene built in Rust: ground, a static torus, and a dynamic star dropped on it.
    let star = ShapeDesc::generated(
        "example.star_prism",
        &StarParams {
            points: 5,
            outer: 0.2,
            inner: 0.08,
            height: 0.05,
        },
    )?;
    let object = |name: &str, shape, z: f64, body| ObjectDesc {
        name: name.into(),
        shape,
        pose: PoseDesc {
            pos: [0.0, 0.0, z],
            rpy: [0.0, 0.0, 0.0],
        },
        body,
        material: None,
        color: None,
        collide: true,
        collision_group: None,
    };
    let desc = SceneDesc {
        objects: vec![
            object(
                "ground",
                ShapeDesc::plane([5.0, 5.0]),
                0.0,
                BodyDesc::Static,
            ),
            object(
                "ring",
                ShapeDesc::torus(0.5, 0.05, 48, 12),
                0.05,
                BodyDesc::Static,
            ),
            object(
                "star",
                star,
                0.6,
                BodyDesc::Dynamic {
                    mass: None,
                    linear_velocity: [0.0; 3],
                    angular_velocity: [0.0, 0.0, 1.0],
                },
            ),
        ],
        ..SceneDesc::default()
    };
    let model = app.compile_scene(&desc, &SceneSource::in_memory("."))?;
    app.spawn_scene(model)?;
    let mut env = Env::new(app);
    env.reset(Some(0));
    for _ in 0..180 {
        env.step(&[]);
    }
    let state = modesuite::engine::dump::dump_state(&env.app.world);
    println!("star after 3 s: {}", state["objects"]["star"]["position"]);
    Ok(())
}
