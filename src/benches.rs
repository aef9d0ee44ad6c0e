//! The `modesuite bench fem`, `bench pbd` and `bench render` suites: the deformable solvers on the reference rod
//! and the reference sheet (../shared/bench defines both), one thread, and 16 copies on one
//! thread and on all threads.
//!
//! Extra JSON keys: FEM `tip_deflection_m` (nonlinear static solve; for `rod_stiff_x16` the
//! dynamic tip of rod 0 at the end of the run), `tip_deflection_linear_m`,
//! `theory_m` (Euler-Bernoulli q L^4 / 8 E I), `nodes`, `elements`, `element_type`; PBD
//! `stretch_mean` (mean of L/L0 - 1), `stretch_max`, `particles_inside` (most particles deeper
//! than 5 mm inside the cube at any checked step).

use std::collections::BTreeMap;
use std::time::Instant;

use bevy_ecs::world::World;
use modesuite_engine::bench::{BenchOptions, BenchRecord};
use modesuite_fem::bench::{
    cantilever_theory, reference_rod, run_rod_bench, RodBench, ROD_POISSON,
};
use modesuite_fem::{FemConfig, NoContacts};
use modesuite_pbd::bench::{reference_scene, run_reference, BenchConfig, REFERENCE_DT};
use rayon::prelude::*;
use serde_json::json;

fn pool(threads: usize) -> Result<rayon::ThreadPool, String> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| e.to_string())
}

/// The thread counts of the x16 cases: one, and all of `opts.threads` (0 = every core) when that
/// is more than one.
pub(crate) fn thread_counts(opts: &BenchOptions) -> Result<Vec<usize>, String> {
    let all = pool(opts.threads)?.current_num_threads();
    Ok(if all > 1 { vec![1, all] } else { vec![1] })
}

/// Steps every item `n` times on a pool of `threads` threads; returns item-steps per second.
fn time_parallel<T: Send, E: std::fmt::Display + Send>(
    threads: usize,
    items: &mut [T],
    n: usize,
    step: impl Fn(&mut T) -> Result<(), E> + Sync,
) -> Result<f64, String> {
    let p = pool(threads)?;
    let t = Instant::now();
    p.install(|| {
        items.par_iter_mut().try_for_each(|item| {
            for _ in 0..n {
                step(item)?;
            }
            Ok(())
        })
    })
    .map_err(|e: E| e.to_string())?;
    Ok((items.len() * n) as f64 / t.elapsed().as_secs_f64())
}

fn steps(base: f64, opts: &BenchOptions) -> usize {
    ((base * opts.scale) as usize).max(5)
}

