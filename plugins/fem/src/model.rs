//! Immutable compiled data of one elastic solid: rest geometry, element quadrature data, lumped
//! masses, sparsity pattern and the element kernel (energy, gradient, projected Hessian).

use crate::element::{barycentric_gradients, shape_gradients, QuadraticMesh, NQ, QUAD_POINTS};
use crate::error::FemError;
use crate::material::{project_psd, Material, StableNeoHookean};
use crate::sparse::BlockPattern;
use nalgebra::{Matrix3, SMatrix, Vector3};

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
    /// Rest volume of each element (m^3).
    pub volume: Vec<f64>,
    /// Node-block sparsity pattern of the stiffness matrix.
    pub pattern: BlockPattern,
    /// Block index of local pair `(a, b)` of each element: `[element * 100 + 10 a + b]`.
    pub elem_blocks: Vec<u32>,
    /// Reverse Cuthill-McKee node order (`order[new] = old`) for the Cholesky factor.
    pub order: Vec<u32>,
    /// Boundary nodes (corners and edge nodes of boundary faces), sorted.
    pub surface_nodes: Vec<u32>,
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
        let order = pattern.rcm();
        let surface_nodes = mesh.boundary_nodes();
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
            volume,
            pattern,
            elem_blocks,
            order,
            surface_nodes,
            length_scale,
        })
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
        let el = &self.mesh.elements[e];
        let g = &self.qp_grad[e * NQ + q];
        let mut f = Matrix3::zeros();
        for a in 0..10 {
            f += x[el[a] as usize] * g[a].transpose();
        }
        f
    }

    /// Elastic energy only (J) and inverted quadrature-point count.
    pub fn energy_only(&self, x: &[Vector3<f64>]) -> KernelStats {
        let mut s = KernelStats::default();
        for e in 0..self.n_elements() {
            for q in 0..NQ {
                let f = self.deformation_gradient(e, q, x);
                if f.determinant() <= 0.0 {
                    s.inverted += 1;
                }
                s.energy += self.qp_weight[e * NQ + q] * self.energy.energy(&f);
            }
        }
        s
    }

    /// Elastic energy, gradient `dPsi/dx` (N, written into `grad`) and, if `hess` is given, the
    /// stiffness matrix (block values overwritten); with `project`, each quadrature point's
    /// `dP/dF` is first made positive semi-definite ([`project_psd`]).
    pub fn eval(
        &self,
        x: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        mut hess: Option<&mut [Matrix3<f64>]>,
        project: bool,
    ) -> KernelStats {
        grad.iter_mut().for_each(|g| *g = Vector3::zeros());
        if let Some(h) = hess.as_deref_mut() {
            h.iter_mut().for_each(|b| *b = Matrix3::zeros());
        }
        let mut s = KernelStats::default();
        for (e, el) in self.mesh.elements.iter().enumerate() {
            let xe = el.map(|n| x[n as usize]);
            let mut ge = [Vector3::<f64>::zeros(); 10];
            let mut ke = [[Matrix3::<f64>::zeros(); 10]; 10];
            for q in 0..NQ {
                let g = &self.qp_grad[e * NQ + q];
                let w = self.qp_weight[e * NQ + q];
                let mut f = Matrix3::zeros();
                for a in 0..10 {
                    f += xe[a] * g[a].transpose();
                }
                if f.determinant() <= 0.0 {
                    s.inverted += 1;
                }
                if hess.is_some() {
                    let (psi, p, h) = self.energy.eval(&f);
                    s.energy += w * psi;
                    let h = if project { project_psd(&h) * w } else { h * w };
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
                } else {
                    s.energy += w * self.energy.energy(&f);
                    let p = self.energy.pk1(&f);
                    for a in 0..10 {
                        ge[a] += p * g[a] * w;
                    }
                }
            }
            for a in 0..10 {
                grad[el[a] as usize] += ge[a];
            }
            if let Some(h) = hess.as_deref_mut() {
                let map = &self.elem_blocks[e * 100..e * 100 + 100];
                for a in 0..10 {
                    for b in a..10 {
                        let blk = ke[a][b];
                        h[map[10 * a + b] as usize] += blk;
                        if b != a {
                            h[map[10 * b + a] as usize] += blk.transpose();
                        }
                    }
                }
            }
        }
        s
    }
}
