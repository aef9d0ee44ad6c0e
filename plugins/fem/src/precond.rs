//! The chord solver's factored matrix with contacts: the system matrix `A` (mass, stiffness at
//! the reference shape, grasp springs, constraints) plus a stiff penalty `k` along each active
//! contact's normal (all three directions for a sticking contact).
//!
//! The contact set changes from one active-set round to the next (a contact starts sliding, a
//! node touches down) while `A` stays the same. With few contacts the penalties are a low-rank
//! change `U C U^T` of `A` (`r` columns: one per sliding contact, three per sticking one), and
//! the Sherman-Morrison-Woodbury identity
//! `(A + U C U^T)^-1 = A^-1 - W S^-1 W^T`, with `W = A^-1 U` and `S = C^-1 + U^T W`,
//! needs `r` solves with the factor of `A` instead of a new factorisation. Which of the two is
//! cheaper follows from the factor's profile (a pure function of the data, so the choice is
//! deterministic). The two agree to rounding on a well-conditioned matrix (1e-12 in the unit
//! test); with the task scenes' penalties (1e6 times the diagonal) the penalised matrix is
//! ill-conditioned and they differed by up to 4e-7 relative in a Franka Lift episode. The factor
//! only preconditions the chord's conjugate gradients, which converge to the same tolerance
//! either way; the trajectories then differ as any rounding change makes them differ.

use crate::error::FemError;
use crate::sparse::ProfileCholesky;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// How the contact penalties enter.
#[derive(Clone, Debug)]
enum Contacts {
    /// No contacts: the base factor is the whole matrix.
    None,
    /// The matrix with the penalties, factored.
    Full(ProfileCholesky),
    /// Woodbury correction of the base factor.
    LowRank {
        /// Columns of `U`: a node and a unit direction.
        cols: Vec<(u32, Vector3<f64>)>,
        /// `W = A^-1 U`, column by column.
        w: Vec<Vec<Vector3<f64>>>,
        /// Cholesky factor of `S = C^-1 + U^T W`.
        s: nalgebra::Cholesky<f64, nalgebra::Dyn>,
    },
}

/// One contact penalty: node, unit normal, sticking (all three directions), penalty stiffness.
pub(crate) type Penalty = (u32, Vector3<f64>, bool, f64);

/// Columns `A^-1 u` solved with a base factor of `A`, each with its `u` (a node and a unit
/// direction): handed on with the base to the next contact set's factor, which reuses those it
/// needs again (a sticking contact's three axis columns do not depend on its normal).
pub(crate) type Solved = Vec<((u32, Vector3<f64>), Vec<Vector3<f64>>)>;

/// Factor of `A` plus the contact penalties (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct ContactFactor {
    /// Factor of `A` (absent when only the full factor was needed so far).
    base: Option<ProfileCholesky>,
    contacts: Contacts,
}

/// Solves applied with one low-rank correction per round, for the cost comparison.
const SOLVES_PER_ROUND: f64 = 8.0;

