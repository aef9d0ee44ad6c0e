//! Immutable compiled data of one elastic solid: rest geometry, element quadrature data, lumped
//! masses, sparsity pattern and the element kernel (energy, gradient, projected Hessian).

use crate::element::{barycentric_gradients, shape_gradients, QuadraticMesh, NQ, QUAD_POINTS};
use crate::error::FemError;
use crate::material::{Material, StableNeoHookean};
use crate::sparse::{BlockPattern, Profile};
use nalgebra::{Matrix3, SMatrix, Vector3};
use std::sync::Arc;

/// Compiled, immutable model of a quadratic-tet solid (shared by value; cheap to clone behind an
/// `Arc` on the engine side). Arrays are structure-of-arrays, world frame, SI units.
#[derive(Clone, Debug)]
pub struct SolidModel {
    /// The quadratic mesh (rest positions, elements, edges, boundary faces).
    pub mesh: QuadraticMesh,
    /// Material as entered by the user.
    pub material: Material,
    /// Stable Neo-Hookean energy with the corrected Lamé mapping of `material`.
    pub energy: StableNeoHookean,
    /// Lumped (HRZ) node masses (kg), length `n_nodes`. Corners get `m_e / 36`, edge nodes `4 m_e / 27`
    /// of each element mass `m_e` (Hinton, Rock & Zienkiewicz 1976 diagonal scaling).
    pub mass: Vec<f64>,
    /// Rest-frame shape-function gradients (1/m), `[element * NQ + q][local node]`.
    pub qp_grad: Vec<[Vector3<f64>; 10]>,
    /// Quadrature weight times element rest volume (m^3), `[element * NQ + q]`.
    pub qp_weight: Vec<f64>,
    /// `qp_grad` and `qp_weight` with the quadrature points innermost (one lane each), for the
    /// gradient kernel that evaluates an element's four points at once.
    lanes: Vec<ElementLanes>,
    /// Rest volume of each element (m^3).
    pub volume: Vec<f64>,
    /// Node-block sparsity pattern of the stiffness matrix.
    pub pattern: BlockPattern,
    /// Block index of local pair `(a, b)` of each element: `[element * 100 + 10 a + b]`.
    pub elem_blocks: Vec<u32>,
    /// The Cholesky factor's node order (reverse Cuthill-McKee) and envelope, shared by every
    /// factor of this model.
    pub profile: Arc<Profile>,
    /// Boundary nodes (corners and edge nodes of boundary faces), sorted.
    pub surface_nodes: Vec<u32>,
    /// Nodes of each boundary face: its 3 corners (outward orientation) then the edge nodes of
    /// edges (0,1), (1,2), (2,0); used for the surface normals at the nodes.
    pub surface_faces: Vec<[u32; 6]>,
    /// Diagonal of the rest bounding box (m), the length scale of tolerances.
    pub length_scale: f64,
}

/// Output of one pass of the element kernel.
#[derive(Clone, Copy, Debug, Default)]
pub struct KernelStats {
    /// Elastic energy (J).
    pub energy: f64,
    /// Quadrature points with `det F <= 0`.
    pub inverted: usize,
}

/// The positions of an element's 10 nodes.
#[inline]
fn gather(x: &[Vector3<f64>], el: &[u32; 10]) -> [Vector3<f64>; 10] {
    let mut xe = [Vector3::zeros(); 10];
    for a in 0..10 {
        xe[a] = x[el[a] as usize];
    }
    xe
}

/// Deformation gradient `sum_a x_a g_a^T` from an element's node positions and the shape-function
/// gradients of one quadrature point.
#[inline(always)]
fn interpolate(xe: &[Vector3<f64>; 10], g: &[Vector3<f64>; 10]) -> Matrix3<f64> {
    // the nine sums written out (same order of additions as `f += x_a * g_a^T`), so that they
    // stay in registers
    let mut f = [[0.0f64; 3]; 3];
    for a in 0..10 {
        let (x, ga) = (&xe[a], &g[a]);
        for (i, row) in f.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v += x[i] * ga[j];
            }
        }
    }
    Matrix3::new(
        f[0][0], f[0][1], f[0][2], f[1][0], f[1][1], f[1][2], f[2][0], f[2][1], f[2][2],
    )
}

