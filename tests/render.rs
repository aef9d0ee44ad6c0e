//! Render plugin tests on whatever adapter the machine has (CI: Mesa's lavapipe, installed by
//! scripts/setup.sh). Without an adapter they fail with the message naming the package.

mod common;

use modesuite::engine::scene;
use modesuite::prelude::*;
use modesuite::render::config::project;
use modesuite::render::{
    render_batch, CameraDesc, CameraFrame, CameraImages, CameraRequests, EnvRenderer, RenderConfig,
    RenderDevice,
};
use nalgebra::{Isometry3, Point3, Translation3, Vector3};

fn device() -> std::sync::Arc<RenderDevice> {
    RenderDevice::shared().unwrap_or_else(|e| panic!("no render adapter: {e}"))
}

/// An env and its renderer from scene text (cameras from `cameras`, RON list).
fn setup(objects: &str, cameras: &str) -> (Env, EnvRenderer) {
    let text = format!(
        "Scene(physics: (dt: 0.016666666666666666, substeps: 2), objects: [{objects}], frames: {{\"goal\": (pos: (0.3, 0.0, 0.3))}}, extensions: {{\"render\": (cameras: [{cameras}])}})"
    );
    let desc = scene::parse_str(&text, "<test>").unwrap_or_else(|e| panic!("{e}"));
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &SceneSource::in_memory(common::root()))
        .unwrap_or_else(|e| panic!("{e}"));
    app.spawn_scene(model.clone())
        .unwrap_or_else(|e| panic!("{e}"));
    device();
    let r = EnvRenderer::for_scene(model).unwrap_or_else(|e| panic!("{e}"));
    let mut env = Env::new(app);
    env.reset(Some(0));
    (env, r)
}

fn render(r: &mut EnvRenderer, env: &Env, name: &str) -> CameraFrame {
    r.render(&env.app.world, &[name])
        .unwrap_or_else(|e| panic!("{e}"))
        .remove(0)
}

/// Depth of the plane z = 0 seen through pixel (u, v), along the optical axis.
fn plane_depth(f: &CameraFrame, u: f64, v: f64) -> Option<f64> {
    let (fx, fy, cx, cy) = f.pinhole;
    let d_cam = Vector3::new((u - cx) / fx, (v - cy) / fy, 1.0);
    let d = f.world_from_camera.rotation * d_cam;
    let o = f.world_from_camera.translation.vector;
    let t = -o.z / d.z;
    (t > 0.0).then_some(t)
}

#[test]
fn plane_depth_at_known_distance_is_within_a_millimetre() {
    let ground = r#"(name: "ground", shape: Plane(size: (40.0, 40.0)), body: Static)"#;
    let cams = r#"(name: "down", width: 96, height: 64, intrinsics: Fov(70.0), pose: (pos: (0.2, -0.1, 1.5)), look_at: (0.2, -0.1, 0.0)),
                  (name: "tilted", width: 80, height: 60, intrinsics: Pinhole(fx: 60.0, fy: 62.0, cx: 41.0, cy: 28.0), pose: (pos: (0.0, -2.0, 1.2)), look_at: (0.0, 0.0, 0.0))"#;
    let (env, mut r) = setup(ground, cams);
    for name in ["down", "tilted"] {
        let f = render(&mut r, &env, name);
        let mut worst: f64 = 0.0;
        let mut hits = 0;
        for v in 0..f.height {
            for u in 0..f.width {
                let i = (v * f.width + u) as usize;
                let expected = plane_depth(&f, u as f64, v as f64);
                match expected {
                    Some(e) if e < 90.0 => {
                        hits += 1;
                        assert_eq!(
                            f.segmentation[i], 1,
                            "{name}: pixel ({u}, {v}) is the ground"
                        );
                        worst = worst.max((f.depth[i] as f64 - e).abs());
                    }
                    _ => {}
                }
            }
        }
        println!(
            "{name}: {hits} ground pixels, worst depth error {:.3} mm (tolerance 1 mm); centre depth {:.4} m",
            worst * 1e3,
            f.depth[(f.height / 2 * f.width + f.width / 2) as usize]
        );
        assert!(hits > 1000, "{name}: only {hits} ground pixels");
        assert!(worst < 1e-3, "{name}: depth error {worst} m");
    }
}

