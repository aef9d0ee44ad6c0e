//! The chord solver's factored matrix with contacts: the system matrix `A` (mass, stiffness at
//! the reference shape, grasp springs, constraints) plus a stiff penalty `k` along each active
//! contact's normal (all three directions for a sticking contact).
//!
//! The contact set changes from one active-set round to the next (a contact starts sliding, a
//! node touches down) while `A` stays the same. The penalties are kept as **entries**, one per
//! penalised direction (a node, a unit direction `d` and a stiffness `k`: `k d d^T` on the
//! node's block; a sticking contact gives three, along the axes, a sliding one its normal). A
//! factor is made of `A` plus the entries of an **anchor** set (the solid's `factor_anchor`,
//! part of its state) and the current set differs from the anchor by a few entries, added or
//! removed: a low-rank change `U C U^T` (`r` columns, `C` the signed stiffnesses), and the
//! Sherman-Morrison-Woodbury identity
//! `(B + U C U^T)^-1 = B^-1 - W S^-1 W^T`, with `W = B^-1 U` and `S = C^-1 + U^T W`
//! (`B` the anchor's matrix; `S` is indefinite when entries are removed: LU), needs `r` solves
//! with the anchor's factor instead of a new factorisation. When the difference costs more
//! than a factorisation ([`plan`], a pure function of the two sets and the profile's costs, so
//! a restored state chooses as the uninterrupted run did), the current set becomes the anchor.
//!
//! A resting body whose contacts flicker between sticking and sliding from round to round (a
//! box on a belt lying on the ground: 1 to 37 of 369 contacts flip each round) was refactored
//! 4-5 times a step; with the anchor, its rounds solve a few cached columns instead.
//! Removing an entry cancels: `S`'s diagonal is `-1/k + d^T B^-1 d`, two numbers equal to
//! about 1e-6 relative for the penalties of 1e6 times the diagonal, so the correction loses
//! about six digits (3e-11 relative in the unit test, whose tolerance is 1e-7). The factor only preconditions the chord's conjugate
//! gradients, which converge to their tolerance either way.

use crate::error::FemError;
use crate::sparse::ProfileCholesky;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// One contact penalty: node, unit normal, sticking (all three directions), penalty stiffness.
pub(crate) type Penalty = (u32, Vector3<f64>, bool, f64);

/// One penalised direction: node, unit direction, stiffness (`k d d^T` on the node's block).
pub(crate) type Entry = (u32, Vector3<f64>, f64);

/// Columns `B^-1 u` solved with an anchor's factor, each with its `u` (a node and a unit
/// direction): handed on with the factor to the next contact set's, which reuses those it
/// needs again.
pub(crate) type Solved = Vec<((u32, Vector3<f64>), Vec<Vector3<f64>>)>;

/// Solves applied with one low-rank correction per round, for the cost comparison.
const SOLVES_PER_ROUND: f64 = 8.0;

/// The share of a correction's columns the cost comparison counts as new solves (the rest were
/// solved for earlier sets on the same anchor). Not measured per call: the choice must not
/// depend on what a cache holds, so that a restored state chooses as the uninterrupted run.
const NEW_COLUMN_SHARE: f64 = 0.25;

/// Columns kept for reuse on one anchor (each `n` blocks); beyond, only the current
/// correction's are kept.
const MAX_SOLVED: usize = 256;

/// The penalties as entries, in their order: a sticking contact's axes x, y, z, a sliding
/// contact's normal.
pub(crate) fn entries(penalties: &[Penalty]) -> Vec<Entry> {
    let mut out = Vec::with_capacity(penalties.len());
    for &(node, n, stick, k) in penalties {
        if stick {
            for d in [Vector3::x(), Vector3::y(), Vector3::z()] {
                out.push((node, d, k));
            }
        } else {
            out.push((node, n, k));
        }
    }
    out
}

/// The bits a column is known by: its node and its direction's bits.
type ColumnBits = (u32, [u64; 3]);

/// The bits an entry's column is known by (node and direction).
fn column_bits(node: u32, d: &Vector3<f64>) -> ColumnBits {
    (node, [d.x.to_bits(), d.y.to_bits(), d.z.to_bits()])
}

