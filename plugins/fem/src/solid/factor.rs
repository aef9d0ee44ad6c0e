//! The factored system matrix: the preconditioner / chord matrix `c_mass M + c_stiff K +
//! grasp springs` with constraints eliminated or penalised and contacts as stiff penalties,
//! cached by key.

use super::{quantised_normal, ConKind, FactorContact, FemSolid};
use crate::error::FemError;
use crate::precond::{entries, plan, ContactFactor, Penalty, Plan, Solved};
use crate::sparse::ProfileCholesky;
use nalgebra::{Matrix3, Vector3};

impl FemSolid {
    /// Factors `c_mass M + c_stiff K(x_ref) + grasp springs` with full constraints eliminated and
    /// partial ones penalised, if the cached factor does not match.
    pub(super) fn ensure_precond(&mut self, c_mass: f64, c_stiff: f64) -> Result<usize, FemError> {
        let c_stiff = c_stiff * self.stiffness_scale;
        // active contacts enter the factor as stiff penalties along their normals, quantised to
        // 1e-2 so that a resting contact set reuses the factor; the factor is a pure function of
        // the key and the preconditioner shape (deterministic after snapshot restore)
        // (penalty contacts enter with their Hessian at the step's predicted positions)
        let mut contacts: Vec<FactorContact> = self
            .active
            .iter()
            .filter(|c| matches!(c.kind, ConKind::Contact))
            .map(|c| {
                (
                    c.node,
                    quantised_normal(&c.normal),
                    c.proj[(0, 0)] == 1.0 && c.proj[(1, 1)] == 1.0,
                    None,
                )
            })
            .collect();
        contacts.extend_from_slice(&self.penalty_factor);
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for (node, n, stick, k) in &contacts {
            for w in [
                *node as u64,
                n.x.to_bits(),
                n.y.to_bits(),
                n.z.to_bits(),
                *stick as u64,
                k.map_or(u64::MAX, f64::to_bits),
            ] {
                h = (h ^ w).wrapping_mul(0x0100_0000_01b3);
            }
        }
        let key = [
            c_mass.to_bits(),
            c_stiff.to_bits(),
            self.constraint_version,
            h,
        ];
        if let Some((k, _)) = &self.precond {
            if *k == key {
                return Ok(0);
            }
        }
        let mat_key = [
            c_mass.to_bits(),
            c_stiff.to_bits(),
            self.constraint_version,
            self.precond_gen,
        ];
        let previous = self.precond.take();
        if self.precond_mat_key == Some(mat_key) {
            // only the contacts changed: the matrix without them is the one built last time,
            // and the last factor's base is this matrix's with the current anchor
            let base = previous.map(|(_, f)| f.into_base());
            if let Ok((f, k)) = self.contact_factor(base, &contacts) {
                self.precond = Some((key, f));
                return Ok(k);
            }
            // not positive definite with these penalties: rebuild the matrix below (projected
            // where the first try fails)
        }
        self.precond_mat_key = None;
        let x_ref = self
            .precond_at
            .clone()
            .unwrap_or_else(|| self.model.mesh.rest.clone());
        // the last matrix's buffer (`eval` overwrites every block) instead of a fresh one
        let mut vals = std::mem::take(&mut self.precond_mat);
        vals.resize(self.model.pattern.cols.len(), Matrix3::zeros());
        let mut g = vec![Vector3::zeros(); self.n_nodes()];
        // at the rest shape unprojected (exact there); at a deformed reference shape projected
        // (ARCHITECTURE.md: an unprojected tangent in compression was nearly singular and gave
        // metre-long steps); projected if the unprojected one is not positive definite
        let mut out = Err(FemError::NotPositiveDefinite(String::new()));
        for project in [self.precond_at.is_some(), true] {
            self.model
                .eval(&x_ref, &mut g, Some(&mut vals), project, None);
            self.system_matrix(&mut vals, c_mass, c_stiff);
            self.precond_mat = vals;
            out = self.contact_factor(None, &contacts);
            vals = std::mem::take(&mut self.precond_mat);
            if out.is_ok() {
                break;
            }
        }
        let (f, k) = out?;
        self.precond = Some((key, f));
        self.precond_mat = vals;
        self.precond_mat_key = Some(mat_key);
        Ok(k)
    }