/// FEM cases: `rod_soft` (E 1e6), `rod_stiff` (E 1e8), both on the 10 x 1 x 1 grid (60 ten-node
/// tets, within 5 % of beam theory), `rod_stiff_peer_grid` (the peers' 40 x 2 x 2 grid, 960 tets),
/// `rod_stiff_x16` (16 rods, one thread and all threads).
pub fn fem_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    for (case, e, cells, base) in [
        ("rod_soft", 1e6, [10, 1, 1], 600.0),
        ("rod_stiff", 1e8, [10, 1, 1], 600.0),
        ("rod_stiff_peer_grid", 1e8, [40, 2, 2], 60.0),
    ] {
        let r = run_rod_bench(&RodBench {
            youngs_modulus: e,
            cells,
            steps: steps(base, opts),
            dt: 1.0 / 60.0,
        })
        .map_err(|e| format!("{case}: {e}"))?;
        let mut extra = BTreeMap::new();
        extra.insert(
            "tip_deflection_m".into(),
            json!(r.nonlinear_static_deflection),
        );
        extra.insert(
            "tip_deflection_linear_m".into(),
            json!(r.linear_static_deflection),
        );
        extra.insert("theory_m".into(), json!(r.theory));
        extra.insert("nodes".into(), json!(r.nodes));
        extra.insert("elements".into(), json!(r.elements));
        extra.insert("element_type".into(), json!("tet10"));
        out.push(BenchRecord::new(case, r.steps_per_second, 1, 1, extra));
    }
    let n = steps(300.0, opts);
    let g = nalgebra::Vector3::new(0.0, 0.0, -9.81);
    for threads in thread_counts(opts)? {
        let mut rods = (0..16)
            .map(|_| {
                reference_rod(1e8, ROD_POISSON, [10, 1, 1], FemConfig::default())
                    .map(|(rod, tip)| (rod, tip, Vec::new()))
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        let tip = rods[0].1;
        let tip_rest = rods[0].0.embedded_position(&tip).z;
        let sps = time_parallel(threads, &mut rods, n, |(rod, _, reactions)| {
            reactions.clear();
            rod.step(1.0 / 60.0, g, &NoContacts, reactions).map(|_| ())
        })?;
        let rod = &rods[0].0;
        let mut extra = BTreeMap::new();
        extra.insert("theory_m".into(), json!(cantilever_theory(1e8)));
        // Dynamic: the tip of rod 0 at the end of the run (still swinging in short runs).
        extra.insert(
            "tip_deflection_m".into(),
            json!(tip_rest - rod.embedded_position(&tip).z),
        );
        extra.insert("nodes".into(), json!(rod.n_nodes()));
        extra.insert("elements".into(), json!(rod.shared_model().n_elements()));
        extra.insert("element_type".into(), json!("tet10"));
        out.push(BenchRecord::new("rod_stiff_x16", sps, threads, 16, extra));
    }
    Ok(out)
}

/// PBD cases on the reference sheet: `cloth`, `cloth_selfcollide`, `cloth_x16` (16 sheets, one
/// thread and all threads).
pub fn pbd_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    for (case, sc) in [("cloth", false), ("cloth_selfcollide", true)] {
        let cfg = BenchConfig {
            steps: steps(600.0, opts),
            ..BenchConfig::reference(sc)
        };
        let r = run_reference(&cfg).map_err(|e| format!("{case}: {e}"))?;
        let mut extra = BTreeMap::new();
        extra.insert("stretch_mean".into(), json!(r.stretch.mean));
        extra.insert("stretch_max".into(), json!(r.stretch.max));
        extra.insert("particles_inside".into(), json!(r.max_inside_cube));
        out.push(BenchRecord::new(case, r.steps_per_second, 1, 1, extra));
    }
    let n = steps(300.0, opts);
    let g = nalgebra::Vector3::new(0.0, 0.0, -9.81);
    for threads in thread_counts(opts)? {
        let cfg = BenchConfig::reference(false);
        let mut sheets = (0..16)
            .map(|_| reference_scene(&cfg).map(|(cloth, cube)| (cloth, cube, Vec::new())))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        let sps = time_parallel(threads, &mut sheets, n, |(cloth, cube, reactions)| {
            reactions.clear();
            cloth.step(REFERENCE_DT, &g, &*cube, reactions).map(|_| ())
        })?;
        let s = sheets[0].0.stretch_stats();
        let inside = sheets
            .iter()
            .map(|(c, cube, _)| {
                cube.count_inside(c.positions(), modesuite_pbd::bench::INSIDE_TOLERANCE)
            })
            .max()
            .unwrap_or(0);
        let mut extra = BTreeMap::new();
        extra.insert("stretch_mean".into(), json!(s.mean));
        extra.insert("stretch_max".into(), json!(s.max));
        extra.insert("particles_inside".into(), json!(inside));
        out.push(BenchRecord::new("cloth_x16", sps, threads, 16, extra));
    }
    Ok(out)
}

/// Base position of the first robot of an env.
fn robot_base(env: &modesuite_engine::Env) -> Result<nalgebra::Vector3<f64>, String> {
    let robots = env.app.world.resource::<modesuite_robots::Robots>();
    let ctx = env.app.world.resource::<modesuite_engine::RigidContext>();
    let r = robots.robots.first().ok_or("no robot")?;
    let o = r.observe(ctx).map_err(|e| e.to_string())?;
    Ok(o.base.translation.vector)
}