fn mask_bounds(f: &CameraFrame, id: u32) -> Option<(u32, u32, u32, u32, usize)> {
    let mut b: Option<(u32, u32, u32, u32, usize)> = None;
    for v in 0..f.height {
        for u in 0..f.width {
            if f.segmentation[(v * f.width + u) as usize] == id {
                b = Some(match b {
                    None => (u, v, u, v, 1),
                    Some((a, c, d, e, n)) => (a.min(u), c.min(v), d.max(u), e.max(v), n + 1),
                });
            }
        }
    }
    b
}

#[test]
fn a_box_footprint_matches_its_pinhole_projection() {
    let objects = r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
        (name: "box", shape: Box(size: (0.4, 0.3, 0.2)), pose: (pos: (0.1, 0.05, 0.1), rpy: (0.0, 0.0, 0.5)), body: Static)"#;
    let cams = r#"(name: "cam", width: 160, height: 120, intrinsics: Pinhole(fx: 150.0, fy: 150.0, cx: 79.5, cy: 59.5), pose: (pos: (1.0, -1.2, 1.1)), look_at: (0.1, 0.05, 0.1))"#;
    let (env, mut r) = setup(objects, cams);
    let f = render(&mut r, &env, "cam");
    let pose = Isometry3::from_parts(
        Translation3::new(0.1, 0.05, 0.1),
        modesuite::engine::math::rpy(0.0, 0.0, 0.5),
    );
    let (mut umin, mut vmin, mut umax, mut vmax) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let p = pose * Point3::new(0.2 * sx, 0.15 * sy, 0.1 * sz);
                let (u, v, _) =
                    project(&f.world_from_camera, f.pinhole, &p.coords).expect("in front");
                umin = umin.min(u);
                umax = umax.max(u);
                vmin = vmin.min(v);
                vmax = vmax.max(v);
            }
        }
    }
    let (a, b, c, d, n) = mask_bounds(&f, 2).expect("the box is visible");
    let err = [
        (a as f64 - umin).abs(),
        (b as f64 - vmin).abs(),
        (c as f64 - umax).abs(),
        (d as f64 - vmax).abs(),
    ];
    println!(
        "box mask u {a}..{c} v {b}..{d} ({n} px); projection u {umin:.2}..{umax:.2} v {vmin:.2}..{vmax:.2}; errors {err:.2?} px (tolerance 2)"
    );
    assert!(err.iter().all(|e| *e <= 2.0), "footprint errors {err:?} px");
    // The depth of the box's pixels lies between its nearest and farthest corner.
    let depths: Vec<f32> = f
        .segmentation
        .iter()
        .zip(&f.depth)
        .filter(|(s, _)| **s == 2)
        .map(|(_, d)| *d)
        .collect();
    let lo = depths.iter().cloned().fold(f32::MAX, f32::min);
    let hi = depths.iter().cloned().fold(f32::MIN, f32::max);
    println!("box depth {lo:.3}..{hi:.3} m");
    assert!(lo > 1.0 && hi < 2.6, "box depths {lo}..{hi}");
}

#[test]
fn segmentation_ids_are_object_indices_plus_one() {
    let objects = r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
        (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (-0.3, 0.0, 0.1)), body: Static, color: (0.9, 0.1, 0.1)),
        (name: "ball", shape: Sphere(radius: 0.12), pose: (pos: (0.3, 0.0, 0.12)), body: Static, color: (0.1, 0.1, 0.9))"#;
    let cams = r#"(name: "cam", width: 128, height: 96, pose: (pos: (0.0, -1.5, 1.0)), look_at: (0.0, 0.0, 0.1))"#;
    let (env, mut r) = setup(objects, cams);
    let f = render(&mut r, &env, "cam");
    let mut ids: Vec<u32> = f.segmentation.clone();
    ids.sort_unstable();
    ids.dedup();
    println!("ids in the image: {ids:?} (objects ground = 1, box = 2, ball = 3; background 0)");
    assert_eq!(ids, vec![0, 1, 2, 3]);
    for (id, centre, colour) in [
        (2u32, Vector3::new(-0.3, 0.0, 0.1), 0usize),
        (3, Vector3::new(0.3, 0.0, 0.12), 2),
    ] {
        let (u, v, _) = project(&f.world_from_camera, f.pinhole, &centre).expect("in front");
        let i = (v.round() as u32 * f.width + u.round() as u32) as usize;
        let rgb = &f.rgb[3 * i..3 * i + 3];
        println!(
            "object {id} at pixel ({u:.1}, {v:.1}): id {} rgb {rgb:?}",
            f.segmentation[i]
        );
        assert_eq!(f.segmentation[i], id);
        // The object's own colour dominates its pixel.
        assert!(rgb[colour] > rgb[1] + 20, "colour {rgb:?}");
    }
}

