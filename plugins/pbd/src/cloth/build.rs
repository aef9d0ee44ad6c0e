//! Building a cloth: from a triangle surface or from explicit distance constraints (masses,
//! distance constraints in colour order, bending hinges).

use super::{check_positions, Cloth, DistanceConstraint};
use crate::error::PbdError;
use crate::lanes::{self, P4};
use crate::material::{ClothMaterial, SolverSettings};
use crate::mesh;
use crate::selfcollide::SelfCollision;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::sync::Arc;

impl Cloth {
    /// Builds a cloth from a triangle surface: masses from the areal density, a distance
    /// constraint per edge (stretch or shear compliance, see [`ClothMaterial`]) and an isometric
    /// bending hinge per interior edge. The rest shape is the given positions; the bending model
    /// assumes a flat rest shape (curved input is pulled towards flat).
    pub fn new(
        positions: &[Vector3<f64>],
        triangles: &[[u32; 3]],
        material: ClothMaterial,
        settings: SolverSettings,
    ) -> Result<Self, PbdError> {
        material.validate()?;
        settings.validate()?;
        check_positions(positions)?;
        if triangles.is_empty() {
            return Err(PbdError::InvalidMesh("no triangles".into()));
        }
        mesh::validate_triangles(positions, triangles)?;
        let n = positions.len();
        let mut mass = vec![0.0; n];
        for t in triangles {
            let m = material.areal_density * mesh::triangle_area(positions, *t) / 3.0;
            for &v in t {
                mass[v as usize] += m;
            }
        }
        if let Some(i) = mass.iter().position(|&m| m <= 0.0) {
            return Err(PbdError::InvalidMesh(format!(
                "particle {i} belongs to no triangle (it would have no mass)"
            )));
        }
        let edges = mesh::mesh_edges(positions, triangles);
        let shear_angle = 80f64.to_radians();
        let mut dists = Vec::with_capacity(edges.len());
        let mut bends = Vec::new();
        for e in &edges {
            let l0 = (positions[e.v[0] as usize] - positions[e.v[1] as usize]).norm();
            let c = if e.max_opposite_angle > shear_angle {
                material.shear_compliance
            } else {
                material.stretch_compliance
            };
            dists.push(DistanceConstraint {
                particles: e.v,
                rest_length: l0,
                compliance: c * l0 * l0 / e.area,
            });
            if e.opp[1] != u32::MAX {
                let ids = [e.v[0], e.v[1], e.opp[0], e.opp[1]];
                let x = ids.map(|i| positions[i as usize]);
                let k = mesh::isometric_bending_coefficients(x);
                if k.iter().all(|v| v.is_finite()) {
                    bends.push((ids, k, e.area * material.bending_compliance / 3.0));
                }
            }
        }
        let mut cloth = Self::build(
            positions, &mass, triangles, &dists, bends, material, settings,
        )?;
        cloth.edge = edges.iter().map(|e| e.v).collect();
        cloth.edge_rest = edges
            .iter()
            .map(|e| (positions[e.v[0] as usize] - positions[e.v[1] as usize]).norm())
            .collect();
        Ok(cloth)
    }

    /// Builds a particle system held together by explicit distance constraints only (a rope or a
    /// hanging chain); `masses` in kg. No triangles: no bending, no self-collision, no area
    /// measures. `material` supplies damping, friction and thickness.
    pub fn from_distance_constraints(
        positions: &[Vector3<f64>],
        masses: &[f64],
        constraints: &[DistanceConstraint],
        material: ClothMaterial,
        settings: SolverSettings,
    ) -> Result<Self, PbdError> {
        material.validate()?;
        settings.validate()?;
        check_positions(positions)?;
        if masses.len() != positions.len() {
            return Err(PbdError::InvalidParameter {
                field: "masses",
                value: format!("{} entries", masses.len()),
                expected: "one mass per particle",
            });
        }
        for &m in masses {
            crate::error::check_param("masses[i]", m, 0.0, true, "a finite mass > 0 kg")?;
        }
        for c in constraints {
            for &p in &c.particles {
                if p as usize >= positions.len() || c.particles[0] == c.particles[1] {
                    return Err(PbdError::InvalidMesh(format!(
                        "distance constraint {:?} refers to a missing or repeated particle",
                        c.particles
                    )));
                }
            }
            crate::error::check_param(
                "constraint.rest_length",
                c.rest_length,
                0.0,
                false,
                "a finite length >= 0 m",
            )?;
            crate::error::check_param(
                "constraint.compliance",
                c.compliance,
                0.0,
                false,
                "a finite compliance >= 0 m/N",
            )?;
        }
        let mut cloth = Self::build(
            positions,
            masses,
            &[],
            constraints,
            Vec::new(),
            material,
            settings,
        )?;
        cloth.edge = constraints.iter().map(|c| c.particles).collect();
        cloth.edge_rest = constraints.iter().map(|c| c.rest_length).collect();
        Ok(cloth)
    }

