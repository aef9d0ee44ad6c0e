//! A third deformable solver written outside the solver crates (CONTRIBUTING.md, "Add a
//! solver"): free particles on a triangle sheet that fall under gravity and stop on the floor.
//! Through the engine's solver-neutral interface alone it is spawned from a scene, stepped,
//! saved in snapshots and state files, moved and pushed by task events, measured by the tasks'
//! region terms and given a surface for the renderer, with no edit to the tasks or render
//! crates.

use std::sync::Arc;

use modesuite::engine::coupling::{ContactQuery, Reaction};
use modesuite::engine::deformable::{add_deformable_systems, DeformableContext, DeformableSolver};
use modesuite::engine::registry::{BodyCompileContext, BodyKind, CompiledBody};
use modesuite::engine::scene::{self, SceneError};
use modesuite::engine::{DeformableSystems, Plugin, SimApp};
use modesuite::prelude::*;
use nalgebra::{Point3, UnitQuaternion, Vector3};

/// Particles without internal forces (dust on a sheet): explicit gravity, the floor at z = 0.
#[derive(Clone)]
struct Dust {
    x: Vec<Vector3<f64>>,
    v: Vec<Vector3<f64>>,
}

impl DeformableSolver for Dust {
    fn step_coupled(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        _query: &dyn ContactQuery,
        _reactions: &mut Vec<Reaction>,
    ) -> Result<(), String> {
        for (x, v) in self.x.iter_mut().zip(&mut self.v) {
            *v += gravity * dt;
            *x += *v * dt;
            if x.z < 0.0 {
                x.z = 0.0;
                *v = Vector3::zeros();
            }
        }
        Ok(())
    }
    fn node_positions(&self) -> &[Vector3<f64>] {
        &self.x
    }
    fn save(&self) -> Vec<f64> {
        self.x
            .iter()
            .chain(&self.v)
            .flat_map(|p| [p.x, p.y, p.z])
            .collect()
    }
    fn load(&mut self, state: &[f64]) -> Result<(), String> {
        let n = self.x.len();
        if state.len() != 6 * n {
            return Err(format!("{} values for {n} particles", state.len()));
        }
        for (i, c) in state.chunks(3).enumerate() {
            let p = Vector3::new(c[0], c[1], c[2]);
            if i < n {
                self.x[i] = p;
            } else {
                self.v[i - n] = p;
            }
        }
        Ok(())
    }
    fn move_rigidly(
        &mut self,
        positions: &[Vector3<f64>],
        rotation: &UnitQuaternion<f64>,
    ) -> Result<(), String> {
        self.x = positions.to_vec();
        self.v.iter_mut().for_each(|v| *v = rotation * *v);
        Ok(())
    }
    fn add_velocity(&mut self, dv: &Vector3<f64>) -> Result<(), String> {
        self.v.iter_mut().for_each(|v| *v += dv);
        Ok(())
    }
}

/// What the body kind compiles: the sheet's particles (world frame) and triangles.
struct CompiledDust {
    x: Vec<Vector3<f64>>,
    triangles: Vec<[u32; 3]>,
}

struct DustKind;

impl BodyKind for DustKind {
    fn name(&self) -> &str {
        "test.dust"
    }
    fn description(&self) -> &str {
        "free particles on a triangle sheet (a test solver)"
    }
    fn compile(&self, ctx: &BodyCompileContext) -> Result<CompiledBody, SceneError> {
        let s = ctx.object.shape.surface(ctx.shapes).map_err(|e| {
            SceneError::semantic(format!("{}.shape", ctx.path), "(shape)", e.to_string())
        })?;
        let pose = ctx.object.pose.isometry();
        Ok(Arc::new(CompiledDust {
            x: s.positions
                .iter()
                .map(|p| (pose * Point3::from(*p)).coords)
                .collect(),
            triangles: s.triangles,
        }))
    }
    fn spawn(
        &self,
        app: &mut SimApp,
        entity: Entity,
        body: &CompiledBody,
    ) -> Result<(), SceneError> {
        let c = body
            .downcast_ref::<CompiledDust>()
            .ok_or_else(|| SceneError::semantic("test.dust", "(body)", "a test.dust body"))?;
        let dust = Dust {
            x: c.x.clone(),
            v: vec![Vector3::zeros(); c.x.len()],
        };
        DeformableContext::<Dust>::spawn_into(app, entity, dust);
        Ok(())
    }
    fn surface_triangles(&self, body: &CompiledBody) -> Option<Vec<[u32; 3]>> {
        Some(body.downcast_ref::<CompiledDust>()?.triangles.clone())
    }
}

struct DustPlugin;

impl Plugin for DustPlugin {
    fn name(&self) -> &str {
        "test.dust"
    }
    fn build(&self, app: &mut SimApp) {
        add_deformable_systems::<Dust>(app, DeformableSystems("test.dust"));
        app.register_body_kind(Arc::new(DustKind));
    }
}