impl ContactFactor {
    /// Factors `a` (the block values of `A`; `diag[i]` is node `i`'s diagonal block) with the
    /// `penalties`, reusing `base` (a factor of `A` and columns solved with it) where given.
    /// `factor` factors block values with some diagonal blocks replaced (block index, value;
    /// sorted, see [`ProfileCholesky::factor`]); `costs` are the flops of one factorisation and
    /// of one solve in this profile. Returns the factor and the number of factorisations done.
    /// `contacts_changed` says that `A` was factored before with other contacts: a base factor
    /// is then worth its cost even where this contact set alone would not repay it, as the next
    /// set will reuse it.
    pub(crate) fn new(
        base: Option<(ProfileCholesky, Solved)>,
        contacts_changed: bool,
        a: &[Matrix3<f64>],
        diag: &[u32],
        penalties: &[Penalty],
        (factor_cost, solve_cost): (f64, f64),
        factor: impl Fn(&[Matrix3<f64>], &[(usize, Matrix3<f64>)]) -> Result<ProfileCholesky, FemError>,
    ) -> Result<(Self, usize), FemError> {
        let n = diag.len();
        let rank: usize = penalties.iter().map(|p| if p.2 { 3 } else { 1 }).sum();
        let r = rank as f64;
        // a factorisation against r solves, the r x r system, the corrections of a round's
        // solves, and the base factor itself where there is none yet
        let mut low_rank_cost =
            r * solve_cost + r * r * r / 3.0 + SOLVES_PER_ROUND * (12.0 * r * n as f64 + r * r);
        if base.is_none() && !contacts_changed {
            low_rank_cost += factor_cost;
        }
        let (base, mut solved) = match base {
            Some((b, s)) => (Some(b), s),
            None => (None, Vec::new()),
        };
        let full = |base: Option<ProfileCholesky>| -> Result<(Self, usize), FemError> {
            // the penalised diagonal blocks, summed in the penalties' order (a node may have
            // several), in place of `a`'s in the factorisation: no copy of the matrix
            let mut blocks: Vec<(usize, Matrix3<f64>)> = Vec::with_capacity(penalties.len());
            for &(node, nrm, stick, k) in penalties {
                let proj = if stick {
                    Matrix3::identity()
                } else {
                    nrm * nrm.transpose()
                };
                let d = diag[node as usize] as usize;
                let i = match blocks.iter().position(|b| b.0 == d) {
                    Some(i) => i,
                    None => {
                        blocks.push((d, a[d]));
                        blocks.len() - 1
                    }
                };
                blocks[i].1 += proj * k;
            }
            blocks.sort_unstable_by_key(|b| b.0);
            let contacts = Contacts::Full(factor(a, &blocks)?);
            Ok((ContactFactor { base, contacts }, 1))
        };
        if rank > 0 && low_rank_cost >= factor_cost {
            return full(base);
        }
        let (mut b, factored) = match base {
            Some(b) => (b, 0),
            None => (factor(a, &[])?, 1),
        };
        if rank == 0 {
            let contacts = Contacts::None;
            return Ok((
                ContactFactor {
                    base: Some(b),
                    contacts,
                },
                factored,
            ));
        }
        let mut cols = Vec::with_capacity(rank);
        let mut cinv = Vec::with_capacity(rank);
        for &(node, nrm, stick, k) in penalties {
            if stick {
                for d in [Vector3::x(), Vector3::y(), Vector3::z()] {
                    cols.push((node, d));
                    cinv.push(1.0 / k);
                }
            } else {
                cols.push((node, nrm));
                cinv.push(1.0 / k);
            }
        }
        let mut w = Vec::with_capacity(rank);
        for &(node, d) in &cols {
            // the same column of the same factor (direction compared bit by bit): the same
            // bits as solving it again
            let same = |((m, u), _): &((u32, Vector3<f64>), Vec<Vector3<f64>>)| {
                *m == node
                    && u.iter()
                        .zip(d.iter())
                        .all(|(a, b)| a.to_bits() == b.to_bits())
            };
            if let Some(i) = solved.iter().position(same) {
                w.push(solved.swap_remove(i).1);
                continue;
            }
            let mut e = vec![Vector3::zeros(); n];
            e[node as usize] = d;
            b.solve_in_place(&mut e);
            w.push(e);
        }
        let s = DMatrix::from_fn(rank, rank, |i, j| {
            let (ni, di) = cols[i];
            let (nj, dj) = cols[j];
            // symmetric by construction: the mean of the two equal products
            let v = 0.5 * (di.dot(&w[j][ni as usize]) + dj.dot(&w[i][nj as usize]));
            if i == j {
                v + cinv[i]
            } else {
                v
            }
        });
        match nalgebra::Cholesky::new(s) {
            Some(s) => {
                let contacts = Contacts::LowRank { cols, w, s };
                let me = ContactFactor {
                    base: Some(b),
                    contacts,
                };
                Ok((me, factored))
            }
            None => full(Some(b)).map(|(f, k)| (f, k + factored)),
        }
    }

    /// The base factor and the columns solved with it, handed on to the next contact set's
    /// factor.
    pub(crate) fn into_base(self) -> Option<(ProfileCholesky, Solved)> {
        let solved = match self.contacts {
            Contacts::LowRank { cols, w, .. } => cols.into_iter().zip(w).collect(),
            Contacts::None | Contacts::Full(_) => Vec::new(),
        };
        self.base.map(|b| (b, solved))
    }

    /// Whether the contacts are a low-rank correction (tests).
    #[cfg(test)]
    pub(crate) fn is_low_rank(&self) -> bool {
        matches!(self.contacts, Contacts::LowRank { .. })
    }