// The lane kernel evaluates the four quadrature points of an element side by side.
const _: () = assert!(NQ == 4);

/// Nodes of an element padded to a multiple of four lanes.
const NODE_LANES: usize = 12;

/// One element's quadrature data in two layouts: `g[a][j][q]` is component `j` of the
/// shape-function gradient of node `a` at point `q` (points innermost, for `F`), `gq[q][j][a]` the
/// same with the nodes innermost (zero-padded, for the node forces); `w[q]` the weight times the
/// rest volume.
#[derive(Clone, Debug)]
struct ElementLanes {
    g: [[[f64; NQ]; 3]; 10],
    gq: [[[f64; NODE_LANES]; 3]; NQ],
    w: [f64; NQ],
}

impl ElementLanes {
    fn new(grads: &[[Vector3<f64>; 10]], weights: &[f64]) -> Self {
        let mut g = [[[0.0; NQ]; 3]; 10];
        let mut gq = [[[0.0; NODE_LANES]; 3]; NQ];
        for (q, grad_q) in grads.iter().enumerate() {
            for (a, ga) in grad_q.iter().enumerate() {
                for j in 0..3 {
                    g[a][j][q] = ga[j];
                    gq[q][j][a] = ga[j];
                }
            }
        }
        let mut w = [0.0; NQ];
        w.copy_from_slice(weights);
        ElementLanes { g, gq, w }
    }
}

type Lanes = [f64; NQ];

#[inline(always)]
fn per_lane(f: impl Fn(usize) -> f64) -> Lanes {
    [f(0), f(1), f(2), f(3)]
}

/// Elastic gradient (when `grad` is given, written into it) and energy (when `with_energy`)
/// without damping, four quadrature points per pass; every lane performs the operations of the scalar kernel ([`interpolate`],
/// `f.determinant()`, [`StableNeoHookean::energy`], [`StableNeoHookean::pk1`]) in the same order,
/// so the results are bitwise those of [`SolidModel::eval`]'s gradient (unit test
/// `lane_kernel_is_bitwise_the_scalar_kernel`). Inlined into both copies of the dispatch.
#[inline(always)]
fn gradient_lanes_body(
    elements: &[[u32; 10]],
    element_lanes: &[ElementLanes],
    mat: &StableNeoHookean,
    x: &[Vector3<f64>],
    mut grad: Option<&mut [Vector3<f64>]>,
    with_energy: bool,
) -> KernelStats {
    if let Some(g) = grad.as_deref_mut() {
        g.iter_mut().for_each(|g| *g = Vector3::zeros());
    }
    let mut s = KernelStats::default();
    let (mu, lambda, alpha) = (mat.mu, mat.lambda, mat.alpha);
    for (el, l) in elements.iter().zip(element_lanes) {
        let xe = gather(x, el);
        // F at the four points: f[i][j][q] = sum_a x_a[i] g_a[j][q], in node order
        let mut f = [[[0.0f64; NQ]; 3]; 3];
        for (xa, ga) in xe.iter().zip(&l.g) {
            for (i, row) in f.iter_mut().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    for q in 0..NQ {
                        v[q] += xa[i] * ga[j][q];
                    }
                }
            }
        }
        // determinant (nalgebra's 3x3 expansion) for the inverted count and the energy
        let det = per_lane(|q| {
            let m = |i: usize, j: usize| f[i][j][q];
            let m12_23 = m(1, 1) * m(2, 2) - m(2, 1) * m(1, 2);
            let m11_23 = m(1, 0) * m(2, 2) - m(2, 0) * m(1, 2);
            let m11_22 = m(1, 0) * m(2, 1) - m(2, 0) * m(1, 1);
            m(0, 0) * m12_23 - m(0, 1) * m11_23 + m(0, 2) * m11_22
        });
        // |F|^2, column by column
        let ic = per_lane(|q| {
            let col = |c: usize| {
                f[0][c][q] * f[0][c][q] + f[1][c][q] * f[1][c][q] + f[2][c][q] * f[2][c][q]
            };
            0.0 + col(0) + col(1) + col(2)
        });
        for q in 0..NQ {
            if det[q] <= 0.0 {
                s.inverted += 1;
            }
            if with_energy {
                let (j, a) = (det[q], alpha);
                let psi = 0.5 * mu * (ic[q] - 3.0)
                    + 0.5 * lambda * ((j - a) * (j - a) - (1.0 - a) * (1.0 - a))
                    - 0.5 * mu * ((ic[q] + 1.0) / 4.0).ln();
                s.energy += l.w[q] * psi;
            }
        }
        let Some(grad) = grad.as_deref_mut() else {
            continue;
        };
        // cofactor columns f1 x f2, f2 x f0, f0 x f1 (cof[r][c][q])
        let mut cof = [[[0.0f64; NQ]; 3]; 3];
        for (c, (u, v)) in [(1, 2), (2, 0), (0, 1)].into_iter().enumerate() {
            for q in 0..NQ {
                let (ax, ay, az) = (f[0][u][q], f[1][u][q], f[2][u][q]);
                let (bx, by, bz) = (f[0][v][q], f[1][v][q], f[2][v][q]);
                cof[0][c][q] = ay * bz - az * by;
                cof[1][c][q] = az * bx - ax * bz;
                cof[2][c][q] = ax * by - ay * bx;
            }
        }
        // P = s F + c cof F, s = mu (1 - 1 / (|F|^2 + 1)), c = lambda (J - alpha) with J from
        // the first column
        let mut p = [[[0.0f64; NQ]; 3]; 3];
        for q in 0..NQ {
            let jq =
                f[0][0][q] * cof[0][0][q] + f[1][0][q] * cof[1][0][q] + f[2][0][q] * cof[2][0][q];
            let sq = mu * (1.0 - 1.0 / (ic[q] + 1.0));
            let cq = lambda * (jq - alpha);
            for r in 0..3 {
                for c in 0..3 {
                    p[r][c][q] = f[r][c][q] * sq + cof[r][c][q] * cq;
                }
            }
        }
        // node forces (P g_a) w, summed over the points in order (one lane per node)
        let mut out = [[0.0f64; NODE_LANES]; 3];
        for (q, gq) in l.gq.iter().enumerate() {
            let w = l.w[q];
            for (i, row) in out.iter_mut().enumerate() {
                let (p0, p1, p2) = (p[i][0][q], p[i][1][q], p[i][2][q]);
                for a in 0..NODE_LANES {
                    row[a] += (p0 * gq[0][a] + p1 * gq[1][a] + p2 * gq[2][a]) * w;
                }
            }
        }
        for (a, &node) in el.iter().enumerate() {
            grad[node as usize] += Vector3::new(out[0][a], out[1][a], out[2][a]);
        }
    }
    s
}

