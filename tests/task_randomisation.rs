//! The task environments' randomisation (friction, materials, Spot's start), task events
//! (startup and interval events, pushes, their errors), image observations, and determinism
//! across threads and shared scenes; split from `tests/tasks.rs` (the helpers are in
//! `tests/common/tasks.rs`).

mod common;

use bevy_ecs::entity::Entity;
use common::tasks::*;
use modesuite::engine::scene::SceneSource;
use modesuite::engine::{Env, RigidContext, Space};
use modesuite::tasks::TaskState;

#[test]
fn friction_randomisation_stays_in_range_and_follows_the_seed() {
    let text = place_text(
        r#"events: {"robot_start""#,
        r#"events: {"table_friction": Friction(object: "table", range: (0.3, 0.9)), "robot_start""#,
    );
    let mut env = Env::new(place_app(&text));
    let friction = |env: &mut Env| {
        use modesuite::engine::components::Object;
        use modesuite::engine::rigid::RigidRef;
        let mut q = env.app.world.query::<(&Object, &RigidRef)>();
        let h = q
            .iter(&env.app.world)
            .find(|(o, _)| o.name == "table")
            .unwrap()
            .1
             .0;
        let ctx = env.app.world.resource::<RigidContext>();
        let c = ctx.bodies.get(h).unwrap().colliders()[0];
        ctx.colliders.get(c).unwrap().friction()
    };
    let mut seen = Vec::new();
    for seed in 0..6 {
        env.reset(Some(seed));
        let f = friction(&mut env);
        assert!((0.3..=0.9).contains(&f), "{f}");
        seen.push(f);
    }
    println!("table friction per seed: {seen:?}");
    env.reset(Some(2));
    assert_eq!(friction(&mut env), seen[2]);
    assert!(seen.windows(2).all(|w| w[0] != w[1]));
    let e = scene_error(&place_text(
        r#"events: {"robot_start""#,
        r#"events: {"f": Friction(object: "table", range: (0.9, 0.3)), "robot_start""#,
    ));
    assert!(e.contains(r#"events["f"].range"#), "{e}");
}

#[test]
fn material_randomisation_stays_in_range_follows_the_seed_and_changes_the_sag() {
    let with = |range: &str| {
        place_text(
            r#"events: {"robot_start""#,
            &format!(
                r#"events: {{"rod_material": Material(object: "rod", youngs_modulus: {range}), "robot_start""#
            ),
        )
    };
    let modulus = |env: &mut Env| {
        use modesuite::engine::components::Object;
        let mut q = env.app.world.query::<(Entity, &Object)>();
        let e = q
            .iter(&env.app.world)
            .find(|(_, o)| o.name == "rod")
            .unwrap()
            .0;
        env.app
            .world
            .resource::<modesuite::fem::FemContext>()
            .get(e)
            .unwrap()
            .youngs_modulus()
    };
    let mut env = Env::new(place_app(&with("(5e5, 2e6)")));
    let mut seen = Vec::new();
    for seed in 0..6 {
        env.reset(Some(seed));
        let e = modulus(&mut env);
        assert!((5e5..=2e6).contains(&e), "{e}");
        seen.push(e);
    }
    println!("rod Young's modulus per seed (Pa): {seen:?}");
    env.reset(Some(2));
    assert_eq!(modulus(&mut env), seen[2]);
    assert!(seen.windows(2).all(|w| w[0] != w[1]));
    // The rod is held at one end: the softer rod's free end hangs lower after 1 s.
    let mut ends = Vec::new();
    for range in ["(2e5, 2e5)", "(4e6, 4e6)"] {
        let mut env = Env::new(place_app(&with(range)));
        env.reset(Some(0));
        for _ in 0..60 {
            let o = env.step(&[0.0; 9]);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
        }
        ends.push(point(&env, "rod_end").z);
    }
    println!(
        "rod end after 1 s: z {:.4} m at E = 2e5 Pa, {:.4} m at E = 4e6 Pa (softer hangs lower)",
        ends[0], ends[1]
    );
    assert!(ends[0] < ends[1] - 0.01, "{ends:?}");
    // Errors: a bad range at compile time, a rigid object at reset.
    let e = scene_error(&with("(2e6, 5e5)"));
    assert!(
        e.contains(r#"events["rod_material"].youngs_modulus"#),
        "{e}"
    );
    let text = place_text(
        r#"events: {"robot_start""#,
        r#"events: {"m": Material(object: "table", youngs_modulus: (1e5, 2e5)), "robot_start""#,
    );
    let mut env = Env::new(place_app(&text));
    let (_, info) = env.reset(Some(0));
    let e = info
        .error
        .expect("a rigid object has no Young's modulus to set");
    println!("{e}");
    assert!(e.contains("table") && e.contains("fem.solid"), "{e}");
}

#[test]
fn spot_start_randomisation_moves_the_floating_base_within_range() {
    let mut env = make("MoDe-Spot-Curtain-v0", None);
    let mut starts = Vec::new();
    for seed in 0..6u64 {
        env.reset(Some(seed));
        let b = base(&env);
        let (_, _, yaw) = b.rotation.euler_angles();
        assert!(b.translation.x.abs() <= 0.1 + 1e-6 && b.translation.y.abs() <= 0.1 + 1e-6);
        assert!(yaw.abs() <= 0.1 + 1e-6);
        starts.push((b.translation.x, b.translation.y, yaw));
    }
    println!("Spot starts (x, y, yaw): {starts:?}");
    env.reset(Some(3));
    let b = base(&env);
    assert_eq!(
        (b.translation.x, b.translation.y),
        (starts[3].0, starts[3].1)
    );
    assert!(
        starts.windows(2).all(|w| w[0] != w[1]),
        "every seed its own start"
    );
}

/// The friction coefficient of a rigid object's first collider.
fn friction(env: &Env, object: &str) -> f32 {
    use modesuite::engine::components::Object;
    use modesuite::engine::rigid::RigidRef;
    let world = &env.app.world;
    let rigid = world.resource::<RigidContext>();
    let body = world
        .iter_entities()
        .find(|e| e.get::<Object>().is_some_and(|o| o.name == object))
        .and_then(|e| e.get::<RigidRef>().map(|r| r.0))
        .unwrap();
    let c = rigid.bodies.get(body).unwrap().colliders()[0];
    rigid.colliders.get(c).unwrap().friction()
}

/// The Place scene with a free box on the floor and `events` before the robot's start event.
fn place_with_events(events: &str) -> String {
    let text = place_text(
        r#"events: {"robot_start""#,
        &format!(r#"events: {{{events} "robot_start""#),
    );
    text.replace(
        r#"        (
            name: "rod","#,
        r#"        (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (3.0, -2.0, 0.1)), body: Dynamic()),
        (
            name: "rod","#,
    )
}

#[test]
fn startup_events_hold_for_the_env_and_interval_events_run_on_time() {
    let text = place_with_events(
        r#""floor": Startup(Friction(object: "table", range: (0.1, 0.9))),
           "gust": Interval(every: (0.5, 0.5), event: Push(object: "box", velocity: (1.0, 1.0, 0.0))),"#,
    );
    // Startup: drawn at the env's first reset, the same after every later reset.
    let mut env = Env::new(place_app(&text));
    let mut seen = Vec::new();
    for seed in [0, 1, 5, 0] {
        env.reset(Some(seed));
        seen.push(friction(&env, "table"));
    }
    println!("table friction after resets with seeds 0, 1, 5, 0 of one env: {seen:?}");
    assert!((0.1..=0.9).contains(&seen[0]), "{seen:?}");
    assert!(seen.iter().all(|f| *f == seen[0]), "{seen:?}");
    let first = |seed: u64| {
        let mut env = Env::new(place_app(&text));
        env.reset(Some(seed));
        friction(&env, "table")
    };
    // A robot link by its `robot/link` name (checked when the event runs).
    let link_text = place_with_events(
        r#""grip": Friction(object: "robot/panda_leftfinger", range: (1.5, 1.5)), "bad": Friction(object: "robot/nope", range: (0.5, 0.5)),"#,
    );
    let mut env = Env::new(place_app(&link_text));
    let (_, info) = env.reset(Some(0));
    assert_eq!(friction(&env, "robot/panda_leftfinger"), 1.5);
    let e = info.error.expect("an unknown link is refused at reset");
    println!("{e}");
    assert!(
        e.contains("robot/nope") && e.contains("not a rigid body"),
        "{e}"
    );
    let (f0, f1) = (first(0), first(1));
    println!("a fresh env's table friction: first reset seed 0: {f0}, seed 1: {f1}");
    assert_eq!(f0, seen[0], "a function of the first reset's seed");
    assert_ne!(f0, f1, "every env its own draw");
    // Interval: every 0.5 s of episode time (30 steps at 60 Hz), before that step's physics.
    let box_speed = |env: &Env| {
        use modesuite::engine::components::Velocity;
        let world = &env.app.world;
        world
            .iter_entities()
            .find(|e| {
                e.get::<modesuite::engine::components::Object>()
                    .is_some_and(|o| o.name == "box")
            })
            .and_then(|e| e.get::<Velocity>().map(|v| v.linear.xy().norm()))
            .unwrap()
    };
    let next = |env: &Env| env.app.world.resource::<TaskState>().next_event.clone();
    let run = |seed: u64| {
        let mut env = Env::new(place_app(&text));
        env.reset(Some(seed));
        assert_eq!(next(&env), vec![0.5]);
        let mut speeds = Vec::new();
        for _ in 0..31 {
            let o = env.step(&[0.0; 9]);
            assert!(o.info.error.is_none(), "{:?}", o.info.error);
            speeds.push(box_speed(&env));
        }
        (speeds, next(&env), env.state_hash())
    };
    let (speeds, after, hash) = run(3);
    println!(
        "box speed after steps 29, 30, 31: {:.4} {:.4} {:.4} m/s; next run at {after:?} s",
        speeds[28], speeds[29], speeds[30]
    );
    assert!(speeds[..30].iter().all(|v| *v < 1e-3), "{speeds:?}");
    assert!(speeds[30] > 0.05, "pushed on step 31: {}", speeds[30]);
    assert_eq!(after, vec![1.0]);
    let (speeds2, _, hash2) = run(3);
    assert_eq!((speeds2, hash2), (speeds, hash), "deterministic per seed");
}

#[test]
fn push_moves_a_cloth_and_refuses_a_static_body() {
    let text = task_text(
        "uncover",
        r#""cover_start": ObjectOffset(object: "cover", xy: 0.05),"#,
        r#""cover_start": ObjectOffset(object: "cover", xy: 0.05), "gust": Push(object: "cover", velocity: (0.0, 0.0, 0.5)),"#,
    );
    let mut env = Env::new(task_app("uncover", &text));
    let (_, info) = env.reset(Some(4));
    assert!(info.error.is_none(), "{:?}", info.error);
    use modesuite::engine::components::Object;
    let e = env
        .app
        .world
        .iter_entities()
        .find(|e| e.get::<Object>().is_some_and(|o| o.name == "cover"))
        .unwrap()
        .id();
    let cloth = env
        .app
        .world
        .resource::<modesuite::pbd::PbdContext>()
        .get(e)
        .unwrap();
    let v = cloth.velocities();
    println!("cover velocity after the push: {:?}", v[0]);
    assert!(v[0].z.abs() > 0.0 && v[0].z.abs() <= 0.5 && v[0].xy().norm() == 0.0);
    assert!(v.iter().all(|w| *w == v[0]), "one push for every particle");
    let text = task_text(
        "uncover",
        r#""cover_start": ObjectOffset(object: "cover", xy: 0.05),"#,
        r#""p": Push(object: "table", velocity: (0.1, 0.1, 0.1)),"#,
    );
    let mut env = Env::new(task_app("uncover", &text));
    let e = env
        .reset(Some(0))
        .1
        .error
        .expect("a static body is refused");
    println!("{e}");
    assert!(
        e.contains("\"p\"") && e.contains("not a free dynamic body"),
        "{e}"
    );
}

#[test]
fn startup_and_interval_errors_name_the_event() {
    for (events, path, what) in [
        (
            r#""g": Interval(every: (0.0, 1.0), event: Push(object: "rod", velocity: (1.0, 0.0, 0.0))),"#,
            r#"events["g"].every"#,
            "0 < shortest",
        ),
        (
            r#""g": Interval(every: (1.0, 2.0), event: ObjectOffset(object: "rod", xy: 0.1)),"#,
            r#"events["g"].event"#,
            "teleport",
        ),
        (
            r#""g": Startup(Interval(every: (1.0, 2.0), event: Push(object: "rod", velocity: (1.0, 0.0, 0.0)))),"#,
            r#"events["g"].0"#,
            "do not nest",
        ),
        (
            r#""g": Interval(every: (1.0, 2.0), event: Push(object: "rod", velocity: (-1.0, 0.0, 0.0))),"#,
            r#"events["g"].event.velocity"#,
            ">= 0",
        ),
        (
            r#""g": Startup(Friction(object: "nope", range: (0.1, 0.2))),"#,
            r#"events["g"].0.object"#,
            "nope",
        ),
    ] {
        let e = scene_error(&place_with_events(events));
        println!("{e}");
        assert!(e.contains(path) && e.contains(what), "{e}");
    }
}

#[test]
fn rgbd_observation_of_the_robot_camera_follows_the_state_terms() {
    for id in [PLACE, "MoDe-Spot-Uncover-v0"] {
        let state_dim = make(id, None).spaces().observation.flat_dim();
        let (mut desc, source) = load(id, None);
        modesuite::make::override_rgbd(&mut desc, "robot").unwrap();
        let mut app = modesuite::make::default_app();
        let model = app
            .compile_scene(&desc, &source)
            .unwrap_or_else(|e| panic!("{e}"));
        modesuite::make::spawn_with_cameras(&mut app, model).unwrap_or_else(|e| panic!("{e}"));
        let mut env = Env::new(app);
        let space = env.spaces().observation.clone();
        let Space::Dict(items) = &space else {
            panic!("{space:?}")
        };
        let names: Vec<&str> = items.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["state", "robot_rgbd"]);
        assert_eq!(items[0].1.flat_dim(), state_dim);
        let Space::Box { shape, .. } = &items[1].1 else {
            panic!()
        };
        assert_eq!(shape, &vec![128, 128, 4]);
        let (obs, info) = env.reset(Some(0));
        assert!(info.error.is_none(), "{:?}", info.error);
        assert_eq!(obs.len(), state_dim + 128 * 128 * 4);
        let image = &obs[state_dim..];
        let rgb_ok = image
            .chunks_exact(4)
            .all(|p| p[..3].iter().all(|c| (0.0..=1.0).contains(c)));
        let depths: Vec<f32> = image.chunks_exact(4).map(|p| p[3]).collect();
        let hit = depths.iter().filter(|d| **d > 0.0).count();
        let (near, far) = depths
            .iter()
            .filter(|d| **d > 0.0)
            .fold((f32::MAX, 0.0f32), |(a, b), d| (a.min(*d), b.max(*d)));
        let mean_rgb = image
            .chunks_exact(4)
            .map(|p| p[0] + p[1] + p[2])
            .sum::<f32>()
            / (3.0 * 128.0 * 128.0);
        println!(
            "{id}: robot camera 128x128 RGB-D, {hit} of 16384 pixels hit, depth {near:.2}..{far:.2} m, mean RGB {mean_rgb:.3}"
        );
        assert!(rgb_ok);
        // The camera looks down at the floor and the task's furniture ahead of the robot.
        assert!(hit > 8000, "{hit}");
        assert!(
            near > 0.05 && far < 20.0 && far - near > 0.3,
            "{near} {far}"
        );
        // The state part is the state observation of the plain env at the same seed.
        let mut plain = make(id, None);
        let (plain_obs, _) = plain.reset(Some(0));
        assert_eq!(&obs[..state_dim], &plain_obs[..]);
        let o = env.step(&vec![0.0; env.spaces().action.flat_dim()]);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
        assert_eq!(o.observation.len(), obs.len());
    }
    // Error: a camera the scene does not have.
    let (mut desc, source) = load(PLACE, None);
    modesuite::make::override_rgbd(&mut desc, "nope").unwrap();
    let app = modesuite::make::default_app();
    let e = match app.compile_scene(&desc, &source) {
        Ok(_) => panic!("an unknown camera is refused"),
        Err(e) => e.to_string(),
    };
    println!("{e}");
    assert!(
        e.contains("camera_observation") && e.contains("\"nope\"") && e.contains("robot"),
        "{e}"
    );
}

#[test]
fn image_observations_stack_their_history_item_by_item() {
    // Two frames of (base xy, the robot camera's depth): a `Dict` of `state` (2, 2) and
    // `robot_depth` (2, 128, 128, 1), each item's frames oldest first (Gymnasium's frame
    // stacking); a reset repeats its first frame, each step shifts the frames by one.
    let text = place_text(
        r#"events: {"robot_start""#,
        r#"observations: {"policy": (terms: [(term: "base_xy"), (term: "camera", params: (camera: "robot", channels: Depth))], history: 2)}, events: {"robot_start""#,
    );
    let desc = modesuite::engine::scene::parse_str(&text, "<test>").unwrap();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/place");
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(dir))
        .unwrap_or_else(|e| panic!("{e}"));
    modesuite::make::spawn_with_cameras(&mut app, model).unwrap_or_else(|e| panic!("{e}"));
    let mut env = Env::new(app);
    let Space::Dict(items) = env.spaces().observation.clone() else {
        panic!("{:?}", env.spaces().observation)
    };
    let shapes: Vec<(&str, Vec<usize>)> = items
        .iter()
        .map(|(n, s)| match s {
            Space::Box { shape, .. } => (n.as_str(), shape.clone()),
            other => panic!("{other:?}"),
        })
        .collect();
    println!("{shapes:?}");
    assert_eq!(
        shapes,
        [("state", vec![2, 2]), ("robot_depth", vec![2, 128, 128, 1])]
    );
    let n = 128 * 128;
    let (mut prev, info) = env.reset(Some(0));
    assert!(info.error.is_none(), "{:?}", info.error);
    assert_eq!(prev.len(), 2 * 2 + 2 * n);
    assert_eq!(prev[0..2], prev[2..4], "a reset repeats its first frame");
    assert_eq!(prev[4..4 + n], prev[4 + n..]);
    let mut action = vec![0.0f32; env.spaces().action.flat_dim()];
    action[0] = 0.5;
    for _ in 0..5 {
        let o = env.step(&action);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
        let obs = o.observation;
        // the older frame of each item is the newer one of the step before
        assert_eq!(obs[0..2], prev[2..4]);
        assert_eq!(obs[4..4 + n], prev[4 + n..]);
        prev = obs;
    }
    println!("base xy: older {:?}, newer {:?}", &prev[0..2], &prev[2..4]);
    assert_ne!(prev[0..2], prev[2..4], "the base moved between the frames");
}

#[test]
fn envs_sharing_one_compiled_scene_step_as_separately_built_ones() {
    // `envs_for_target` compiles the scene once for all its envs (a `VecEnv`'s, the bench's):
    // each must still be its own world, bit-identical to an env built alone.
    for id in [PLACE, "MoDe-Spot-Uncover-v0"] {
        let mut shared = modesuite::make::envs_for_target(id, None, 3).unwrap();
        let mut alone = modesuite::make::env_for_target(id, None).unwrap();
        for (seed, e) in shared.iter_mut().enumerate() {
            e.reset(Some(seed as u64));
        }
        alone.reset(Some(2));
        let mut action = vec![0.0f32; alone.spaces().action.flat_dim()];
        action[0] = 0.5;
        for _ in 0..30 {
            for e in &mut shared {
                assert!(e.step(&action).info.error.is_none());
            }
            assert!(alone.step(&action).info.error.is_none());
        }
        let hashes: Vec<u64> = shared.iter().map(|e| e.state_hash()).collect();
        println!(
            "{id}: shared envs (seeds 0, 1, 2) {hashes:x?}, alone (seed 2) {:x}",
            alone.state_hash()
        );
        assert_eq!(hashes[2], alone.state_hash());
        assert_ne!(hashes[0], hashes[2]);
        assert_ne!(hashes[0], hashes[1]);
    }
}

#[test]
fn task_envs_are_bit_identical_on_one_or_two_threads_and_alone() {
    // The determinism promise for the benchmark itself, every environment: a `VecEnv` of task
    // envs gives the same bits on one thread and on two, and its env 2 the bits of an env run
    // alone with env 2's seed and actions (FEM contact-factor caches, cloth, walking Spot),
    // under changing actions.
    // step `s`'s actions; `first` is the index of `a[0]` among the batch's values
    let actions = |a: &mut [f32], first: usize, s: usize| {
        for (k, x) in a.iter_mut().enumerate() {
            *x = 0.5 * ((s as f32) * 0.1 + (first + k) as f32).sin();
        }
    };
    for id in modesuite::tasks::IMPLEMENTED {
        let run = |threads: usize| -> Vec<u64> {
            let envs = modesuite::make::envs_for_target(id, None, 3).unwrap();
            let mut v = modesuite::engine::VecEnv::new(envs, threads).unwrap();
            v.reset(Some(10));
            let dim = v.envs()[0].spaces().action.flat_dim();
            let mut a = vec![0.0f32; 3 * dim];
            for s in 0..25 {
                actions(&mut a, 0, s);
                let out = v.step(&a).unwrap();
                assert!(out.infos.iter().all(|i| i.error.is_none()), "{id}");
            }
            v.state_hashes()
        };
        let (one, two) = (run(1), run(2));
        let mut alone = modesuite::make::env_for_target(id, None).unwrap();
        alone.reset(Some(12));
        let dim = alone.spaces().action.flat_dim();
        let mut a = vec![0.0f32; dim];
        for s in 0..25 {
            actions(&mut a, 2 * dim, s);
            alone.step(&a);
        }
        println!(
            "{id}: 1 thread {one:x?}, 2 threads {two:x?}, alone (seed 12) {:x}",
            alone.state_hash()
        );
        assert_eq!(one, two, "{id}: 1 vs 2 threads");
        assert_eq!(one[2], alone.state_hash(), "{id}: env 2 vs alone");
        assert_ne!(one[0], one[1], "{id}: envs differ");
    }
}