    /// Factors the system matrix `precond_mat` with the contacts' stiff penalties (their own
    /// stiffness, or `1e6` times the norm of the node's diagonal block, along the normal; all
    /// three directions when sticking): the factor of the matrix with the anchor's penalties
    /// (`factor_anchor`), corrected by the difference to these, or, where that costs more than
    /// a factorisation ([`plan`]), a new factor with these as the anchor. `base` is the last
    /// factor's base when the matrix is the same and reused if the anchor stays.
    fn contact_factor(
        &mut self,
        base: Option<(ProfileCholesky, Solved)>,
        contacts: &[FactorContact],
    ) -> Result<(ContactFactor, usize), FemError> {
        let pat = &self.model.pattern;
        let vals = &self.precond_mat;
        let penalties: Vec<Penalty> = contacts
            .iter()
            .map(|&(node, n, stick, k)| {
                let scale = vals[pat.diag[node as usize] as usize].norm().max(1e-300);
                let n = n.try_normalize(1e-12).unwrap_or(Vector3::z());
                (node, n, stick, k.unwrap_or(1e6 * scale))
            })
            .collect();
        let new = entries(&penalties);
        let factor = |m: &[Matrix3<f64>], blocks: &[(usize, Matrix3<f64>)]| {
            ProfileCholesky::factor(&self.model.profile, pat, m, blocks)
        };
        // the anchor's factor may fail (a state file's anchor), S may be singular or not
        // finite: either way the set becomes the anchor, deterministically
        let mut tried = 0;
        if let Plan::Keep(delta) = plan(
            &self.factor_anchor,
            &new,
            self.n_nodes(),
            self.profile_costs,
        ) {
            match ContactFactor::new(base, vals, &pat.diag, &self.factor_anchor, &delta, factor) {
                Ok((Some(f), k)) => return Ok((f, k)),
                Ok((None, k)) => tried = k,
                Err(_) => {}
            }
        }
        let (f, k) = ContactFactor::new(None, vals, &pat.diag, &new, &[], factor)?;
        self.factor_anchor = new;
        Ok((f.expect("no correction to refuse"), tried + k))
    }

    /// Turns the scaled elastic Hessian in `vals` into the system matrix without contacts:
    /// stiffness scaled by `c_stiff`, masses by `c_mass`, grasp springs, full constraints
    /// eliminated and partial ones penalised, and a tiny regularisation.
    fn system_matrix(&self, vals: &mut [Matrix3<f64>], c_mass: f64, c_stiff: f64) {
        for v in vals.iter_mut() {
            *v *= c_stiff;
        }
        let pat = &self.model.pattern;
        for i in 0..self.n_nodes() {
            vals[pat.diag[i] as usize] += Matrix3::identity() * (c_mass * self.model.mass[i]);
        }
        for gr in &self.grasps {
            for &n in &gr.nodes {
                vals[pat.diag[n as usize] as usize] += Matrix3::identity() * gr.params.stiffness;
            }
        }
        let full = self.full_constrained();
        for i in 0..self.n_nodes() {
            for k in pat.row_ptr[i] as usize..pat.row_ptr[i + 1] as usize {
                let j = pat.cols[k] as usize;
                if full[i] || full[j] {
                    vals[k] = if i == j {
                        Matrix3::identity()
                    } else {
                        Matrix3::zeros()
                    };
                }
            }
        }
        for w in &self.world {
            if !full[w.node as usize] {
                let d = pat.diag[w.node as usize] as usize;
                let scale = vals[d].norm().max(1e-300);
                vals[d] += w.proj * (1e6 * scale);
            }
        }
        // tiny regularisation keeps statics with roller-only supports factorable
        let mean_diag = (0..self.n_nodes())
            .map(|i| vals[pat.diag[i] as usize].trace())
            .sum::<f64>()
            / (3 * self.n_nodes()) as f64;
        for i in 0..self.n_nodes() {
            vals[pat.diag[i] as usize] += Matrix3::identity() * (1e-10 * mean_diag);
        }
    }
}