    /// `z <- (A + U C U^T)^-1 z`.
    pub(crate) fn solve_in_place(&mut self, z: &mut [Vector3<f64>]) {
        match &mut self.contacts {
            Contacts::Full(f) => f.solve_in_place(z),
            Contacts::None => self
                .base
                .as_mut()
                .expect("a contact-free factor keeps its base")
                .solve_in_place(z),
            Contacts::LowRank { cols, w, s } => {
                self.base
                    .as_mut()
                    .expect("a low-rank factor keeps its base")
                    .solve_in_place(z);
                let t = DVector::from_iterator(
                    cols.len(),
                    cols.iter().map(|(node, d)| d.dot(&z[*node as usize])),
                );
                let y = s.solve(&t);
                for (wj, yj) in w.iter().zip(y.iter()) {
                    for (zi, wi) in z.iter_mut().zip(wj) {
                        *zi -= wi * *yj;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse::tests::banded;

    #[test]
    fn low_rank_contacts_solve_like_the_factored_penalties() {
        let (pat, a) = banded(40);
        let profile = std::sync::Arc::new(crate::sparse::Profile::new(&pat, &pat.rcm()));
        let factor = |m: &[Matrix3<f64>], blocks: &[(usize, Matrix3<f64>)]| {
            ProfileCholesky::factor(&profile, &pat, m, blocks)
        };
        let k = 1e6 * a[pat.diag[0] as usize].norm();
        let penalties: Vec<Penalty> = vec![
            (7, Vector3::new(0.0, 0.6, 0.8), false, k),
            (21, Vector3::z(), true, 2.0 * k),
            (22, Vector3::new(1.0, 0.0, 0.0), false, k),
        ];
        // costs that force each way (a base factor is made when the contacts changed)
        let (mut low, n_low) =
            ContactFactor::new(None, true, &a, &pat.diag, &penalties, (1e12, 1.0), factor).unwrap();
        let (mut full, n_full) =
            ContactFactor::new(None, false, &a, &pat.diag, &penalties, (0.0, 1.0), factor).unwrap();
        assert!(low.is_low_rank() && !full.is_low_rank());
        assert_eq!((n_low, n_full), (1, 1));
        let rhs: Vec<Vector3<f64>> = (0..40)
            .map(|i| Vector3::new((i as f64).sin(), 1.0, (0.3 * i as f64).cos()))
            .collect();
        let (mut x_low, mut x_full) = (rhs.clone(), rhs);
        low.solve_in_place(&mut x_low);
        full.solve_in_place(&mut x_full);
        let scale = x_full.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let diff = x_low
            .iter()
            .zip(&x_full)
            .map(|(a, b)| (a - b).amax())
            .fold(0.0, f64::max);
        println!("Woodbury vs factored penalties: largest difference {diff:.2e} of {scale:.2e} (tolerance 1e-9 relative)");
        assert!(diff <= 1e-9 * scale);
        // the penalised directions are (nearly) held: the solution's component along them is
        // about 1/k of the rest
        assert!(x_low[21].amax() < 1e-5 * scale);
        // a new contact set on the same matrix reuses the base factor and the columns it solved
        // before (the sticking contact's axes whatever its normal): bitwise a fresh solve
        let turned: Vec<Penalty> = vec![
            (21, Vector3::new(0.0, 0.6, 0.8), true, 2.0 * k),
            (30, Vector3::x(), false, k),
        ];
        let (mut reused, n) = ContactFactor::new(
            low.clone().into_base(),
            true,
            &a,
            &pat.diag,
            &turned,
            (1e12, 1.0),
            factor,
        )
        .unwrap();
        let (mut fresh, _) =
            ContactFactor::new(None, true, &a, &pat.diag, &turned, (1e12, 1.0), factor).unwrap();
        assert!(reused.is_low_rank() && fresh.is_low_rank());
        assert_eq!(n, 0);
        let (mut x_reused, mut x_fresh) = (x_low.clone(), x_low.clone());
        reused.solve_in_place(&mut x_reused);
        fresh.solve_in_place(&mut x_fresh);
        assert!(x_reused.iter().zip(&x_fresh).all(|(a, b)| a
            .iter()
            .zip(b.iter())
            .all(|(p, q)| p.to_bits() == q.to_bits())));
        // a new contact set on the same matrix reuses the base factor: no factorisation
        let base = low.into_base();
        let (again, n) = ContactFactor::new(
            base,
            true,
            &a,
            &pat.diag,
            &penalties[..1],
            (1e12, 1.0),
            factor,
        )
        .unwrap();
        assert!(again.is_low_rank());
        assert_eq!(n, 0);
        // no contacts: the base factor alone
        let (none, n) = ContactFactor::new(
            again.into_base(),
            true,
            &a,
            &pat.diag,
            &[],
            (1e12, 1.0),
            factor,
        )
        .unwrap();
        assert!(!none.is_low_rank());
        assert_eq!(n, 0);
    }
}
