//! Sparse linear algebra written for the FEM solver: a 3x3 block-CSR symmetric matrix, reverse
//! Cuthill-McKee node ordering, a profile (envelope) Cholesky factorisation and a filtered
//! preconditioned conjugate gradient (Baraff & Witkin 1998, "Large steps in cloth simulation",
//! sec. 5.3: constrained directions are projected out of residual and search directions).
//!
//! Why profile Cholesky: the solids are rods and belts, long and thin; after RCM their envelope is
//! a narrow band whose width is one cross-section slab, so the envelope factor has no wasted fill
//! for these shapes and its rows are contiguous (fast dot products). It is computed once for the
//! rest state and reused as the PCG preconditioner.

use crate::error::FemError;
use modesuite_engine::simd::Simd;
use nalgebra::{Matrix3, Vector3};
use std::sync::Arc;

/// Sparsity pattern of a symmetric 3x3 block matrix over nodes (both triangles stored).
#[derive(Clone, Debug)]
pub struct BlockPattern {
    /// Row start offsets into `cols`, length `n_rows + 1`.
    pub row_ptr: Vec<u32>,
    /// Column (node) index of each stored block, sorted within a row.
    pub cols: Vec<u32>,
    /// Index of the diagonal block of each row.
    pub diag: Vec<u32>,
}

impl BlockPattern {
    /// Pattern of the union of the dense node cliques `groups` over `n` nodes.
    pub fn from_cliques<'a>(n: usize, groups: impl Iterator<Item = &'a [u32]> + Clone) -> Self {
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for g in groups {
            for &a in g {
                for &b in g {
                    pairs.push((a, b));
                }
            }
        }
        for i in 0..n as u32 {
            pairs.push((i, i));
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut row_ptr = vec![0u32; n + 1];
        for &(r, _) in &pairs {
            row_ptr[r as usize + 1] += 1;
        }
        for i in 0..n {
            row_ptr[i + 1] += row_ptr[i];
        }
        let cols: Vec<u32> = pairs.iter().map(|p| p.1).collect();
        let mut diag = vec![0u32; n];
        for (i, d) in diag.iter_mut().enumerate() {
            let (s, e) = (row_ptr[i] as usize, row_ptr[i + 1] as usize);
            *d = (s + cols[s..e]
                .binary_search(&(i as u32))
                .expect("diagonal present")) as u32;
        }
        BlockPattern {
            row_ptr,
            cols,
            diag,
        }
    }

    /// Number of block rows.
    pub fn n(&self) -> usize {
        self.diag.len()
    }

    /// Index of block `(r, c)` if stored.
    pub fn find(&self, r: u32, c: u32) -> Option<usize> {
        let (s, e) = (
            self.row_ptr[r as usize] as usize,
            self.row_ptr[r as usize + 1] as usize,
        );
        self.cols[s..e].binary_search(&c).ok().map(|k| s + k)
    }

    /// `y = A x` for block values `vals`.
    pub fn spmv(&self, vals: &[Matrix3<f64>], x: &[Vector3<f64>], y: &mut [Vector3<f64>]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let mut acc = Vector3::zeros();
            for k in self.row_ptr[i] as usize..self.row_ptr[i + 1] as usize {
                acc += vals[k] * x[self.cols[k] as usize];
            }
            *yi = acc;
        }
    }

    /// Reverse Cuthill-McKee ordering of the node graph: returns `order[new] = old`.
    /// Deterministic (ties broken by degree, then index); handles disconnected graphs.
    pub fn rcm(&self) -> Vec<u32> {
        let n = self.n();
        let deg: Vec<u32> = (0..n)
            .map(|i| self.row_ptr[i + 1] - self.row_ptr[i])
            .collect();
        let mut visited = vec![false; n];
        let mut order: Vec<u32> = Vec::with_capacity(n);
        let neighbours =
            |i: usize| &self.cols[self.row_ptr[i] as usize..self.row_ptr[i + 1] as usize];
        // BFS levels helper for pseudo-peripheral start
        let bfs_last = |start: usize, visited: &[bool]| -> (usize, usize) {
            let mut level = vec![u32::MAX; n];
            let mut q = std::collections::VecDeque::new();
            level[start] = 0;
            q.push_back(start);
            let mut last = start;
            while let Some(v) = q.pop_front() {
                last = v;
                for &w in neighbours(v) {
                    let w = w as usize;
                    if !visited[w] && level[w] == u32::MAX {
                        level[w] = level[v] + 1;
                        q.push_back(w);
                    }
                }
            }
            (last, level[last] as usize)
        };
        while order.len() < n {
            // lowest-degree unvisited node, then walk to a pseudo-peripheral node
            let mut start = (0..n)
                .filter(|&i| !visited[i])
                .min_by_key(|&i| (deg[i], i))
                .expect("unvisited node");
            let mut ecc = 0;
            for _ in 0..4 {
                let (far, e) = bfs_last(start, &visited);
                if e <= ecc {
                    break;
                }
                ecc = e;
                start = far;
            }
            let first = order.len();
            visited[start] = true;
            order.push(start as u32);
            let mut head = first;
            let mut nb: Vec<u32> = Vec::new();
            while head < order.len() {
                let v = order[head] as usize;
                head += 1;
                nb.clear();
                nb.extend(
                    neighbours(v)
                        .iter()
                        .copied()
                        .filter(|&w| !visited[w as usize]),
                );
                nb.sort_unstable_by_key(|&w| (deg[w as usize], w));
                for &w in &nb {
                    visited[w as usize] = true;
                    order.push(w);
                }
            }
        }
        order.reverse();
        order
    }
}