/// Franka Place with a dust sheet 1 m up over the floor in front of the robot, a reset event
/// that offsets it, one that pushes it sideways, and a reward that measures its cover of a
/// floor region.
fn env() -> Env {
    let dir = modesuite::make::scenes_dir().join("place");
    let text = std::fs::read_to_string(dir.join("franka.scene.ron")).unwrap();
    let objects = "objects: [";
    let events = r#"events: {"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"])},"#;
    assert!(text.contains(objects) && text.contains(events));
    let text = text
        .replacen(
            objects,
            r#"objects: [
        (name: "dust", shape: Grid(size: (0.4, 0.4), resolution: (9, 9)), pose: (pos: (0.0, -1.5, 1.0)),
         body: Kind(kind: "test.dust", params: ())),"#,
            1,
        )
        .replace(
            events,
            r#"events: {"robot_start": RobotPose(xy: 0.1, yaw: 0.1, carry: ["rod"]),
                      "dust_offset": ObjectOffset(object: "dust", xy: 0.05),
                      "dust_push": Push(object: "dust", velocity: (0.0, 0.4, 0.0))},
            rewards: {"dust_cover": (term: "cloth_coverage", weight: 1.0,
                                     params: (object: "dust", min: (-0.5, -2.0), max: (0.5, -1.0)))},"#,
        );
    let desc = scene::parse_str(&text, "<place with dust>").unwrap_or_else(|e| panic!("{e}"));
    let mut app = modesuite::make::default_app();
    app.add_plugins(DustPlugin);
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(&dir))
        .unwrap_or_else(|e| panic!("{e}"));
    let body = &model
        .objects
        .iter()
        .find(|o| o.name == "dust")
        .unwrap()
        .body;
    let tris = modesuite::render::geometry::deformable_triangles(body).expect("a surface");
    assert_eq!(
        tris.len(),
        8 * 8 * 2,
        "the renderer sees the solver's surface"
    );
    app.spawn_scene(model).unwrap_or_else(|e| panic!("{e}"));
    Env::new(app)
}

fn dust(env: &mut Env) -> Vec<Vector3<f64>> {
    let mut q = env.app.world.query::<(&Object, &DeformableNodes)>();
    q.iter(&env.app.world)
        .find(|(o, _)| o.name == "dust")
        .map(|(_, n)| n.0.clone())
        .unwrap()
}

#[test]
fn a_solver_outside_the_solver_crates_is_moved_pushed_measured_and_saved_by_tasks() {
    let mut env = env();
    let (_, info) = env.reset(Some(3));
    assert_eq!(info.error, None);
    let start = dust(&mut env);
    let centre = start.iter().sum::<Vector3<f64>>() / start.len() as f64;
    println!(
        "dust centre after reset {:.4?} (spawned at (0, -1.5, 1), offset up to 0.05 m in x and y)",
        centre
    );
    assert!((centre.x.abs() <= 0.05) && ((centre.y + 1.5).abs() <= 0.05) && centre.z == 1.0);
    assert!(
        centre.x != 0.0 || centre.y != -1.5,
        "the offset event moved it"
    );
    let act = env.spaces().action.flat_dim();
    let mut last = 0.0;
    for _ in 0..60 {
        let o = env.step(&vec![0.0; act]);
        assert_eq!(o.info.error, None);
        last = o.info.values["reward/dust_cover"];
    }
    let end = dust(&mut env);
    let moved: Vec<f64> = end.iter().zip(&start).map(|(a, b)| a.y - b.y).collect();
    let spread = moved
        .iter()
        .fold(0.0f64, |m, d| m.max((d - moved[0]).abs()));
    println!(
        "after 1 s: dust on the floor (max z {:.3} m), pushed {:.4} m along y by the Push event (a draw in +-0.4 m/s over the 0.45 s fall: at most 0.18 m), spread over particles {spread:.1e}, floor region covered {last:.4} of its 1 m^2",
        end.iter().map(|p| p.z).fold(f64::MIN, f64::max),
        moved[0]
    );
    assert!(end.iter().all(|p| p.z == 0.0));
    assert!(
        moved[0].abs() > 1e-3 && moved[0].abs() < 0.19,
        "{}",
        moved[0]
    );
    assert!(spread < 1e-9, "every particle got the same push: {spread}");
    // a 0.4 x 0.4 sheet on the floor inside the region: 0.16 m^2 of the 1 m^2 (raster error
    // at most a boundary row of the 40 x 40 cells around the sheet)
    assert!((last - 0.16).abs() < 0.03, "{last}");

    // its state goes through state files like the built-in solvers'
    let saved = env.save_state().unwrap();
    let mut again = self::env();
    again.reset(Some(9));
    again.load_state(&saved).unwrap();
    assert_eq!(again.state_hash(), env.state_hash());
    assert_eq!(dust(&mut again), end);
}