modesuite_engine::avx2_dispatch! {
    /// [`gradient_lanes_body`], with the AVX2 copy where `simd` allows.
    fn gradient_lanes / gradient_lanes_avx2 => gradient_lanes_body(
        elements: &[[u32; 10]],
        element_lanes: &[ElementLanes],
        mat: &StableNeoHookean,
        x: &[Vector3<f64>],
        grad: Option<&mut [Vector3<f64>]>,
        with_energy: bool,
    ) -> KernelStats
}

impl SolidModel {
    /// Compiles a linear tet mesh (positively oriented) into 10-node elements.
    pub fn new(
        nodes: &[Vector3<f64>],
        tets: &[[u32; 4]],
        material: Material,
    ) -> Result<Self, FemError> {
        material.validate()?;
        let mesh = QuadraticMesh::from_linear(nodes, tets)?;
        let n = mesh.rest.len();
        let ne = mesh.elements.len();
        let mut mass = vec![0.0; n];
        let mut qp_grad = Vec::with_capacity(ne * NQ);
        let mut qp_weight = Vec::with_capacity(ne * NQ);
        let mut volume = Vec::with_capacity(ne);
        for (e, el) in mesh.elements.iter().enumerate() {
            let x = [0, 1, 2, 3].map(|k| mesh.rest[el[k] as usize]);
            let (gl, vol) = barycentric_gradients(&x).ok_or(FemError::DegenerateElement {
                tet: e,
                volume: 0.0,
            })?;
            volume.push(vol);
            let me = material.density * vol;
            for k in 0..4 {
                mass[el[k] as usize] += me / 36.0;
            }
            for k in 4..10 {
                mass[el[k] as usize] += me * 4.0 / 27.0;
            }
            for q in QUAD_POINTS.iter() {
                qp_grad.push(shape_gradients(q, &gl));
                qp_weight.push(vol / NQ as f64);
            }
        }
        let lanes = (0..ne)
            .map(|e| {
                ElementLanes::new(
                    &qp_grad[e * NQ..e * NQ + NQ],
                    &qp_weight[e * NQ..e * NQ + NQ],
                )
            })
            .collect();
        let pattern = BlockPattern::from_cliques(n, mesh.elements.iter().map(|e| &e[..]));
        let mut elem_blocks = Vec::with_capacity(ne * 100);
        for el in &mesh.elements {
            for a in 0..10 {
                for b in 0..10 {
                    elem_blocks
                        .push(pattern.find(el[a], el[b]).expect("element pair in pattern") as u32);
                }
            }
        }
        let profile = Arc::new(Profile::new(&pattern, &pattern.rcm()));
        let surface_nodes = mesh.boundary_nodes();
        let surface_faces = mesh
            .boundary_faces
            .iter()
            .map(|f| {
                let e = |a: usize, b: usize| mesh.edge_node(f[a], f[b]).unwrap_or(f[a]);
                [f[0], f[1], f[2], e(0, 1), e(1, 2), e(2, 0)]
            })
            .collect();
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for p in &mesh.rest {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let length_scale = (hi - lo).norm();
        Ok(SolidModel {
            energy: StableNeoHookean::from_young_poisson(
                material.youngs_modulus,
                material.poisson_ratio,
            ),
            mesh,
            material,
            mass,
            qp_grad,
            qp_weight,
            lanes,
            volume,
            pattern,
            elem_blocks,
            profile,
            surface_nodes,
            surface_faces,
            length_scale,
        })
    }

    /// Outward surface normals at the nodes for positions `x` (area-weighted sums of the normals
    /// of the boundary faces' corner triangles, normalised), written into `out` (resized to
    /// `n_nodes`); interior nodes, and nodes whose faces cancel out, get zero.
    pub fn surface_normals(&self, x: &[Vector3<f64>], out: &mut Vec<Vector3<f64>>) {
        out.clear();
        out.resize(self.n_nodes(), Vector3::zeros());
        for f in &self.surface_faces {
            let [a, b, c] = [f[0], f[1], f[2]].map(|i| x[i as usize]);
            let n = (b - a).cross(&(c - a));
            for &i in f {
                out[i as usize] += n;
            }
        }
        for v in out.iter_mut() {
            *v = v.try_normalize(1e-300).unwrap_or_else(Vector3::zeros);
        }
    }

    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.mass.len()
    }