/// The envelope of a block pattern in a node order: which entries a [`ProfileCholesky`] stores.
/// A pure function of the pattern and the order, so a model computes it once and all its
/// factors (and all environments' copies of a solid) share it.
#[derive(Clone, Debug, PartialEq)]
pub struct Profile {
    /// `perm[new_node] = old_node`.
    perm: Vec<u32>,
    /// `inv[old_node] = new_node`.
    inv: Vec<u32>,
    /// First stored column of each scalar row.
    first: Vec<u32>,
    /// Offset of each scalar row's first entry in the values (`start[n]` is their count).
    start: Vec<usize>,
}

impl Profile {
    /// The envelope of pattern `pat` in node order `perm` (`perm[new] = old`).
    pub fn new(pat: &BlockPattern, perm: &[u32]) -> Self {
        let nn = pat.n();
        let mut inv = vec![0u32; nn];
        for (new, &old) in perm.iter().enumerate() {
            inv[old as usize] = new as u32;
        }
        let n = 3 * nn;
        let mut first_node = vec![u32::MAX; nn];
        for old in 0..nn {
            let ni = inv[old];
            let mut m = ni;
            for k in pat.row_ptr[old] as usize..pat.row_ptr[old + 1] as usize {
                m = m.min(inv[pat.cols[k] as usize]);
            }
            first_node[ni as usize] = m;
        }
        let mut first = vec![0u32; n];
        let mut start = vec![0usize; n + 1];
        for r in 0..n {
            first[r] = 3 * first_node[r / 3];
            start[r + 1] = start[r] + (r + 1 - first[r] as usize);
        }
        Profile {
            perm: perm.to_vec(),
            inv,
            first,
            start,
        }
    }

    /// Flops of one factorisation and of one solve (forward and back substitution) in this
    /// profile: their ratio decides whether a low-rank update beats a new factorisation.
    pub fn costs(&self) -> (f64, f64) {
        let mut factor = 0.0;
        let mut solve = 0.0;
        for (i, &f) in self.first.iter().enumerate() {
            let len = (i - f as usize) as f64;
            factor += len * len;
            solve += 4.0 * len;
        }
        (factor, solve)
    }
}

/// Profile (envelope) Cholesky factor `L L^T` of a symmetric positive definite matrix given as 3x3
/// blocks, in a node ordering; row `i` stores columns `first[i]..=i` contiguously.
#[derive(Clone, Debug)]
pub struct ProfileCholesky {
    /// Node order and envelope (shared with the model's other factors).
    profile: Arc<Profile>,
    /// Factor entries, row by row.
    vals: Vec<f64>,
    /// Reciprocals of the factor's diagonal (multiplications instead of divisions on the
    /// substitutions' dependency chains).
    dinv: Vec<f64>,
    /// Scratch vector (permuted right-hand side).
    work: Vec<f64>,
}

