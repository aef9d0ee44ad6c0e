//! The rotation-warped chord matrix.
//!
//! The chord solver ([`crate::FemSolid`], `FemConfig::quasi_newton`) reuses the factor of the
//! system matrix `A` assembled at a reference shape `X` (the rest shape or an earlier shape where
//! convergence slowed). A thin belt that bends or swings away from `X` turns its stiff membrane
//! directions with it; `A` still has them in the old directions, the chord steps lose their
//! contraction (rates near 1 in a Spot Drag episode) and the solver refactors at the new shape
//! (a Hessian evaluation with the PSD projection and a factorisation, about ten chord iterations'
//! work).
//!
//! The warped chord matrix is `R A R^T` with `R` block-diagonal, one rotation `R_i` per node from
//! the reference shape to the current shape (stiffness warping, Müller et al. 2002, used here
//! only as a Newton matrix, never for forces). It is symmetric positive definite whenever `A` is
//! (a congruence by an orthogonal matrix), so every chord step is still a descent direction
//! under the Armijo line search, the gradient is still exact and the solver stops at the same
//! tolerance; only the number of iterations and refactors changes. Its inverse is
//! `R A^-1 R^T`: rotate a vector into the reference frame, solve with the factor, rotate back.
//! Lumped masses and isotropic grasp springs are rotation invariant, so `R` only turns the
//! elastic part (and the constraint penalties, which the solver's filter handles exactly).
//! With active contacts the chord step is a filtered PCG on `R A R^T`, preconditioned by
//! `R (A + P)^-1 R^T` where `P` holds the contact penalties along world normals: contact nodes
//! keep `R_i = I` so that their penalties stay along the filtered directions (warping them too
//! cost 40 % more PCG iterations in Spot Lift; leaving contact iterations unwarped kept a stale
//! matrix there, and one Spot Drag expert episode (seed 6) then blew up where the belt met the
//! post).
//!
//! `R_i` comes from an element that contains the node: elements are visited in order and each one
//! that still has a node without a rotation computes its best-fit (Kabsch) rotation from its ten
//! nodes, the rotation factor of `S_e = sum_a (x_a - xbar)(X_a - Xbar)^T`, and gives it to those
//! nodes. For a rigid motion `x = Q X + t` every `R_i = Q`. One polar decomposition per element
//! (not per node, and only for elements that still cover a node) keeps the update cheaper than a
//! gradient evaluation; per-node sums over all incident elements cost as much as the refactors
//! they saved on a rod. Nodes whose element's `S_e` is singular or reflects keep `R_i = I`.
//!
//! A warped chord step is taken whole or not at all: where the line search would have to damp
//! it, the rotations do not fit the shape (a 4 mm belt crushed by a box moving 12 thicknesses
//! per step: the first warped step was 14 m long), the step is rejected and the solver refactors
//! at the current shape, as it does without the warp when convergence slows. Damped warped steps
//! had moved that belt into states even exact Newton could not solve (the test
//! `light_fast_box_against_a_thin_belt_does_not_explode`).
//!
//! Everything here is a cache computed from the solid's state (reference shape and current
//! positions) at the start of each chord solve, never part of a snapshot: a restored state
//! computes the same rotations.

use nalgebra::{Matrix3, Vector3};

/// Rotation factor of the polar decomposition of `m` by the scaled Newton iteration of Higham
/// (1986): `X <- (g X + X^-T / g) / 2`, `g = sqrt(|X^-1| / |X|)` (Frobenius norms), with
/// `X^-T = cof(X) / det X` from the columns' cross products. `None` when `m` is singular or
/// reflects (`det m <= 0`), or has not converged in 20 iterations.
pub fn polar_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let mut x = *m;
    for _ in 0..20 {
        let (c0, c1, c2) = (x.column(0), x.column(1), x.column(2));
        let cof = Matrix3::from_columns(&[c1.cross(&c2), c2.cross(&c0), c0.cross(&c1)]);
        let det = c0.dot(&cof.column(0));
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let g = (cof.norm() / (det * x.norm())).sqrt();
        let next = x * (0.5 * g) + cof * (0.5 / (g * det));
        let change = (next - x).norm_squared();
        x = next;
        if change <= 1e-6 {
            return Some(x);
        }
    }
    None
}