    /// Number of 10-node elements.
    pub fn n_elements(&self) -> usize {
        self.mesh.elements.len()
    }

    /// Deformation gradient at quadrature point `q` of element `e` for positions `x`.
    #[inline]
    pub fn deformation_gradient(&self, e: usize, q: usize, x: &[Vector3<f64>]) -> Matrix3<f64> {
        interpolate(
            &gather(x, &self.mesh.elements[e]),
            &self.qp_grad[e * NQ + q],
        )
    }

    /// Elastic energy only (J) and inverted quadrature-point count; with `damping`, the
    /// strain-rate damping potential (see [`SolidModel::eval`]) is included in the energy.
    pub fn energy_only(
        &self,
        x: &[Vector3<f64>],
        damping: Option<(&[Vector3<f64>], f64)>,
    ) -> KernelStats {
        self.kernel(x, None, damping, true)
    }

    /// Strain-rate (stiffness-proportional) damping potential density at one quadrature point:
    /// `c/2 dE : C : dE` with `dE = E(F) - E(F_prev)` the Green strain increment and `C` the
    /// small-strain isotropic elasticity tensor (`lambda_L`, `mu_L`); with `c = b / dt` it is
    /// Rayleigh's `b K` at small strain but exactly invariant to rigid rotation (a linear `b K`
    /// damps the second-order chord of a rotation). Returns the energy density, `dD/dF` and, when
    /// asked, its Gauss-Newton (positive semi-definite) derivative.
    pub fn damping_qp(
        &self,
        f: &Matrix3<f64>,
        f_prev: &Matrix3<f64>,
        c: f64,
        hess: bool,
    ) -> (f64, Matrix3<f64>, Option<SMatrix<f64, 9, 9>>) {
        let (mu, lambda) = self.energy.small_strain_lame();
        let de = (f.transpose() * f - f_prev.transpose() * f_prev) * 0.5;
        let tr = de.trace();
        let stress = Matrix3::identity() * (lambda * tr) + de * (2.0 * mu);
        let energy = 0.5 * c * (lambda * tr * tr + 2.0 * mu * de.norm_squared());
        let p = f * stress * c;
        let h = hess.then(|| {
            let mut h = SMatrix::<f64, 9, 9>::zeros();
            for k in 0..9 {
                let mut df = Matrix3::zeros();
                df.as_mut_slice()[k] = 1.0;
                let ftdf = f.transpose() * df;
                let d_e = (ftdf + ftdf.transpose()) * 0.5;
                let ds = Matrix3::identity() * (lambda * d_e.trace()) + d_e * (2.0 * mu);
                let dp = f * ds * c;
                for r in 0..9 {
                    h[(r, k)] = dp.as_slice()[r];
                }
            }
            h
        });
        (energy, p, h)
    }