/// Robot cases: each robot alone on flat ground at dt 1/60 s with its controller on, through
/// the full env path, with the rapier settings of its robot-only scenes (`RobotSpec::substeps`:
/// Franka 1, Spot 2 substeps; `RobotSpec::pgs_iterations` Gauss-Seidel sweeps). `franka`: base
/// velocity (0.25 m/s forward) and joint-delta arm mode with a constant arm command; `spot`:
/// walking forward at 0.5 m/s (`Locomotion`). Extra keys: `robot`, `mode`, `distance_m` (base
/// travel during the run, to show it moved), `substeps` (physics substeps per step).
pub fn robots_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    for (id, actions, mode) in [
        (
            "franka",
            "(base: Velocity, arm: JointDelta)",
            "velocity+joint_delta",
        ),
        (
            "spot",
            "(base: Locomotion, arm: JointDelta)",
            "locomotion+joint_delta",
        ),
    ] {
        // the robot's substeps and Gauss-Seidel sweeps, as its scenes have them
        let spec = modesuite_robots::RobotSpec::builtin(id).map_err(|e| e.to_string())?;
        let (case, sub, pgs) = (spec.id.as_str(), spec.substeps, spec.pgs_iterations);
        let text = format!(
            r#"Scene(
    physics: (dt: 0.016666666666666666, substeps: {sub}, rigid_iterations: 1, rigid_pgs_iterations: {pgs}),
    objects: [(name: "ground", shape: Plane(size: (200.0, 200.0)), body: Static)],
    extensions: {{ "robots": [(name: "robot", model: "{case}", actions: {actions})] }},
)"#
        );
        let mut env = crate::make::env_from_text(&text).map_err(|e| format!("{case}: {e}"))?;
        env.reset(Some(0));
        let n = env.spaces().action.flat_dim();
        // Forward at half the base limit (franka 0.25 m/s) or the full walking command (spot
        // 0.5 m/s); the arm's first joint drifts slowly.
        let mut a = vec![0.0f32; n];
        a[0] = if case == "spot" { 1.0 } else { 0.5 };
        if n > 3 {
            a[3] = 0.05;
        }
        let start = robot_base(&env)?;
        let steps = steps(600.0, opts);
        let t = Instant::now();
        for _ in 0..steps {
            let o = env.step(&a);
            if let Some(e) = o.info.error {
                return Err(format!("{case}: {e}"));
            }
        }
        let sps = steps as f64 / t.elapsed().as_secs_f64();
        let end = robot_base(&env)?;
        let mut extra = BTreeMap::new();
        extra.insert("robot".into(), json!(case));
        extra.insert("mode".into(), json!(mode));
        extra.insert("distance_m".into(), json!((end - start).xy().norm()));
        extra.insert("substeps".into(), json!(sub));
        out.push(BenchRecord::new(case, sps, 1, 1, extra));
    }
    Ok(out)
}

/// Rounds of the interleaved 1-env / 16-env measurement of [`tasks_cases`].
pub const TASK_ROUNDS: usize = 4;