fn stats(f: &CameraFrame, id: u32) -> (usize, f64) {
    let d: Vec<f64> = f
        .segmentation
        .iter()
        .zip(&f.depth)
        .filter(|(s, _)| **s == id)
        .map(|(_, d)| *d as f64)
        .collect();
    (d.len(), d.iter().sum::<f64>() / d.len().max(1) as f64)
}

#[test]
fn cloth_and_fem_bodies_render_and_move_between_frames() {
    let path = common::root().join("scenes/examples/tabletop_cameras.scene.ron");
    let (desc, source) = scene::load_file(&path).unwrap_or_else(|e| panic!("{e}"));
    let mut app = modesuite::make::default_app();
    let model = app
        .compile_scene(&desc, &source)
        .unwrap_or_else(|e| panic!("{e}"));
    app.spawn_scene(model.clone())
        .unwrap_or_else(|e| panic!("{e}"));
    device();
    let mut r = EnvRenderer::for_scene(model.clone()).unwrap_or_else(|e| panic!("{e}"));
    let mut env = Env::new(app);
    env.reset(Some(0));
    let id = |name: &str| model.objects.iter().position(|o| o.name == name).unwrap() as u32 + 1;
    let before = render(&mut r, &env, "overhead");
    for _ in 0..45 {
        let o = env.step(&[]);
        assert!(o.info.error.is_none(), "{:?}", o.info.error);
    }
    let after = render(&mut r, &env, "overhead");
    for name in ["towel", "rod"] {
        let (n0, d0) = stats(&before, id(name));
        let (n1, d1) = stats(&after, id(name));
        let changed = before
            .segmentation
            .iter()
            .zip(&after.segmentation)
            .filter(|(a, b)| (**a == id(name)) != (**b == id(name)))
            .count();
        println!(
            "{name}: {n0} px at mean depth {d0:.4} m -> {n1} px at {d1:.4} m; {changed} pixels changed membership"
        );
        assert!(n0 > 50 && n1 > 50, "{name} visible in both frames");
        // Both fall onto the table (further from the overhead camera).
        assert!(d1 - d0 > 0.02, "{name} depth {d0} -> {d1}");
    }
}

#[test]
fn rendering_does_not_change_the_simulation() {
    let path = common::root().join("scenes/examples/tabletop_cameras.scene.ron");
    let run = |render_every: Option<u64>| {
        let (desc, source) = scene::load_file(&path).unwrap_or_else(|e| panic!("{e}"));
        let mut app = modesuite::make::default_app();
        let model = app
            .compile_scene(&desc, &source)
            .unwrap_or_else(|e| panic!("{e}"));
        app.spawn_scene(model.clone())
            .unwrap_or_else(|e| panic!("{e}"));
        let mut env = Env::new(app);
        env.reset(Some(3));
        let mut r =
            render_every.map(|_| EnvRenderer::for_scene(model).unwrap_or_else(|e| panic!("{e}")));
        for i in 0..40 {
            env.step(&[]);
            if let (Some(r), Some(k)) = (r.as_mut(), render_every) {
                if i % k == 0 {
                    r.render(&env.app.world, &["overhead"])
                        .unwrap_or_else(|e| panic!("{e}"));
                }
            }
        }
        env.state_hash()
    };
    let plain = run(None);
    let rendered = run(Some(3));
    println!("state hash without rendering {plain:016x}, with {rendered:016x}");
    assert_eq!(plain, rendered);
}