    /// Elastic energy, gradient `dPsi/dx` (N, written into `grad`) and, if `hess` is given, the
    /// stiffness matrix (block values overwritten); with `project`, each quadrature point's
    /// `dP/dF` is first made positive semi-definite ([`StableNeoHookean::project_hessian`]). With
    /// `damping = Some((x_prev, c))` the strain-rate damping potential of
    /// [`SolidModel::damping_qp`] (relative to the shape `x_prev`) is added to all three.
    pub fn eval(
        &self,
        x: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        hess: Option<&mut [Matrix3<f64>]>,
        project: bool,
        damping: Option<(&[Vector3<f64>], f64)>,
    ) -> KernelStats {
        let Some(hess) = hess else {
            return self.kernel(x, Some(grad), damping, true);
        };
        grad.iter_mut().for_each(|g| *g = Vector3::zeros());
        hess.iter_mut().for_each(|b| *b = Matrix3::zeros());
        let mut s = KernelStats::default();
        for (e, el) in self.mesh.elements.iter().enumerate() {
            let xe = gather(x, el);
            let xpe = damping.map(|(xp, c)| (gather(xp, el), c));
            let mut ge = [Vector3::<f64>::zeros(); 10];
            let mut ke = [[Matrix3::<f64>::zeros(); 10]; 10];
            for q in 0..NQ {
                let g = &self.qp_grad[e * NQ + q];
                let w = self.qp_weight[e * NQ + q];
                let f = interpolate(&xe, g);
                if f.determinant() <= 0.0 {
                    s.inverted += 1;
                }
                let (mut psi, mut p, h) = self.energy.eval(&f);
                let mut h = if project {
                    self.energy.project_hessian(&f, &h)
                } else {
                    h
                };
                if let Some((xpe, c)) = &xpe {
                    let (ed, pd, hd) = self.damping_qp(&f, &interpolate(xpe, g), *c, true);
                    psi += ed;
                    p += pd;
                    h += hd.expect("requested");
                }
                s.energy += w * psi;
                let h = h * w;
                for a in 0..10 {
                    ge[a] += p * g[a] * w;
                }
                // hb[b] (9x3): hb[(r, k)] = sum_l H[(r, k + 3 l)] g_b[l]
                let mut hb = [SMatrix::<f64, 9, 3>::zeros(); 10];
                for b in 0..10 {
                    for k in 0..3 {
                        let col = h.column(k) * g[b][0]
                            + h.column(k + 3) * g[b][1]
                            + h.column(k + 6) * g[b][2];
                        hb[b].set_column(k, &col);
                    }
                }
                for a in 0..10 {
                    let ga = g[a];
                    for b in a..10 {
                        let m = &hb[b];
                        let mut blk = Matrix3::zeros();
                        for i in 0..3 {
                            for k in 0..3 {
                                blk[(i, k)] = ga[0] * m[(i, k)]
                                    + ga[1] * m[(i + 3, k)]
                                    + ga[2] * m[(i + 6, k)];
                            }
                        }
                        ke[a][b] += blk;
                    }
                }
            }
            for a in 0..10 {
                grad[el[a] as usize] += ge[a];
            }
            let map = &self.elem_blocks[e * 100..e * 100 + 100];
            for a in 0..10 {
                for b in a..10 {
                    let blk = ke[a][b];
                    hess[map[10 * a + b] as usize] += blk;
                    if b != a {
                        hess[map[10 * b + a] as usize] += blk.transpose();
                    }
                }
            }
        }
        s
    }