/// `new - anchor` by column: each node and direction with its net stiffness (added minus
/// removed, summed in the sets' orders), the zero ones left out, sorted by node and direction
/// bits.
pub(crate) fn difference(anchor: &[Entry], new: &[Entry]) -> Vec<Entry> {
    let mut all: Vec<(ColumnBits, usize, Vector3<f64>, f64)> = anchor
        .iter()
        .enumerate()
        .map(|(i, e)| (column_bits(e.0, &e.1), i, e.1, -e.2))
        .chain(
            new.iter()
                .enumerate()
                .map(|(i, e)| (column_bits(e.0, &e.1), anchor.len() + i, e.1, e.2)),
        )
        .collect();
    all.sort_unstable_by_key(|x| (x.0, x.1));
    let mut out: Vec<Entry> = Vec::new();
    let mut last: Option<ColumnBits> = None;
    for (bits, _, d, k) in all {
        match out.last_mut() {
            Some(e) if last == Some(bits) => e.2 += k,
            _ => out.push((bits.0, d, k)),
        }
        last = Some(bits);
    }
    out.retain(|e| e.2 != 0.0);
    out
}

/// What the next factor is made of.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Plan {
    /// The anchor's factor corrected by these entries (signed stiffnesses; none: the anchor's
    /// factor alone).
    Keep(Vec<Entry>),
    /// A new factor with the current set as the anchor.
    Reanchor,
}

/// Keep the anchor when correcting its factor by the difference costs less than a
/// factorisation (`costs`: flops of one factorisation and of one solve; `n` nodes).
pub(crate) fn plan(anchor: &[Entry], new: &[Entry], n: usize, costs: (f64, f64)) -> Plan {
    let delta = difference(anchor, new);
    let (factor_cost, solve_cost) = costs;
    let r = delta.len() as f64;
    // new columns' solves, the r x r LU, the corrections of a round's solves
    let cost = NEW_COLUMN_SHARE * r * solve_cost
        + 2.0 * r * r * r / 3.0
        + SOLVES_PER_ROUND * (12.0 * r * n as f64 + 2.0 * r * r);
    if cost < factor_cost {
        Plan::Keep(delta)
    } else {
        Plan::Reanchor
    }
}

/// The anchor's entries as replaced diagonal blocks of `a` (block index, `a`'s block plus the
/// entries' `k d d^T`, summed in the entries' order), sorted by block.
pub(crate) fn anchor_blocks(
    a: &[Matrix3<f64>],
    diag: &[u32],
    anchor: &[Entry],
) -> Vec<(usize, Matrix3<f64>)> {
    let mut blocks: Vec<(usize, Matrix3<f64>)> = Vec::with_capacity(anchor.len());
    for &(node, d, k) in anchor {
        let b = diag[node as usize] as usize;
        let i = match blocks.iter().position(|x| x.0 == b) {
            Some(i) => i,
            None => {
                blocks.push((b, a[b]));
                blocks.len() - 1
            }
        };
        blocks[i].1 += d * d.transpose() * k;
    }
    blocks.sort_unstable_by_key(|b| b.0);
    blocks
}

/// The Woodbury correction of an anchor's factor.
#[derive(Clone, Debug)]
struct Correction {
    /// Columns of `U`: a node and a unit direction.
    cols: Vec<(u32, Vector3<f64>)>,
    /// `W = B^-1 U`: each column's index in the factor's `solved`.
    idx: Vec<usize>,
    /// LU factors of `S = C^-1 + U^T W`.
    s: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
}

/// Factor of `A` plus the contact penalties (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct ContactFactor {
    /// Factor of `A` plus the anchor's entries.
    base: ProfileCholesky,
    /// Columns solved with `base` for this and earlier corrections.
    solved: Solved,
    /// `None`: the contacts are the anchor's.
    correction: Option<Correction>,
}