/// Best-fit rotation of an element's ten nodes from `x_ref` to `x` (Kabsch): the rotation factor
/// of `S = sum_a (x_a - xbar)(X_a - Xbar)^T`; `None` where `S` is singular or reflects.
fn element_rotation(
    el: &[u32; 10],
    x_ref: &[Vector3<f64>],
    x: &[Vector3<f64>],
) -> Option<Matrix3<f64>> {
    let mut cx = Vector3::zeros();
    let mut cr = Vector3::zeros();
    for &k in el {
        cx += x[k as usize];
        cr += x_ref[k as usize];
    }
    cx /= 10.0;
    cr /= 10.0;
    let mut s = Matrix3::zeros();
    for &k in el {
        s += (x[k as usize] - cx) * (x_ref[k as usize] - cr).transpose();
    }
    polar_rotation(&s)
}

/// Per-node rotations of the warped chord matrix (see the module docs).
#[derive(Clone, Debug, Default)]
pub(crate) struct Warp {
    /// `R_i` per node; empty while the warp is off (identity).
    rot: Vec<Matrix3<f64>>,
    /// Whether node `i` has its rotation yet (scratch of [`Warp::update`]).
    done: Vec<bool>,
}

impl Warp {
    /// Computes the rotations from the reference shape `x_ref` to `x`: elements in order, each
    /// one that still has a node without a rotation computes its own and gives it to those nodes.
    pub(crate) fn update(
        &mut self,
        elements: &[[u32; 10]],
        x_ref: &[Vector3<f64>],
        x: &[Vector3<f64>],
    ) {
        let n = x.len();
        self.rot.clear();
        self.rot.resize(n, Matrix3::identity());
        self.done.clear();
        self.done.resize(n, false);
        for el in elements {
            if el.iter().all(|&k| self.done[k as usize]) {
                continue;
            }
            let r = element_rotation(el, x_ref, x).unwrap_or_else(Matrix3::identity);
            for &k in el {
                if !self.done[k as usize] {
                    self.done[k as usize] = true;
                    self.rot[k as usize] = r;
                }
            }
        }
    }

    /// Gives `nodes` the identity (e.g. nodes with contact penalties along world normals).
    pub(crate) fn unwarp(&mut self, nodes: impl Iterator<Item = u32>) {
        for k in nodes {
            if let Some(r) = self.rot.get_mut(k as usize) {
                *r = Matrix3::identity();
            }
        }
    }

    /// `y = R A R^T v`, where `spmv(u, y)` computes `y = A u`; `tmp` is scratch of `v`'s length.
    pub(crate) fn apply(
        &self,
        v: &[Vector3<f64>],
        y: &mut [Vector3<f64>],
        tmp: &mut [Vector3<f64>],
        spmv: impl Fn(&[Vector3<f64>], &mut [Vector3<f64>]),
    ) {
        if self.rot.is_empty() {
            spmv(v, y);
            return;
        }
        tmp.copy_from_slice(v);
        self.turn_back(tmp);
        spmv(tmp, y);
        self.turn(y);
    }

    /// Whether the rotations are in use (`false`: the chord matrix is `A` itself).
    pub(crate) fn is_on(&self) -> bool {
        !self.rot.is_empty()
    }

    /// Turns the warp off (the chord matrix is `A` itself), e.g. after a refactor at the current
    /// shape.
    pub(crate) fn reset(&mut self) {
        self.rot.clear();
    }

    /// `v <- R^T v` (into the reference frame).
    pub(crate) fn turn_back(&self, v: &mut [Vector3<f64>]) {
        for (x, r) in v.iter_mut().zip(&self.rot) {
            *x = r.tr_mul(x);
        }
    }

    /// `v <- R v` (back to the current frame).
    pub(crate) fn turn(&self, v: &mut [Vector3<f64>]) {
        for (x, r) in v.iter_mut().zip(&self.rot) {
            *x = r * *x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, UnitQuaternion};

    /// Largest `|a_i - b_i|`.
    fn max_diff(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max)
    }