impl ProfileCholesky {
    /// Factors the block matrix `vals` (pattern `pat`) in the node order and envelope of
    /// `profile` (made for `pat`), with the diagonal blocks listed in `diag_blocks` (block
    /// index, value; sorted by index) taking the place of theirs in `vals`: a matrix that differs
    /// from `vals` on a few diagonal blocks (contact penalties) without a copy of it.
    pub fn factor(
        profile: &Arc<Profile>,
        pat: &BlockPattern,
        vals: &[Matrix3<f64>],
        diag_blocks: &[(usize, Matrix3<f64>)],
    ) -> Result<Self, FemError> {
        let nn = pat.n();
        let Profile {
            perm,
            inv,
            first,
            start,
        } = &**profile;
        let n = first.len();
        let mut a = vec![0.0; start[n]];
        for old in 0..nn {
            let ni = inv[old] as usize;
            for k in pat.row_ptr[old] as usize..pat.row_ptr[old + 1] as usize {
                let nj = inv[pat.cols[k] as usize] as usize;
                if nj > ni {
                    continue;
                }
                let b = (nj == ni)
                    .then(|| diag_blocks.binary_search_by_key(&k, |d| d.0).ok())
                    .flatten()
                    .map_or(&vals[k], |i| &diag_blocks[i].1);
                for r in 0..3 {
                    let row = 3 * ni + r;
                    for c in 0..3 {
                        let col = 3 * nj + c;
                        if col <= row {
                            a[start[row] + col - first[row] as usize] = b[(r, c)];
                        }
                    }
                }
            }
        }
        let mut dinv = vec![0.0; n];
        if let Err((i, d)) = kernels::factor(Simd::detect(), &mut a, &mut dinv, first, start) {
            return Err(FemError::NotPositiveDefinite(format!(
                "pivot {d:e} at dof {} of node {}",
                i % 3,
                perm[i / 3]
            )));
        }
        Ok(ProfileCholesky {
            profile: Arc::clone(profile),
            vals: a,
            dinv,
            work: vec![0.0; n],
        })
    }

    /// Number of stored factor entries.
    pub fn nnz(&self) -> usize {
        self.vals.len()
    }

    /// Solves `A x = b` in place (`b` becomes `x`).
    pub fn solve_in_place(&mut self, b: &mut [Vector3<f64>]) {
        let p = &*self.profile;
        for (old, v) in b.iter().enumerate() {
            let ni = p.inv[old] as usize;
            self.work[3 * ni] = v.x;
            self.work[3 * ni + 1] = v.y;
            self.work[3 * ni + 2] = v.z;
        }
        kernels::solve(
            Simd::detect(),
            &mut self.work,
            &self.vals,
            &self.dinv,
            &p.first,
            &p.start,
        );
        let y = &self.work;
        for (new, &old) in p.perm.iter().enumerate() {
            b[old as usize] = Vector3::new(y[3 * new], y[3 * new + 1], y[3 * new + 2]);
        }
    }
}