#[test]
fn camera_requests_fill_camera_images_in_the_sense_pass() {
    let objects = r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
        (name: "ball", shape: Sphere(radius: 0.1), pose: (pos: (0.0, 0.0, 1.0)), body: Dynamic())"#;
    let cams = r#"(name: "chase", width: 32, height: 24, attach: "ball", pose: (pos: (0.0, -1.0, 0.3)), look_at: (0.0, 0.0, 0.0)),
                  (name: "fixed", width: 16, height: 16, pose: (pos: (0.0, 0.0, 3.0)), look_at: (0.0, 0.0, 0.0))"#;
    let (mut env, _) = setup(objects, cams);
    modesuite::render::prepare(&mut env.app).unwrap_or_else(|e| panic!("{e}"));
    env.step(&[]);
    assert!(
        env.app.world.resource::<CameraImages>().0.is_empty(),
        "nothing is rendered unless asked"
    );
    env.app
        .world
        .resource_mut::<CameraRequests>()
        .0
        .insert("chase".into());
    env.step(&[]);
    let z0 = env.app.world.resource::<CameraImages>().0["chase"]
        .world_from_camera
        .translation
        .z;
    for _ in 0..20 {
        env.step(&[]);
    }
    let images = env.app.world.resource::<CameraImages>().0.clone();
    let chase = &images["chase"];
    let z1 = chase.world_from_camera.translation.z;
    println!("attached camera height {z0:.4} -> {z1:.4} m (the ball falls)");
    assert_eq!(chase.rgb.len(), 32 * 24 * 3);
    assert!(z0 - z1 > 0.1, "the attached camera follows the ball");
    assert!(!images.contains_key("fixed"));
    // The ball fills the centre of its chase camera.
    let centre = chase.segmentation[(12 * 32 + 16) as usize];
    assert_eq!(centre, 2, "ball at the image centre");
    // A request for an unknown camera ends the episode with a message, not a panic.
    env.app
        .world
        .resource_mut::<CameraRequests>()
        .0
        .insert("nope".into());
    let o = env.step(&[]);
    let err = o.info.error.unwrap_or_default();
    println!("unknown camera: {err}");
    assert!(err.contains("nope") && err.contains("chase"), "{err}");
}

#[test]
fn batched_envs_share_one_device_and_match_single_renders() {
    let objects = r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
        (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (0.0, 0.0, 0.5)), body: Dynamic())"#;
    let cams = r#"(name: "cam", width: 48, height: 32, markers: true, pose: (pos: (1.0, -1.0, 1.0)), look_at: (0.0, 0.0, 0.2))"#;
    let (mut e1, mut r1) = setup(objects, cams);
    let (e2, mut r2) = setup(objects, cams);
    for _ in 0..10 {
        e1.step(&[]);
    }
    assert!(std::sync::Arc::ptr_eq(r1.device(), r2.device()));
    let cam = r1.scene_camera("cam").unwrap().clone();
    let single1 = r1
        .render_cameras(&e1.app.world, std::slice::from_ref(&cam))
        .unwrap();
    let single2 = r2
        .render_cameras(&e2.app.world, std::slice::from_ref(&cam))
        .unwrap();
    let batch = render_batch(
        &mut [(&mut r1, &e1.app.world), (&mut r2, &e2.app.world)],
        &[cam],
    )
    .unwrap();
    assert_eq!(batch[0][0], single1[0]);
    assert_eq!(batch[1][0], single2[0]);
    assert_ne!(
        batch[0][0].depth, batch[1][0].depth,
        "different worlds, different images"
    );
}

#[test]
fn markers_are_translucent_and_only_in_colour() {
    let objects = r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static)"#;
    let cams = r#"(name: "on", width: 64, height: 48, markers: true, pose: (pos: (0.3, -0.4, 0.45)), look_at: (0.3, 0.0, 0.3)),
                  (name: "off", width: 64, height: 48, pose: (pos: (0.3, -0.4, 0.45)), look_at: (0.3, 0.0, 0.3))"#;
    let (env, mut r) = setup(objects, cams);
    let on = render(&mut r, &env, "on");
    let off = render(&mut r, &env, "off");
    let changed = on
        .rgb
        .chunks(3)
        .zip(off.rgb.chunks(3))
        .filter(|(a, b)| a != b)
        .count();
    println!("marker changed {changed} pixels");
    assert!(changed > 20, "the goal marker is drawn");
    assert_eq!(on.depth, off.depth, "markers do not write depth");
    assert_eq!(on.segmentation, off.segmentation, "markers have no id");
    // Translucent: the background still shows through (not the pure marker green).
    let (u, v, _) = project(
        &on.world_from_camera,
        on.pinhole,
        &Vector3::new(0.3, 0.0, 0.3),
    )
    .unwrap();
    let i = 3 * (v.round() as usize * 64 + u.round() as usize);
    println!(
        "marker centre {:?} vs background {:?}",
        &on.rgb[i..i + 3],
        &off.rgb[i..i + 3]
    );
    assert_ne!(
        on.rgb[i..i + 3],
        off.rgb[i..i + 3],
        "the marker covers its centre"
    );
    assert!(on.rgb[i + 1] > on.rgb[i], "green tint");
    assert!(on.rgb[i + 2] > 40, "background shows through");
}