    /// The elastic gradient of [`SolidModel::eval`] (N, written into `grad`) without the energy
    /// (no logarithm) and without the Hessian; returns the number of inverted quadrature points.
    pub fn gradient(
        &self,
        x: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        damping: Option<(&[Vector3<f64>], f64)>,
    ) -> usize {
        self.kernel(x, Some(grad), damping, false).inverted
    }

    /// Elastic energy and gradient in one pass (N, written into `grad`): the energy is bitwise
    /// that of [`SolidModel::energy_only`] and the gradient that of [`SolidModel::gradient`].
    pub fn energy_gradient(
        &self,
        x: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        damping: Option<(&[Vector3<f64>], f64)>,
    ) -> KernelStats {
        self.kernel(x, Some(grad), damping, true)
    }

    /// [`SolidModel::eval`] without the Hessian: the gradient when `grad` is given (written into
    /// it), the energy when `with_energy`; the lane kernel without damping, else one quadrature
    /// point at a time.
    pub(crate) fn kernel(
        &self,
        x: &[Vector3<f64>],
        grad: Option<&mut [Vector3<f64>]>,
        damping: Option<(&[Vector3<f64>], f64)>,
        with_energy: bool,
    ) -> KernelStats {
        if damping.is_none() {
            return gradient_lanes(
                modesuite_engine::simd::Simd::detect(),
                &self.mesh.elements,
                &self.lanes,
                &self.energy,
                x,
                grad,
                with_energy,
            );
        }
        self.kernel_scalar(x, grad, damping, with_energy)
    }

