//! Diagnostics: follower end moment.
use modesuite_fem::testing::box_mesh;
use modesuite_fem::{FemConfig, FemSolid, Material, NoContacts};
use nalgebra::Vector3;
fn main() {
    let arg = |i: usize, d: f64| std::env::args().nth(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (l, h) = (0.5, 0.01);
    let cells = [arg(1, 40.0) as usize, 1, 1];
    let e = 1e9;
    let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(l, h, h), cells);
    let config = FemConfig { rayleigh_mass: arg(2, 20.0), quasi_newton: arg(3, 1.0) == 1.0, ..FemConfig::default() };
    let mut s = FemSolid::new(&nodes, &tets, Material::new(e, 0.3, 1000.0).unwrap(), config).unwrap();
    let clamp = s.rest_nodes_where(|p| p.x.abs() < 1e-12);
    s.fix_nodes(&clamp).unwrap();
    let face = s.rest_nodes_where(|p| (p.x - l).abs() < 1e-12);
    let zc = 0.5 * h;
    let top: Vec<u32> = face.iter().copied().filter(|&n| s.rest_positions()[n as usize].z > zc + 1e-12).collect();
    let bottom: Vec<u32> = face.iter().copied().filter(|&n| s.rest_positions()[n as usize].z < zc - 1e-12).collect();
    let mean = |s: &FemSolid, ns: &[u32]| ns.iter().map(|&n| s.positions()[n as usize]).sum::<Vector3<f64>>() / ns.len() as f64;
    // consistent nodal loads of the linear traction sigma = -zeta / I_face on the end face
    // (6-point degree-4 rule on each quadratic boundary triangle)
    let mesh = &s.model().mesh;
    let mut unit = vec![0.0f64; s.n_nodes()];
    let rule = [
        (0.223381589678011, [0.108103018168070, 0.445948490915965, 0.445948490915965]),
        (0.223381589678011, [0.445948490915965, 0.108103018168070, 0.445948490915965]),
        (0.223381589678011, [0.445948490915965, 0.445948490915965, 0.108103018168070]),
        (0.109951743655322, [0.816847572980459, 0.091576213509771, 0.091576213509771]),
        (0.109951743655322, [0.091576213509771, 0.816847572980459, 0.091576213509771]),
        (0.109951743655322, [0.091576213509771, 0.091576213509771, 0.816847572980459]),
    ];
    let i_face = h.powi(4) / 12.0;
    for f in &mesh.boundary_faces {
        let x = f.map(|c| mesh.rest[c as usize]);
        if x.iter().any(|p| (p.x - l).abs() > 1e-12) {
            continue;
        }
        let area = 0.5 * (x[1] - x[0]).cross(&(x[2] - x[0])).norm();
        let en = [mesh.edge_node(f[0], f[1]).unwrap(), mesh.edge_node(f[1], f[2]).unwrap(), mesh.edge_node(f[0], f[2]).unwrap()];
        for (w, lq) in rule {
            let z = lq[0] * x[0].z + lq[1] * x[1].z + lq[2] * x[2].z - zc;
            let sigma = -z / i_face;
            let nv = [
                lq[0] * (2.0 * lq[0] - 1.0),
                lq[1] * (2.0 * lq[1] - 1.0),
                lq[2] * (2.0 * lq[2] - 1.0),
                4.0 * lq[0] * lq[1],
                4.0 * lq[1] * lq[2],
                4.0 * lq[0] * lq[2],
            ];
            let nodes6 = [f[0], f[1], f[2], en[0], en[1], en[2]];
            for k in 0..6 {
                unit[nodes6[k] as usize] += w * area * nv[k] * sigma;
            }
        }
    }
    let mom: f64 = (0..s.n_nodes()).map(|n| unit[n] * (mesh.rest[n].z - zc)).sum();
    let net: f64 = unit.iter().sum();
    println!("unit traction: moment {mom:.6} (-1), net force {net:e}");
    let m_full = 2.0 * std::f64::consts::PI * e * h.powi(4) / 12.0 / l;
    let dt = 1.0 / arg(4, 240.0);
    let ramp = arg(5, 240.0) as usize;
    let mut theta = 0.0f64;
    let mut r = Vec::new();
    for k in 1..=ramp * 5 / 2 {
        let m = m_full * (k.min(ramp) as f64 / ramp as f64);
        let d = mean(&s, &top) - mean(&s, &bottom);
        let raw = (-d.x).atan2(d.z);
        theta = raw + 2.0 * std::f64::consts::PI * ((theta - raw) / (2.0 * std::f64::consts::PI)).round();
        let t = Vector3::new(theta.cos(), 0.0, theta.sin());
        let f: Vec<Vector3<f64>> = unit.iter().map(|u| t * (m * u)).collect();
        s.set_external_forces(&f).unwrap();
        let st = s.step(dt, Vector3::zeros(), &NoContacts, &mut r).unwrap();
        if k % (ramp / 12) == 0 {
            let tip = (mean(&s, &top) + mean(&s, &bottom)) * 0.5;
            println!("k {k} M/Mfull {:.3} theta {theta:.4} expected {:.4} tip {:?} conv {} newton {}", m / m_full, 2.0 * std::f64::consts::PI * m / m_full, tip, st.converged, st.newton_iterations);
        }
    }
}