#[test]
fn scene_cameras_are_validated_with_located_errors() {
    let app = modesuite::make::default_app();
    let bad = r#"Scene(objects: [(name: "ground", shape: Plane(size: (1.0, 1.0)), body: Static)],
        extensions: {"render": (cameras: [(name: "c", width: 16, height: 16, attach: "nobody")])})"#;
    let desc = scene::parse_str(bad, "<test>").unwrap();
    // The render section is a registered scene section: compiling the scene already fails.
    let e = match app.compile_scene(&desc, &SceneSource::in_memory(".")) {
        Ok(_) => panic!("a camera attached to an unknown object compiled"),
        Err(e) => e.to_string(),
    };
    println!("{e}");
    assert!(
        e.contains("cameras[0].attach") && e.contains("ground"),
        "{e}"
    );
}

#[test]
fn frame_bytes_are_consistent() {
    let f = CameraFrame::default();
    assert!(f.rgb.is_empty() && f.depth.is_empty());
    let camera = r#"(name: "c", width: 33, height: 17, pose: (pos: (0.0, 0.0, 2.0)), look_at: (0.0, 0.0, 0.0))"#;
    let (env, mut r) = setup(
        r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static)"#,
        camera,
    );
    // An odd width exercises the padded readback rows.
    let f = render(&mut r, &env, "c");
    assert_eq!(f.rgb.len(), 33 * 17 * 3);
    assert_eq!(f.depth.len(), 33 * 17);
    assert_eq!(f.segmentation.len(), 33 * 17);
    let max_err = f
        .depth
        .iter()
        .map(|d| (d - 2.0).abs())
        .fold(0.0f32, f32::max);
    println!("odd-width frame: depth error {max_err:e} m");
    assert!(max_err < 1e-3);
    // The frame reports the camera it was taken with, which `CameraDesc::looking_at` makes in
    // code the same as the scene's text does.
    let made = CameraDesc::looking_at("c", 33, 17, 60.0, [0.0, 0.0, 2.0], [0.0; 3]);
    let parsed = RenderConfig::parse(&format!("(cameras: [{camera}])")).unwrap();
    assert_eq!(parsed.camera("c"), Some(&made));
    assert_eq!((f.width, f.height), (made.width, made.height));
    assert_eq!(f.pinhole, made.pinhole());
    let pose = made.parent_from_camera();
    assert!(
        (f.world_from_camera.to_homogeneous() - pose.to_homogeneous()).norm() < 1e-12,
        "{} vs {pose}",
        f.world_from_camera
    );
}

/// Pixels where `on` differs from `off` and has the hue of `rgb` (each channel relative to the
/// brightest within 0.35 of the marker colour's: shading and sRGB encoding shift it a little).
fn marker_pixels(on: &CameraFrame, off: &CameraFrame, rgb: [f32; 3]) -> usize {
    let share = |p: [f32; 3]| {
        let s = p.iter().copied().fold(1e-3, f32::max);
        p.map(|c| c / s)
    };
    let want = share(rgb);
    let changed: Vec<_> = on
        .rgb
        .chunks(3)
        .zip(off.rgb.chunks(3))
        .filter(|(a, b)| a != b)
        .map(|(a, _)| [a[0], a[1], a[2]].map(f32::from))
        .collect();
    println!(
        "{} pixels changed, e.g. {:?}",
        changed.len(),
        &changed[..changed.len().min(4)]
    );
    changed
        .iter()
        .filter(|p| {
            share(**p)
                .iter()
                .zip(want)
                .all(|(a, b)| (a - b).abs() < 0.35)
        })
        .count()
}

/// Markers of a deformable object by name.
fn deformable_markers(
    env: &mut Env,
    name: &str,
) -> modesuite::engine::deformable::DeformableMarkers {
    let mut q = env
        .app
        .world
        .query::<(&Object, &modesuite::engine::deformable::DeformableMarkers)>();
    q.iter(&env.app.world)
        .find(|(o, _)| o.name == name)
        .map(|(_, m)| m.clone())
        .unwrap()
}