    #[test]
    fn polar_rotation_recovers_the_rotation_of_a_stretched_rotation() {
        let q = Rotation3::from_euler_angles(0.3, -1.1, 2.0);
        let stretch = Matrix3::new(1.5, 0.2, 0.0, 0.2, 0.7, 0.1, 0.0, 0.1, 1.2);
        let r = polar_rotation(&(q.matrix() * stretch)).expect("converges");
        let err = (r - q.matrix()).norm();
        println!("polar rotation error {err:.2e} (tolerance 1e-9)");
        assert!(err < 1e-9);
        assert!(polar_rotation(&Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0))).is_none());
        assert!(polar_rotation(&Matrix3::zeros()).is_none());
    }

    #[test]
    fn rigid_motion_gives_its_rotation_at_every_node_and_the_warped_product_matches() {
        let (nodes, tets) =
            crate::testing::box_mesh(Vector3::zeros(), Vector3::new(0.9, 0.05, 0.004), [6, 1, 1]);
        let mesh = crate::element::QuadraticMesh::from_linear(&nodes, &tets).unwrap();
        let q = UnitQuaternion::from_euler_angles(0.4, 0.2, -0.7);
        let t = Vector3::new(0.1, -2.0, 0.5);
        let moved: Vec<_> = mesh.rest.iter().map(|p| q * p + t).collect();
        let mut warp = Warp::default();
        warp.update(&mesh.elements, &mesh.rest, &moved);
        assert_eq!(warp.rot.len(), moved.len());
        let worst = warp
            .rot
            .iter()
            .map(|r| (r - q.to_rotation_matrix().matrix()).norm())
            .fold(0.0, f64::max);
        println!(
            "largest rotation error at {} nodes: {worst:.2e} (tolerance 1e-9)",
            moved.len()
        );
        assert!(worst < 1e-9);
        // R A R^T v with A = diag(1, 2, 3) per node, against the explicit product
        let a = Matrix3::from_diagonal(&Vector3::new(1.0, 2.0, 3.0));
        let v: Vec<_> = (0..moved.len())
            .map(|i| Vector3::new(i as f64, 1.0, -0.5 * i as f64))
            .collect();
        let mut y = vec![Vector3::zeros(); v.len()];
        let mut tmp = y.clone();
        warp.apply(&v, &mut y, &mut tmp, |u, out| {
            for (o, ui) in out.iter_mut().zip(u) {
                *o = a * ui;
            }
        });
        let r = q.to_rotation_matrix();
        let want = r.matrix() * a * r.matrix().transpose();
        let want_y: Vec<_> = v.iter().map(|vi| want * vi).collect();
        let err = max_diff(&y, &want_y);
        let scale = v.iter().map(|x| x.norm()).fold(0.0, f64::max);
        assert!(
            err < 1e-8 * scale,
            "warped product error {err:e} for |v| up to {scale}"
        );
        // into the reference frame and back is the identity
        let mut w = v.clone();
        warp.turn_back(&mut w);
        warp.turn(&mut w);
        let err = max_diff(&w, &v);
        assert!(err < 1e-8 * scale, "round trip error {err:e}");
        warp.reset();
        assert!(warp.rot.is_empty());
    }

    /// A rubber belt clamped at one end swings down under gravity (a quarter turn): with the
    /// warped chord matrix the solver refactors less and reaches the same motion within a few
    /// Newton tolerances.
    #[test]
    fn a_swinging_belt_refactors_less_and_moves_the_same_with_the_warp() {
        use crate::{FemConfig, FemSolid, Material, NoContacts};
        let run = |warped_chord: bool| {
            let (nodes, tets) = crate::testing::box_mesh(
                Vector3::zeros(),
                Vector3::new(0.9, 0.05, 0.004),
                [18, 1, 1],
            );
            let config = FemConfig {
                warped_chord,
                rayleigh_mass: 1.0,
                ..FemConfig::default()
            };
            let material = Material::new(3e5, 0.45, 1100.0).unwrap();
            let mut belt = FemSolid::new(&nodes, &tets, material, config).unwrap();
            let clamp = belt.rest_nodes_where(|p| p.x < 1e-9);
            belt.fix_nodes(&clamp).unwrap();
            let (mut factorizations, mut iterations) = (0, 0);
            let mut reactions = Vec::new();
            for _ in 0..120 {
                let stats = belt
                    .step(
                        1.0 / 240.0,
                        Vector3::new(0.0, 0.0, -9.81),
                        &NoContacts,
                        &mut reactions,
                    )
                    .unwrap();
                assert!(stats.converged);
                factorizations += stats.factorizations;
                iterations += stats.newton_iterations;
            }
            let tol_x = belt.config().newton_tolerance * belt.model().length_scale;
            (belt.positions().to_vec(), factorizations, iterations, tol_x)
        };
        let (x_plain, f_plain, it_plain, _) = run(false);
        let (x_warp, f_warp, it_warp, tol_x) = run(true);
        let tip = |x: &[Vector3<f64>]| x.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let diff = max_diff(&x_plain, &x_warp);
        println!(
            "0.5 s of swing: lowest node z {:.4} m; factorisations {f_plain} -> {f_warp}, \
             chord iterations {it_plain} -> {it_warp}; largest node difference {diff:.2e} m \
             (Newton tolerance {tol_x:.1e} m, bound 100x)",
            tip(&x_warp)
        );
        assert!(tip(&x_warp) < -0.3, "the belt swings down");
        assert!(
            f_warp * 2 <= f_plain,
            "{f_warp} vs {f_plain} factorisations"
        );
        assert!(diff < 100.0 * tol_x);
    }
}