    fn build(
        positions: &[Vector3<f64>],
        masses: &[f64],
        triangles: &[[u32; 3]],
        dists: &[DistanceConstraint],
        bends: Vec<([u32; 4], [f64; 4], f64)>,
        material: ClothMaterial,
        settings: SolverSettings,
    ) -> Result<Self, PbdError> {
        let n = positions.len();
        // colour-sorted distance constraints
        let lists: Vec<&[u32]> = dists.iter().map(|d| &d.particles[..]).collect();
        let col = mesh::greedy_colouring(n, &lists);
        let mut order: Vec<usize> = (0..dists.len()).collect();
        order.sort_by_key(|&k| (col[k], k));
        let dist_idx: Vec<[u32; 2]> = order.iter().map(|&k| dists[k].particles).collect();
        let dist_rest: Vec<f64> = order.iter().map(|&k| dists[k].rest_length).collect();
        let dist_alpha: Vec<f64> = order.iter().map(|&k| dists[k].compliance).collect();
        let dist_colour_end = colour_ends(&order.iter().map(|&k| col[k]).collect::<Vec<_>>());
        // colour-sorted bending hinges
        let blists: Vec<&[u32]> = bends.iter().map(|b| &b.0[..]).collect();
        let bcol = mesh::greedy_colouring(n, &blists);
        let mut border: Vec<usize> = (0..bends.len()).collect();
        border.sort_by_key(|&k| (bcol[k], k));
        // adjacency for tethers
        let mut deg = vec![0u32; n + 1];
        for d in dists {
            deg[d.particles[0] as usize] += 1;
            deg[d.particles[1] as usize] += 1;
        }
        let mut adj_start = vec![0u32; n + 1];
        for i in 0..n {
            adj_start[i + 1] = adj_start[i] + deg[i];
        }
        let mut fill = adj_start.clone();
        let mut adj = vec![(0u32, 0.0f64); adj_start[n] as usize];
        for d in dists {
            let [a, b] = d.particles;
            adj[fill[a as usize] as usize] = (b, d.rest_length);
            fill[a as usize] += 1;
            adj[fill[b as usize] as usize] = (a, d.rest_length);
            fill[b as usize] += 1;
        }
        let inv: Vec<f64> = masses.iter().map(|m| 1.0 / m).collect();
        Ok(Cloth {
            material,
            settings,
            time: 0.0,
            steps: 0,
            pos: positions.to_vec(),
            vel: vec![Vector3::zeros(); n],
            rest: positions.to_vec(),
            mass: masses.to_vec(),
            inv_mass_free: inv.clone(),
            inv_mass: inv,
            x: positions.iter().map(P4::from_v).collect(),
            v: vec![P4::ZERO; n],
            prev: positions.iter().map(P4::from_v).collect(),
            avx2: lanes::Simd::detect(),
            save_pos: positions.to_vec(),
            save_vel: vec![Vector3::zeros(); n],
            triangles: triangles.to_vec(),
            edge: Vec::new(),
            edge_rest: Vec::new(),
            dist_lambda: vec![0.0; dist_idx.len()],
            rows: Arc::default(),
            row_cache: Arc::default(),
            dist_colour_end,
            dist_idx,
            dist_rest,
            dist_alpha,
            bend_idx: border.iter().map(|&k| bends[k].0).collect(),
            bend_k: border.iter().map(|&k| bends[k].1).collect(),
            bend_alpha: border.iter().map(|&k| bends[k].2).collect(),
            bend_lambda: vec![P4::ZERO; bends.len()],
            cache_h: f64::NAN,
            tether_rows: Vec::new(),
            grasp_tether_rows: Vec::new(),
            adj_start,
            adj,
            frames: Vec::new(),
            attachments: Vec::new(),
            next_attachment: 0,
            drives: Vec::new(),
            frame_now: Vec::new(),
            c_particle: Vec::new(),
            c_point: Vec::new(),
            c_normal: Vec::new(),
            c_vel: Vec::new(),
            c_mu: Vec::new(),
            c_body: Vec::new(),
            c_dn: Vec::new(),
            c_impulse: Vec::new(),
            query_buf: Vec::new(),
            e_edge: Vec::new(),
            e_point: Vec::new(),
            e_normal: Vec::new(),
            e_vel: Vec::new(),
            e_body: Vec::new(),
            e_impulse: Vec::new(),
            e_mu: Vec::new(),
            e_dn: Vec::new(),
            contact_start: vec![0; n + 1],
            guard_origin: positions.iter().map(P4::from_v).collect(),
            guard_radius: vec![0.0; n],
            selfc: SelfCollision::new(positions, triangles),
            groups: BTreeMap::new(),
        })
    }
}

/// End index of each run of equal colours in a colour-sorted list.
fn colour_ends(colours: &[u32]) -> Vec<usize> {
    let mut ends = Vec::new();
    for k in 1..=colours.len() {
        if k == colours.len() || colours[k] != colours[k - 1] {
            ends.push(k);
        }
    }
    ends
}