/// The envelope factorisation and triangular solves. Their inner products are summed in eight
/// interleaved partial sums (lane `k` takes the elements `k`, `k + 8`, ...), added pairwise at
/// the end: a fixed order, so that LLVM can keep the lanes in vector registers and every target
/// gives the same bits. Each kernel is compiled twice, for the build's baseline and with AVX2
/// enabled (chosen at run time); Rust never fuses a multiply and an add, so both copies compute
/// the same numbers (tested).
mod kernels {
    /// `a . b` over the common length, in the fixed eight-lane order.
    #[inline(always)]
    fn dot8(a: &[f64], b: &[f64]) -> f64 {
        let n = a.len().min(b.len());
        let (a, b) = (&a[..n], &b[..n]);
        let mut acc = [0.0f64; 8];
        let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
        let (ra, rb) = (ca.remainder(), cb.remainder());
        for (x, y) in ca.zip(cb) {
            for k in 0..8 {
                acc[k] += x[k] * y[k];
            }
        }
        let mut tail = 0.0;
        for (x, y) in ra.iter().zip(rb) {
            tail += x * y;
        }
        (((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]))) + tail
    }

    /// Row-oriented envelope Cholesky in place, with the reciprocals of the diagonal in `dinv`;
    /// `Err((row, pivot))` at a pivot that is not positive and finite.
    #[inline(always)]
    fn factor_body(
        a: &mut [f64],
        dinv: &mut [f64],
        first: &[u32],
        start: &[usize],
    ) -> Result<(), (usize, f64)> {
        let n = first.len();
        for i in 0..n {
            let fi = first[i] as usize;
            let si = start[i];
            let (done, row_i) = a.split_at_mut(si);
            let row_i = &mut row_i[..i + 1 - fi];
            for j in fi..i {
                let fj = first[j] as usize;
                let sj = start[j];
                let k0 = fi.max(fj);
                let rj = &done[sj + k0 - fj..sj + j - fj];
                let s = row_i[j - fi] - dot8(&row_i[k0 - fi..j - fi], rj);
                row_i[j - fi] = s * dinv[j];
            }
            let (row, diag) = row_i.split_at_mut(i - fi);
            let d = diag[0] - dot8(row, row);
            if d.is_nan() || d <= 0.0 || d.is_infinite() {
                return Err((i, d));
            }
            diag[0] = d.sqrt();
            dinv[i] = 1.0 / diag[0];
        }
        Ok(())
    }

    /// Forward and back substitution with the factor, in place on the permuted vector `y`.
    #[inline(always)]
    fn solve_body(y: &mut [f64], vals: &[f64], dinv: &[f64], first: &[u32], start: &[usize]) {
        let n = y.len();
        for i in 0..n {
            let fi = first[i] as usize;
            let si = start[i];
            let row = &vals[si..si + i - fi];
            let s = dot8(row, &y[fi..i]);
            y[i] = (y[i] - s) * dinv[i];
        }
        for i in (0..n).rev() {
            let fi = first[i] as usize;
            let si = start[i];
            let xi = y[i] * dinv[i];
            y[i] = xi;
            let row = &vals[si..si + i - fi];
            for (yk, l) in y[fi..i].iter_mut().zip(row) {
                *yk -= l * xi;
            }
        }
    }

    modesuite_engine::avx2_dispatch! {
        /// Factors in place (see `factor_body`), with the AVX2 copy where `simd` allows.
        pub(super) fn factor / factor_avx2 => factor_body(
            a: &mut [f64], dinv: &mut [f64], first: &[u32], start: &[usize]
        ) -> Result<(), (usize, f64)>
    }

    modesuite_engine::avx2_dispatch! {
        /// Solves in place (see `solve_body`), with the AVX2 copy where `simd` allows.
        pub(super) fn solve / solve_avx2 => solve_body(
            y: &mut [f64], vals: &[f64], dinv: &[f64], first: &[u32], start: &[usize]
        )
    }
}

/// Dot product of two block vectors (fixed summation order).
#[inline]
pub fn dot(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

/// Result of a conjugate gradient solve.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CgResult {
    /// Iterations taken.
    pub iterations: usize,
    /// Final residual norm relative to the filtered right-hand side.
    pub relative_residual: f64,
    /// A search direction of non-positive curvature was met (the matrix is not positive
    /// definite); `x` then holds the last iterate before it (or the preconditioned residual).
    pub indefinite: bool,
}