/// Task cases, one per implemented environment id (the other ids are not implemented yet): the
/// env with its state observation and the zero action, `ID` (1 env, 1 thread) and `ID_x16` (16
/// envs stepped by a `VecEnv`, one thread and all threads). Extra keys: `task`, `single_runs`
/// (the single-env rate in each round), `overhead` (x16 on one thread: per-env time over the
/// single env's, minus 1; 0.10 = 10 % slower per env), `overhead_rounds` (the same per round),
/// and its two parts: `turns_overhead` (16 envs stepped in turn by a plain loop over the single
/// env's: the cost of 16 worlds' state sharing the caches, which one world alone keeps warm) and
/// `path_overhead` (the one-thread `VecEnv` over that loop: the cost of the vectorised path
/// itself).
///
/// All sides do the same work: 16 envs, env `i` reset with seed `i` (as a `VecEnv` seeds them),
/// each stepped through the same window of the episode. The single-env side steps them one after
/// another (each env alone for the window, as a single env runs), the loop side steps the 16 in
/// turn, one step each, and the x16 side in lock step through a one-thread `VecEnv`. The window
/// is cut into [`TASK_ROUNDS`] rounds and the sides take turns, so all see the same machine: a
/// shared VM's speed drifts 5-15 % within a minute. `steps_per_s` and the overheads come from
/// the summed times.
pub fn tasks_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    for id in modesuite_tasks::IMPLEMENTED {
        // 16 envs sharing one compiled scene, as a `VecEnv` of a task gets them
        let make = || -> Result<Vec<modesuite_engine::Env>, String> {
            let mut envs =
                crate::make::envs_for_target(id, None, 16).map_err(|e| format!("{id}: {e}"))?;
            for (i, e) in envs.iter_mut().enumerate() {
                e.reset(Some(i as u64));
            }
            Ok(envs)
        };
        let mut singles = make()?;
        let zero = vec![0.0f32; singles[0].spaces().action.flat_dim()];
        let actions = vec![0.0f32; 16 * zero.len()];
        let x16_envs = |threads: usize| -> Result<modesuite_engine::VecEnv, String> {
            modesuite_engine::VecEnv::new(make()?, threads).map_err(|e| e.to_string())
        };
        let time_x16 = |venv: &mut modesuite_engine::VecEnv, w: usize| -> Result<f64, String> {
            let t = Instant::now();
            for _ in 0..w {
                venv.step(&actions).map_err(|e| e.to_string())?;
            }
            Ok(t.elapsed().as_secs_f64())
        };
        // steps per round (at least one: `--scale 0.01`, the CLI test, runs 4 per env)
        let w = ((300.0 * opts.scale / TASK_ROUNDS as f64) as usize).max(1);
        let n = w * TASK_ROUNDS;
        let mut by_hand = make()?;
        let mut venv = x16_envs(1)?;
        let step = |env: &mut modesuite_engine::Env| match env.step(&zero).info.error {
            Some(e) => Err(format!("{id}: {e}")),
            None => Ok(()),
        };
        // per round: (each env alone, the 16 stepped in turn by hand, the `VecEnv`) seconds
        let mut rounds = Vec::with_capacity(TASK_ROUNDS);
        for _ in 0..TASK_ROUNDS {
            let t = Instant::now();
            for env in &mut singles {
                for _ in 0..w {
                    step(env)?;
                }
            }
            let t1 = t.elapsed().as_secs_f64();
            let t = Instant::now();
            for _ in 0..w {
                for env in &mut by_hand {
                    step(env)?;
                }
            }
            let t_turns = t.elapsed().as_secs_f64();
            rounds.push((t1, t_turns, time_x16(&mut venv, w)?));
        }
        drop((venv, singles, by_hand));
        let t1: f64 = rounds.iter().map(|r| r.0).sum();
        let t_turns: f64 = rounds.iter().map(|r| r.1).sum();
        let t16: f64 = rounds.iter().map(|r| r.2).sum();
        let mut x16 = vec![(1, (16 * n) as f64 / t16, Some(t16 / t1 - 1.0))];
        for threads in thread_counts(opts)?.into_iter().filter(|&t| t != 1) {
            let mut venv = x16_envs(threads)?;
            x16.push((threads, (16 * n) as f64 / time_x16(&mut venv, n)?, None));
        }
        let mut extra = BTreeMap::new();
        extra.insert("task".into(), json!(id));
        extra.insert(
            "single_runs".into(),
            json!(rounds
                .iter()
                .map(|r| (16 * w) as f64 / r.0)
                .collect::<Vec<_>>()),
        );
        out.push(BenchRecord::new(id, (16 * n) as f64 / t1, 1, 1, extra));
        for (threads, sps, overhead) in x16 {
            let mut extra = BTreeMap::new();
            extra.insert("task".into(), json!(id));
            if let Some(o) = overhead {
                extra.insert("overhead".into(), json!(o));
                extra.insert(
                    "overhead_rounds".into(),
                    json!(rounds.iter().map(|r| r.2 / r.0 - 1.0).collect::<Vec<_>>()),
                );
                extra.insert("turns_overhead".into(), json!(t_turns / t1 - 1.0));
                extra.insert("path_overhead".into(), json!(t16 / t_turns - 1.0));
            }
            out.push(BenchRecord::new(
                &format!("{id}_x16"),
                sps,
                threads,
                16,
                extra,
            ));
        }
    }
    Ok(out)
}

/// The scene of the render suite (embedded, so the suite runs from any folder).
pub const RENDER_BENCH_SCENE: &str = include_str!("../scenes/examples/tabletop_cameras.scene.ron");