#[test]
fn contact_markers_sit_where_bodies_touch() {
    use modesuite::render::geometry::CONTACT_MARKER_RGB;
    let objects = r#"(name: "ground", shape: Plane(size: (10.0, 10.0)), body: Static),
        (name: "box", shape: Box(size: (0.2, 0.2, 0.2)), pose: (pos: (0.0, 0.0, 0.15)), body: Dynamic())"#;
    let cams = r#"(name: "on", width: 96, height: 64, overlays: true, pose: (pos: (0.6, -0.6, 0.5)), look_at: (0.0, 0.0, 0.05)),
                  (name: "off", width: 96, height: 64, pose: (pos: (0.6, -0.6, 0.5)), look_at: (0.0, 0.0, 0.05))"#;
    let (mut env, mut r) = setup(objects, cams);
    let mut points = Vec::new();
    env.app
        .world
        .resource::<RigidContext>()
        .contact_points(2e-3, &mut points);
    assert!(
        points.is_empty(),
        "no contact while the box falls: {points:?}"
    );
    for _ in 0..60 {
        env.step(&[]);
    }
    env.app
        .world
        .resource::<RigidContext>()
        .contact_points(2e-3, &mut points);
    println!("resting box: {} contact points {points:?}", points.len());
    assert!(points.len() >= 4, "a resting box touches at its corners");
    for p in &points {
        // On the ground (within 2 mm) and under the box's 0.2 m footprint.
        assert!(p.z.abs() < 2e-3, "contact height {}", p.z);
        assert!(p.x.abs() < 0.101 && p.y.abs() < 0.101, "contact {p}");
    }
    let (on, off) = (render(&mut r, &env, "on"), render(&mut r, &env, "off"));
    let red = marker_pixels(&on, &off, CONTACT_MARKER_RGB);
    println!("contact marker pixels: {red}");
    assert!(red > 4, "contact markers drawn");
    assert_eq!(on.depth, off.depth, "markers do not write depth");
}

#[test]
fn deformables_publish_contact_nodes_and_grasp_markers_follow_the_gripper() {
    use modesuite::render::geometry::GRASP_MARKER_RGB;
    // Cloth and FEM rod fall onto the table: their touching nodes are published.
    let mut env = common::run_scene("scenes/examples/tabletop_cameras.scene.ron", 60);
    for name in ["towel", "rod"] {
        let m = deformable_markers(&mut env, name);
        let nodes = common::nodes(&mut env, name);
        let zmin = nodes.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        println!(
            "{name}: {} of {} nodes touch, {} grasped; lowest node z {zmin:.4}",
            m.contacts.len(),
            nodes.len(),
            m.grasped.len()
        );
        assert!(!m.contacts.is_empty(), "{name} rests on the table");
        assert!(m.grasped.is_empty(), "nothing holds the {name}");
        // Touching nodes are the low ones (within 2 cm of the lowest).
        for &i in &m.contacts {
            assert!(nodes[i as usize].z < zmin + 0.02, "{name} node {i}");
        }
    }
    // The Franka closes its gripper on the napkin at 3.5 s and lifts it.
    let mut env = common::run_scene("scenes/examples/franka_cloth_grasp.scene.ron", 300);
    let m = deformable_markers(&mut env, "napkin");
    let nodes = common::nodes(&mut env, "napkin");
    let held: Vec<_> = m.grasped.iter().map(|&i| nodes[i as usize]).collect();
    println!("napkin: {} grasped particles at {held:?}", held.len());
    assert!(!held.is_empty(), "the closed gripper holds particles");
    assert!(
        held.iter().all(|p| p.z > 0.55),
        "the held particles are lifted with the hand"
    );
    device();
    let model = env.app.scene().cloned().unwrap();
    let mut r = EnvRenderer::for_scene(model).unwrap_or_else(|e| panic!("{e}"));
    let mut on = r.orbit_camera(&env.app.world, "o", 320, 240, Default::default());
    on.markers = false;
    on.overlays = true;
    let mut off = on.clone();
    off.name = "o_off".into();
    off.overlays = false;
    let frames = r.render_cameras(&env.app.world, &[on, off]).unwrap();
    let yellow = marker_pixels(&frames[0], &frames[1], GRASP_MARKER_RGB);
    println!("grasp marker pixels: {yellow}");
    assert!(yellow >= 6, "grasp markers drawn");
}
