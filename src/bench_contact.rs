//! The `modesuite bench contact` suite: the contact validation scenes of `scenes/examples/` (issue
//! 30) and the peer harness's contact scenes K (`../shared/bench/peers/peer_mujoco_contact.py`:
//! a soft block 0.3 x 0.3 x 0.1 m, E 5e5 Pa, nu 0.4, rho 300, on the ground, with a 0.5 kg box, a
//! second block or a cloth dropped on it), each stepped 10 s (600 steps of 1/60 s, times
//! `--scale`) from reset with zero actions, one env, one thread.
//!
//! Extra JSON keys: `steps` run, `deepest_mm` (the deepest node of a deformable inside another
//! deformable's closed surface at the end), `max_speed` (the fastest deformable node over the
//! last step, m/s), and for the K scenes with a box, `box_z` (its centre's height, m).

use std::collections::BTreeMap;
use std::time::Instant;

use modesuite_engine::bench::{BenchOptions, BenchRecord};
use modesuite_engine::components::{DeformableNodes, Object, Pose};
use modesuite_engine::contact::{ContactSurface, SurfaceProbe};
use modesuite_engine::Env;
use nalgebra::Vector3;
use serde_json::json;

/// The block of the K scenes: 6 x 6 x 2 hexes of ten-node tets (845 nodes, the node count of
/// the peer's 12 x 12 x 4 linear grid).
const K_BLOCK: &str = r#"(
            name: "block",
            shape: Box(size: (0.3, 0.3, 0.1), divisions: (6, 6, 2)),
            pose: (pos: (0.0, 0.0, 0.05)),
            body: Kind(kind: "fem.solid", params: (youngs_modulus: 5e5, poisson_ratio: 0.4, density: 300.0, rayleigh_mass: 1.0)),
        )"#;

fn k_scene(extra: &str) -> String {
    format!(
        r#"Scene(
    physics: (dt: 0.016666666666666666, substeps: 1),
    objects: [
        (name: "ground", shape: Plane(size: (4.0, 4.0)), body: Static),
        {K_BLOCK},
        {extra}
    ],
)"#
    )
}

fn cases() -> Vec<(&'static str, String)> {
    let example = |text: &str| text.to_string();
    vec![
        (
            "tori_stacked",
            example(include_str!("../scenes/examples/tori_stacked.scene.ron")),
        ),
        (
            "cloth_over_torus",
            example(include_str!(
                "../scenes/examples/cloth_over_torus.scene.ron"
            )),
        ),
        (
            "cloths_falling",
            example(include_str!("../scenes/examples/cloths_falling.scene.ron")),
        ),
        (
            "box_on_foam",
            example(include_str!("../scenes/examples/box_on_foam.scene.ron")),
        ),
        (
            "medium_box_on_foam",
            example(include_str!(
                "../scenes/examples/medium_box_on_foam.scene.ron"
            )),
        ),
        (
            "box_on_torus",
            example(include_str!("../scenes/examples/box_on_torus.scene.ron")),
        ),
        (
            "box_across_belt",
            example(include_str!("../scenes/examples/box_across_belt.scene.ron")),
        ),
        (
            "heavy_box_across_belt",
            example(include_str!(
                "../scenes/examples/heavy_box_across_belt.scene.ron"
            )),
        ),
        (
            // the box (0.5 kg) is lighter than the block (2.7 kg): the rigid solver resolves it
            "K_box_on_block",
            k_scene(
                r#"(name: "box", shape: Box(size: (0.1, 0.1, 0.1)), pose: (pos: (0.0, 0.0, 0.35)), body: Dynamic(mass: 0.5)),"#,
            ),
        ),
        (
            "K_blocks",
            k_scene(
                &K_BLOCK
                    .replace("\"block\"", "\"upper\"")
                    .replace("pos: (0.0, 0.0, 0.05)", "pos: (0.0, 0.0, 0.2)"),
            ),
        ),
        (
            "K_cloth_on_block",
            k_scene(
                r#"(name: "cloth", shape: Grid(size: (0.6, 0.6), resolution: (21, 21)), pose: (pos: (0.0, 0.0, 0.25)),
            body: Kind(kind: "pbd.cloth", params: (areal_density: 0.19444))),"#,
            ),
        ),
    ]
}

/// A deformable's name, nodes and closed surface (if its surface closes).
type Deformable = (String, Vec<Vector3<f64>>, Option<Vec<[u32; 3]>>);

/// Every deformable of the env.
fn deformables(env: &mut Env) -> Vec<Deformable> {
    let mut q = env
        .app
        .world
        .query::<(&Object, &DeformableNodes, Option<&ContactSurface>)>();
    q.iter(&env.app.world)
        .map(|(o, n, s)| {
            let closed = s.filter(|s| s.closed).map(|s| s.triangles.to_vec());
            (o.name.clone(), n.0.clone(), closed)
        })
        .collect()
}

/// The contact suite (see the module).
pub fn contact_cases(opts: &BenchOptions) -> Result<Vec<BenchRecord>, String> {
    let mut out = Vec::new();
    for (case, text) in cases() {
        let mut env = crate::make::env_from_text(&text).map_err(|e| format!("{case}: {e}"))?;
        env.autoreset = false;
        env.reset(Some(0));
        let n = ((600.0 * opts.scale) as usize).max(2);
        let t = Instant::now();
        for i in 0..n - 1 {
            if let Some(e) = env.step(&[]).info.error {
                return Err(format!("{case}: step {i}: {e}"));
            }
        }
        let before = deformables(&mut env);
        if let Some(e) = env.step(&[]).info.error {
            return Err(format!("{case}: last step: {e}"));
        }
        let steps_per_s = n as f64 / t.elapsed().as_secs_f64();
        let after = deformables(&mut env);
        let dt = env.app.world.resource::<modesuite_engine::SimSettings>().dt;
        let max_speed = before
            .iter()
            .zip(&after)
            .flat_map(|(a, b)| a.1.iter().zip(&b.1).map(|(p, q)| (q - p).norm() / dt))
            .fold(0.0, f64::max);
        let mut deepest: f64 = 0.0;
        for (name, nodes, surface) in &after {
            let Some(tris) = surface else { continue };
            let probe = SurfaceProbe::new(nodes, tris);
            for (_, pts, _) in after.iter().filter(|d| &d.0 != name) {
                for p in pts {
                    if let Some(d) = probe.distance(p) {
                        deepest = deepest.max(-d);
                    }
                }
            }
        }
        let mut extra = BTreeMap::new();
        extra.insert("steps".into(), json!(n));
        extra.insert("deepest_mm".into(), json!(deepest * 1e3));
        extra.insert("max_speed".into(), json!(max_speed));
        let mut q = env.app.world.query::<(&Object, &Pose)>();
        if let Some((_, p)) = q.iter(&env.app.world).find(|(o, _)| o.name == "box") {
            extra.insert("box_z".into(), json!(p.0.translation.z));
        }
        out.push(BenchRecord::new(case, steps_per_s, 1, 1, extra));
    }
    Ok(out)
}