impl ContactFactor {
    /// The factor of `a` (the block values of `A`; `diag[i]` is node `i`'s diagonal block)
    /// plus the `anchor`'s entries, corrected by `delta` (signed, from [`plan`]); `base` is an
    /// earlier factor of the same `a` and anchor (from [`ContactFactor::into_base`]), reused
    /// with its columns when given. `factor` factors block values with some diagonal blocks
    /// replaced (see [`ProfileCholesky::factor`]). Returns the factor and the number of
    /// factorisations done. A correction whose `S` is not finite or has a zero pivot is refused
    /// (`None`): the caller makes the set the anchor instead. (A nearly singular `S`, or one
    /// whose inertia says the corrected matrix is indefinite, is not detected.)
    pub(crate) fn new(
        base: Option<(ProfileCholesky, Solved)>,
        a: &[Matrix3<f64>],
        diag: &[u32],
        anchor: &[Entry],
        delta: &[Entry],
        factor: impl Fn(&[Matrix3<f64>], &[(usize, Matrix3<f64>)]) -> Result<ProfileCholesky, FemError>,
    ) -> Result<(Option<Self>, usize), FemError> {
        let n = diag.len();
        let (mut b, mut solved, factored) = match base {
            Some((b, s)) => (b, s, 0),
            None => (factor(a, &anchor_blocks(a, diag, anchor))?, Vec::new(), 1),
        };
        if delta.is_empty() {
            let me = ContactFactor {
                base: b,
                solved,
                correction: None,
            };
            return Ok((Some(me), factored));
        }
        let r = delta.len();
        // each column's index in `solved`: the same column of the same factor (direction
        // compared bit by bit) is the same bits as solving it again
        let mut idx = Vec::with_capacity(r);
        for &(node, d, _) in delta {
            let bits = column_bits(node, &d);
            if let Some(i) = solved
                .iter()
                .position(|((m, u), _)| column_bits(*m, u) == bits)
            {
                idx.push(i);
                continue;
            }
            let mut e = vec![Vector3::zeros(); n];
            e[node as usize] = d;
            b.solve_in_place(&mut e);
            solved.push(((node, d), e));
            idx.push(solved.len() - 1);
        }
        let col = |j: usize| &solved[idx[j]].1;
        let s = DMatrix::from_fn(r, r, |i, j| {
            let (ni, di, ki) = delta[i];
            let (nj, dj, _) = delta[j];
            // symmetric by construction: the mean of the two equal products
            let v = 0.5 * (di.dot(&col(j)[ni as usize]) + dj.dot(&col(i)[nj as usize]));
            if i == j {
                v + 1.0 / ki
            } else {
                v
            }
        });
        if !s.iter().all(|v| v.is_finite()) {
            return Ok((None, factored));
        }
        let lu = s.lu();
        if !lu.is_invertible() {
            return Ok((None, factored));
        }
        if solved.len() > MAX_SOLVED {
            // keep this correction's columns only (a cache: the bits do not depend on it)
            let mut kept: Solved = Vec::with_capacity(r);
            for i in &mut idx {
                let c = std::mem::take(&mut solved[*i].1);
                kept.push((solved[*i].0, c));
                *i = kept.len() - 1;
            }
            solved = kept;
        }
        let cols = delta.iter().map(|&(node, d, _)| (node, d)).collect();
        let me = ContactFactor {
            base: b,
            solved,
            correction: Some(Correction { cols, idx, s: lu }),
        };
        Ok((Some(me), factored))
    }

    /// The anchor's factor and the columns solved with it, handed on to the next contact set's
    /// factor on the same matrix and anchor.
    pub(crate) fn into_base(self) -> (ProfileCholesky, Solved) {
        (self.base, self.solved)
    }

    /// Whether the contacts are a low-rank correction of the anchor's factor (tests).
    #[cfg(test)]
    pub(crate) fn is_low_rank(&self) -> bool {
        self.correction.is_some()
    }