/// A spawned, reset env of the render bench scene with its renderer (shared device).
fn render_bench_env() -> Result<(modesuite_engine::Env, modesuite_render::EnvRenderer), String> {
    let desc = modesuite_engine::scene::parse_str(RENDER_BENCH_SCENE, "tabletop_cameras.scene.ron")
        .map_err(|e| e.to_string())?;
    let mut app = crate::make::default_app();
    let model = app
        .compile_scene(&desc, &modesuite_engine::SceneSource::in_memory("."))
        .map_err(|e| e.to_string())?;
    app.spawn_scene(model.clone()).map_err(|e| e.to_string())?;
    let renderer = modesuite_render::EnvRenderer::for_scene(model).map_err(|e| e.to_string())?;
    let mut env = modesuite_engine::Env::new(app);
    env.reset(Some(0));
    Ok((env, renderer))
}

/// Render cases on the tabletop scene (cloth, FEM rod, rigid bodies, shadows), rendering and
/// reading back RGB + depth + segmentation of a static world (physics not stepped):
/// `rgbd_128` (the 128 x 128 overhead camera), `rgbd_640` (the 640 x 480 front camera),
/// `rgbd_128_x16` (16 envs, one 128 x 128 camera each, batched into one submission).
/// `steps_per_s` is images per second. Extra keys: `width`, `height`, `images`, `adapter`,
/// `software` (a CPU rasteriser), `triangles`.
pub fn render_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    let record = |case: &str,
                  ips: f64,
                  envs: usize,
                  cam: &modesuite_render::CameraDesc,
                  images: usize,
                  r: &modesuite_render::EnvRenderer,
                  triangles: usize| {
        let mut extra = BTreeMap::new();
        extra.insert("width".into(), json!(cam.width));
        extra.insert("height".into(), json!(cam.height));
        extra.insert("images".into(), json!(images));
        extra.insert("adapter".into(), json!(r.device().adapter_name()));
        extra.insert("software".into(), json!(r.device().is_software()));
        extra.insert("triangles".into(), json!(triangles));
        BenchRecord::new(case, ips, 1, envs, extra)
    };
    for (case, camera, base) in [
        ("rgbd_128", "overhead", 1000.0),
        ("rgbd_640", "front", 150.0),
    ] {
        let (env, mut r) = render_bench_env()?;
        let cam = r.scene_camera(camera).map_err(|e| e.to_string())?.clone();
        let cams = [cam.clone()];
        let mut frame = Vec::new();
        for _ in 0..5 {
            frame = r
                .render_cameras(&env.app.world, &cams)
                .map_err(|e| e.to_string())?;
        }
        let n = steps(base, opts);
        let t = Instant::now();
        for _ in 0..n {
            frame = r
                .render_cameras(&env.app.world, &cams)
                .map_err(|e| e.to_string())?;
        }
        let ips = n as f64 / t.elapsed().as_secs_f64();
        let tris = r.last_triangles();
        if frame.first().is_none_or(|f| f.rgb.is_empty()) {
            return Err(format!("{case}: no image rendered"));
        }
        out.push(record(case, ips, 1, &cam, n, &r, tris));
    }
    let mut envs = (0..16)
        .map(|_| render_bench_env())
        .collect::<Result<Vec<_>, _>>()?;
    let cam = envs[0]
        .1
        .scene_camera("overhead")
        .map_err(|e| e.to_string())?
        .clone();
    let cams = [cam.clone()];
    let batch = |envs: &mut Vec<(modesuite_engine::Env, modesuite_render::EnvRenderer)>| {
        let mut items: Vec<(&mut modesuite_render::EnvRenderer, &World)> =
            envs.iter_mut().map(|(e, r)| (r, &e.app.world)).collect();
        modesuite_render::render_batch(&mut items, &cams).map_err(|e| e.to_string())
    };
    for _ in 0..3 {
        batch(&mut envs)?;
    }
    let n = steps(100.0, opts);
    let t = Instant::now();
    for _ in 0..n {
        batch(&mut envs)?;
    }
    let ips = (16 * n) as f64 / t.elapsed().as_secs_f64();
    let tris = envs[0].1.last_triangles();
    out.push(record(
        "rgbd_128_x16",
        ips,
        16,
        &cam,
        16 * n,
        &envs[0].1,
        tris,
    ));
    Ok(out)
}