/// Filtered preconditioned conjugate gradient for `S A S x = S b` with `x` in the range of `S`
/// (the filter `S` projects out constrained directions, applied in place by `filter`). Starts from
/// `x = 0`. `apply` computes `y = A x`, `precond` applies `z = P^-1 r` in place.
#[allow(clippy::too_many_arguments)]
pub fn pcg(
    mut apply: impl FnMut(&[Vector3<f64>], &mut [Vector3<f64>]),
    mut precond: impl FnMut(&mut [Vector3<f64>]),
    filter: impl Fn(&mut [Vector3<f64>]),
    b: &[Vector3<f64>],
    x: &mut [Vector3<f64>],
    tol: f64,
    max_iter: usize,
    scratch: &mut [Vec<Vector3<f64>>; 3],
) -> CgResult {
    let n = b.len();
    let [r, z, q] = scratch;
    r.clear();
    r.extend_from_slice(b);
    filter(r);
    x.iter_mut().for_each(|v| *v = Vector3::zeros());
    let bnorm = dot(r, r).sqrt();
    if bnorm == 0.0 {
        return CgResult {
            iterations: 0,
            relative_residual: 0.0,
            indefinite: false,
        };
    }
    z.clear();
    z.extend_from_slice(r);
    precond(z);
    filter(z);
    let mut p = z.clone();
    let mut rz = dot(r, z);
    q.resize(n, Vector3::zeros());
    let mut it = 0;
    let mut rel = 1.0;
    let mut indefinite = false;
    while it < max_iter {
        it += 1;
        apply(&p, q);
        filter(q);
        let pq = dot(&p, q);
        if pq.is_nan() || pq <= 0.0 {
            // negative curvature (truncated CG, Steihaug 1983): keep the iterate, which is a
            // descent direction; at the first iteration use the preconditioned residual
            indefinite = true;
            if it == 1 {
                x.copy_from_slice(&p);
            }
            break;
        }
        let alpha = rz / pq;
        for i in 0..n {
            x[i] += p[i] * alpha;
            r[i] -= q[i] * alpha;
        }
        rel = dot(r, r).sqrt() / bnorm;
        if rel <= tol {
            break;
        }
        z.copy_from_slice(r);
        precond(z);
        filter(z);
        let rz_new = dot(r, z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + p[i] * beta;
        }
    }
    CgResult {
        iterations: it,
        relative_residual: rel,
        indefinite,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_block_laplacian() {
        // 1-D chain of 30 nodes with 3x3 coupling, SPD
        let n = 30;
        let groups: Vec<[u32; 2]> = (0..n as u32 - 1).map(|i| [i, i + 1]).collect();
        let pat = BlockPattern::from_cliques(n, groups.iter().map(|g| &g[..]));
        let mut vals = vec![Matrix3::zeros(); pat.cols.len()];
        for g in &groups {
            let c = Matrix3::new(1.0, 0.2, 0.0, 0.2, 2.0, 0.1, 0.0, 0.1, 1.5);
            for (a, b, s) in [
                (g[0], g[0], 1.0),
                (g[1], g[1], 1.0),
                (g[0], g[1], -1.0),
                (g[1], g[0], -1.0),
            ] {
                vals[pat.find(a, b).unwrap()] += c * s;
            }
        }
        for i in 0..n {
            vals[pat.diag[i] as usize] += Matrix3::identity() * 0.01;
        }
        let profile = Arc::new(Profile::new(&pat, &pat.rcm()));
        let mut f = ProfileCholesky::factor(&profile, &pat, &vals, &[]).unwrap();
        let xs: Vec<Vector3<f64>> = (0..n)
            .map(|i| Vector3::new(i as f64, 1.0, -(i as f64).sin()))
            .collect();
        let mut b = vec![Vector3::zeros(); n];
        pat.spmv(&vals, &xs, &mut b);
        f.solve_in_place(&mut b);
        let err = b
            .iter()
            .zip(&xs)
            .map(|(a, c)| (a - c).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-9, "err {err}");
    }

    /// A banded SPD block matrix: cliques of six consecutive nodes (rows of up to 18 entries,
    /// so the eight-lane dot products run full chunks and a tail).
    pub(crate) fn banded(n: usize) -> (BlockPattern, Vec<Matrix3<f64>>) {
        let groups: Vec<Vec<u32>> = (0..n as u32 - 5).map(|i| (i..i + 6).collect()).collect();
        let pat = BlockPattern::from_cliques(n, groups.iter().map(|g| &g[..]));
        let mut vals = vec![Matrix3::zeros(); pat.cols.len()];
        for (gi, g) in groups.iter().enumerate() {
            for &a in g {
                for &b in g {
                    let c = Matrix3::new(
                        1.0,
                        0.1 * (gi % 3) as f64,
                        0.0,
                        0.1 * (gi % 3) as f64,
                        1.5,
                        0.05,
                        0.0,
                        0.05,
                        1.2,
                    );
                    let s = if a == b {
                        5.0
                    } else {
                        -1.0 / (1.0 + a.abs_diff(b) as f64)
                    };
                    vals[pat.find(a, b).unwrap()] += c * s;
                }
            }
        }
        for i in 0..n {
            vals[pat.diag[i] as usize] += Matrix3::identity() * 0.5;
        }
        (pat, vals)
    }

    #[test]
    fn avx2_and_baseline_kernels_give_the_same_bits_and_match_a_plain_cholesky() {
        let (pat, vals) = banded(40);
        let profile = Arc::new(Profile::new(&pat, &pat.rcm()));
        let f = ProfileCholesky::factor(&profile, &pat, &vals, &[]).unwrap();
        let p = &*f.profile;
        let n = p.first.len();
        // the profile's entries before factorisation
        let mut a0 = vec![0.0; f.vals.len()];
        let inv = &p.inv;
        for old in 0..pat.n() {
            let ni = inv[old] as usize;
            for k in pat.row_ptr[old] as usize..pat.row_ptr[old + 1] as usize {
                let nj = inv[pat.cols[k] as usize] as usize;
                for r in 0..3 {
                    for c in 0..3 {
                        let (row, col) = (3 * ni + r, 3 * nj + c);
                        if nj <= ni && col <= row {
                            a0[p.start[row] + col - p.first[row] as usize] = vals[k][(r, c)];
                        }
                    }
                }
            }
        }
        // plain sequential Cholesky of the same profile as the reference
        let mut plain = a0.clone();
        for i in 0..n {
            let fi = p.first[i] as usize;
            for j in fi..=i {
                let fj = p.first[j] as usize;
                let mut s = plain[p.start[i] + j - fi];
                for k in fi.max(fj)..j {
                    s -= plain[p.start[i] + k - fi] * plain[p.start[j] + k - fj];
                }
                plain[p.start[i] + j - fi] = if j == i {
                    s.sqrt()
                } else {
                    s / plain[p.start[j] + j - fj]
                };
            }
        }
        let worst = plain
            .iter()
            .zip(&f.vals)
            .map(|(p, v)| (p - v).abs() / p.abs().max(1.0))
            .fold(0.0, f64::max);
        println!(
            "eight-lane factor vs plain Cholesky: largest difference {worst:.2e} (tolerance 1e-12)"
        );
        assert!(worst < 1e-12);
        let (mut base, mut wide) = (a0.clone(), a0);
        let (mut dbase, mut dwide) = (vec![0.0; n], vec![0.0; n]);
        kernels::factor(Simd::baseline(), &mut base, &mut dbase, &p.first, &p.start).unwrap();
        let simd = Simd::detect();
        kernels::factor(simd, &mut wide, &mut dwide, &p.first, &p.start).unwrap();
        assert!(base
            .iter()
            .zip(&wide)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(dbase
            .iter()
            .zip(&dwide)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        let rhs: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let (mut y0, mut y1) = (rhs.clone(), rhs);
        kernels::solve(Simd::baseline(), &mut y0, &base, &dbase, &p.first, &p.start);
        kernels::solve(simd, &mut y1, &wide, &dwide, &p.first, &p.start);
        assert!(y0.iter().zip(&y1).all(|(a, b)| a.to_bits() == b.to_bits()));
        println!(
            "AVX2 available: {}; both kernels gave the same bits",
            simd.avx2()
        );
    }

    #[test]
    fn replaced_diagonal_blocks_factor_as_the_changed_matrix() {
        let (pat, vals) = banded(40);
        let profile = Arc::new(Profile::new(&pat, &pat.rcm()));
        let bump = |i: usize| Matrix3::new(5.0, 0.5, 0.0, 0.5, 3.0, 0.0, 0.0, 0.0, 1e6 * i as f64);
        let mut changed = vals.clone();
        let mut blocks = Vec::new();
        for node in [3usize, 17, 30] {
            let k = pat.diag[node] as usize;
            changed[k] += bump(node);
            blocks.push((k, changed[k]));
        }
        blocks.sort_by_key(|b| b.0);
        let mut copied = ProfileCholesky::factor(&profile, &pat, &changed, &[]).unwrap();
        let mut replaced = ProfileCholesky::factor(&profile, &pat, &vals, &blocks).unwrap();
        let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same(&copied.vals, &replaced.vals) && same(&copied.dinv, &replaced.dinv));
        let rhs: Vec<Vector3<f64>> = (0..40).map(|i| Vector3::new(1.0, i as f64, -0.5)).collect();
        let (mut x1, mut x2) = (rhs.clone(), rhs);
        copied.solve_in_place(&mut x1);
        replaced.solve_in_place(&mut x2);
        assert!(x1
            .iter()
            .zip(&x2)
            .all(|(a, b)| same(a.as_slice(), b.as_slice())));
    }
}