    /// `z <- (B + U C U^T)^-1 z`.
    pub(crate) fn solve_in_place(&mut self, z: &mut [Vector3<f64>]) {
        self.base.solve_in_place(z);
        if let Some(Correction { cols, idx, s }) = &self.correction {
            let t = DVector::from_iterator(
                cols.len(),
                cols.iter().map(|(node, d)| d.dot(&z[*node as usize])),
            );
            let y = s.solve(&t).expect("an invertible S (checked when built)");
            for (&j, yj) in idx.iter().zip(y.iter()) {
                let wj = &self.solved[j].1;
                for (zi, wi) in z.iter_mut().zip(wj) {
                    *zi -= wi * *yj;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse::tests::banded;

    fn max_diff(x: &[Vector3<f64>], y: &[Vector3<f64>]) -> (f64, f64) {
        let scale = y.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let diff = x
            .iter()
            .zip(y)
            .map(|(a, b)| (a - b).amax())
            .fold(0.0, f64::max);
        (diff, scale)
    }

    fn bitwise(x: &[Vector3<f64>], y: &[Vector3<f64>]) -> bool {
        x.iter().zip(y).all(|(a, b)| {
            a.iter()
                .zip(b.iter())
                .all(|(p, q)| p.to_bits() == q.to_bits())
        })
    }

    #[test]
    fn an_anchor_corrected_by_added_and_removed_contacts_solves_like_a_fresh_factor() {
        let (pat, a) = banded(40);
        let profile = std::sync::Arc::new(crate::sparse::Profile::new(&pat, &pat.rcm()));
        let factor = |m: &[Matrix3<f64>], blocks: &[(usize, Matrix3<f64>)]| {
            ProfileCholesky::factor(&profile, &pat, m, blocks)
        };
        let k = 1e6 * a[pat.diag[0] as usize].norm();
        let anchor = entries(&[
            (7, Vector3::new(0.0, 0.6, 0.8), false, k),
            (21, Vector3::z(), true, 2.0 * k),
            (22, Vector3::x(), false, k),
            (30, Vector3::z(), true, k),
        ]);
        // node 21 slides now (its x and y go), 22 is released, 30 keeps sticking, 35 touches
        let now = entries(&[
            (7, Vector3::new(0.0, 0.6, 0.8), false, k),
            (21, Vector3::z(), false, 2.0 * k),
            (30, Vector3::z(), true, k),
            (35, Vector3::new(0.6, 0.0, 0.8), true, k),
        ]);
        let delta = difference(&anchor, &now);
        let added = delta.iter().filter(|e| e.2 > 0.0).count();
        let removed = delta.iter().filter(|e| e.2 < 0.0).count();
        // 21: -x, -y; 22: -x; 35: +x, +y, +z
        assert_eq!((added, removed), (3, 3), "{delta:?}");
        assert!(difference(&now, &now).is_empty());
        let (corrected, n) =
            ContactFactor::new(None, &a, &pat.diag, &anchor, &delta, factor).unwrap();
        let mut corrected = corrected.unwrap();
        assert!(corrected.is_low_rank());
        assert_eq!(n, 1);
        let (fresh, _) = ContactFactor::new(None, &a, &pat.diag, &now, &[], factor).unwrap();
        let mut fresh = fresh.unwrap();
        assert!(!fresh.is_low_rank());
        let rhs: Vec<Vector3<f64>> = (0..40)
            .map(|i| Vector3::new((i as f64).sin(), 1.0, (0.3 * i as f64).cos()))
            .collect();
        let (mut x_c, mut x_f) = (rhs.clone(), rhs.clone());
        corrected.solve_in_place(&mut x_c);
        fresh.solve_in_place(&mut x_f);
        let (diff, scale) = max_diff(&x_c, &x_f);
        println!(
            "anchor + Woodbury (3 added, 3 removed of penalties 1e6 x the diagonal) vs a fresh factor: largest difference {diff:.2e} of {scale:.2e} (tolerance 1e-7 relative)"
        );
        assert!(diff <= 1e-7 * scale);
        // the released node moves freely again, the new one is held
        assert!(x_f[22].amax() > 1e-3 * scale && x_f[35].amax() < 1e-5 * scale);
        // the next set on the same anchor reuses the factor and the columns it solved: no
        // factorisation, bitwise a fresh correction
        let later = entries(&[
            (7, Vector3::new(0.0, 0.6, 0.8), false, k),
            (21, Vector3::z(), true, 2.0 * k),
            (30, Vector3::z(), true, k),
            (35, Vector3::new(0.6, 0.0, 0.8), true, k),
        ]);
        let delta2 = difference(&anchor, &later);
        let (reused, n) = ContactFactor::new(
            Some(corrected.into_base()),
            &a,
            &pat.diag,
            &anchor,
            &delta2,
            factor,
        )
        .unwrap();
        let (again, _) = ContactFactor::new(None, &a, &pat.diag, &anchor, &delta2, factor).unwrap();
        assert_eq!(n, 0);
        let (mut x_r, mut x_a) = (rhs.clone(), rhs);
        reused.unwrap().solve_in_place(&mut x_r);
        again.unwrap().solve_in_place(&mut x_a);
        assert!(bitwise(&x_r, &x_a));
    }

    #[test]
    fn the_plan_keeps_the_anchor_for_a_few_flips_and_reanchors_for_many() {
        let k = 1e6;
        let anchor: Vec<Entry> = entries(
            &(0..100u32)
                .map(|i| (i, Vector3::z(), true, k))
                .collect::<Vec<_>>(),
        );
        let flip = |m: u32| {
            entries(
                &(0..100u32)
                    .map(|i| (i, Vector3::z(), i >= m, k))
                    .collect::<Vec<_>>(),
            )
        };
        // a factorisation of 38 Mflop and a solve of 1.1 (the belt of box_across_belt)
        let costs = (38e6, 1.1e6);
        assert_eq!(plan(&anchor, &anchor, 1107, costs), Plan::Keep(Vec::new()));
        match plan(&anchor, &flip(5), 1107, costs) {
            Plan::Keep(d) => assert_eq!(d.len(), 10),
            p => panic!("{p:?}"),
        }
        assert_eq!(plan(&anchor, &flip(100), 1107, costs), Plan::Reanchor);
    }
}