    /// [`SolidModel::kernel`] one quadrature point at a time, with or without damping (the kernel
    /// of the damped passes, and the reference the lane kernel is tested against).
    fn kernel_scalar(
        &self,
        x: &[Vector3<f64>],
        mut grad: Option<&mut [Vector3<f64>]>,
        damping: Option<(&[Vector3<f64>], f64)>,
        with_energy: bool,
    ) -> KernelStats {
        if let Some(g) = grad.as_deref_mut() {
            g.iter_mut().for_each(|g| *g = Vector3::zeros());
        }
        let mut s = KernelStats::default();
        for (e, el) in self.mesh.elements.iter().enumerate() {
            let xe = gather(x, el);
            let xpe = damping.map(|(xp, c)| (gather(xp, el), c));
            let mut ge = [Vector3::<f64>::zeros(); 10];
            for q in 0..NQ {
                let g = &self.qp_grad[e * NQ + q];
                let w = self.qp_weight[e * NQ + q];
                let f = interpolate(&xe, g);
                if f.determinant() <= 0.0 {
                    s.inverted += 1;
                }
                if with_energy {
                    s.energy += w * self.energy.energy(&f);
                }
                let damped = xpe
                    .as_ref()
                    .map(|(xpe, c)| self.damping_qp(&f, &interpolate(xpe, g), *c, false));
                if let (true, Some((ed, _, _))) = (with_energy, &damped) {
                    s.energy += w * ed;
                }
                if grad.is_some() {
                    let mut p = self.energy.pk1(&f);
                    if let Some((_, pd, _)) = damped {
                        p += pd;
                    }
                    for a in 0..10 {
                        ge[a] += p * g[a] * w;
                    }
                }
            }
            if let Some(grad) = grad.as_deref_mut() {
                for a in 0..10 {
                    grad[el[a] as usize] += ge[a];
                }
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::box_mesh;
    use crate::{FemConfig, FemSolid, Material};
    use nalgebra::Vector3;

    /// A 0.3 x 0.05 x 0.02 m rubber belt on `cells`, Young's modulus `e`.
    fn belt(cells: [usize; 3], e: f64) -> FemSolid {
        let (nodes, tets) = box_mesh(Vector3::zeros(), Vector3::new(0.3, 0.05, 0.02), cells);
        let material = Material::new(e, 0.45, 1100.0).unwrap();
        FemSolid::new(&nodes, &tets, material, FemConfig::default()).unwrap()
    }

    /// The bits of every component, to compare vectors exactly.
    fn bits(g: &[Vector3<f64>]) -> Vec<u64> {
        g.iter()
            .flat_map(|v| v.iter().map(|c| c.to_bits()))
            .collect()
    }

    #[test]
    fn energy_gradient_is_bitwise_energy_only_and_gradient() {
        let s = belt([6, 1, 1], 2e5);
        let m = s.model();
        let rest = s.rest_positions();
        // bent and squeezed, one element inverted
        let mut x: Vec<Vector3<f64>> = rest
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let t = (i as f64 * 0.37).sin();
                Vector3::new(p.x, p.y * (1.0 - 0.3 * t), p.z + 0.4 * p.x * p.x)
            })
            .collect();
        x[0] = rest[1] + Vector3::new(0.02, 0.0, 0.0);
        for damping in [None, Some((rest, 0.3))] {
            let mut g1 = vec![Vector3::zeros(); x.len()];
            let mut g2 = vec![Vector3::zeros(); x.len()];
            let fused = m.energy_gradient(&x, &mut g1, damping);
            let energy = m.energy_only(&x, damping);
            let inverted = m.gradient(&x, &mut g2, damping);
            assert_eq!(fused.energy.to_bits(), energy.energy.to_bits());
            assert_eq!(fused.inverted, energy.inverted);
            assert_eq!(fused.inverted, inverted);
            assert!(inverted > 0, "the test shape has inverted points");
            assert_eq!(bits(&g1), bits(&g2));
        }
    }

    #[test]
    fn lane_kernel_is_bitwise_the_scalar_kernel() {
        let s = belt([6, 1, 2], 3e5);
        let m = s.model();
        let rest = s.rest_positions();
        let mut compared = 0;
        for k in 0..50 {
            // random-ish large deformations, some elements inverted
            let mut x: Vec<Vector3<f64>> = rest
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let t = ((i * 7 + k * 13) as f64 * 0.61).sin();
                    let u = ((i * 3 + k * 5) as f64 * 1.37).cos();
                    Vector3::new(
                        p.x * (1.0 + 0.2 * u),
                        p.y * (1.0 - 0.5 * t) + 0.01 * u,
                        p.z + 0.3 * p.x * p.x * t,
                    )
                })
                .collect();
            if k % 3 == 0 {
                x[k % rest.len()] = rest[(k + 5) % rest.len()];
            }
            let mut want = vec![Vector3::zeros(); x.len()];
            let reference = m.kernel_scalar(&x, Some(&mut want), None, true);
            for simd in [
                modesuite_engine::simd::Simd::baseline(),
                modesuite_engine::simd::Simd::detect(),
            ] {
                let avx2 = simd.avx2();
                let run = |grad: Option<&mut [Vector3<f64>]>, with_energy: bool| {
                    gradient_lanes(
                        simd,
                        &m.mesh.elements,
                        &m.lanes,
                        &m.energy,
                        &x,
                        grad,
                        with_energy,
                    )
                };
                let mut got = vec![Vector3::zeros(); x.len()];
                let st = run(Some(&mut got), true);
                assert_eq!(
                    st.energy.to_bits(),
                    reference.energy.to_bits(),
                    "energy, case {k}, avx2 {avx2}"
                );
                assert_eq!(st.inverted, reference.inverted);
                assert_eq!(bits(&got), bits(&want), "gradient, case {k}, avx2 {avx2}");
                let mut no_energy = vec![Vector3::zeros(); x.len()];
                let st = run(Some(&mut no_energy), false);
                assert_eq!(st.inverted, reference.inverted);
                assert_eq!(bits(&no_energy), bits(&want));
                let st = run(None, true);
                assert_eq!(st.energy.to_bits(), reference.energy.to_bits());
                assert_eq!(st.inverted, reference.inverted);
                compared += 1;
            }
        }
        println!("{compared} lane-kernel evaluations bitwise equal to the scalar kernel (AVX2 available: {})", modesuite_engine::simd::have_avx2());
    }
}
