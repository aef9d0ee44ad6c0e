//! Working layout of the substep loop and its hot kernels.
//!
//! Inside [`Cloth::step`](crate::Cloth::step) positions and velocities live in [`P4`]s: three
//! coordinates and a zero pad, 32-byte aligned, so that one particle is one 256-bit load or
//! store. The hot loops (distance constraints four rows at a time, bending hinges, tethers,
//! prediction and velocities) are written as plain per-lane arithmetic and compiled twice: once
//! for the build's baseline target and once with AVX2 enabled (`#[target_feature]`, chosen at
//! run time with `is_x86_feature_detected!`), where LLVM turns the lane arithmetic into 256-bit
//! instructions, including four square roots and four divisions at once. Rust never contracts a
//! multiplication and an addition into a fused multiply-add, and square root and division are
//! correctly rounded, so both versions give the same bits (tested).
//!
//! Every operation here mirrors nalgebra's order of evaluation for `Vector3<f64>` (a dot product
//! is `(x * x' + y * y') + z * z'`), so the cloth computes the same numbers it computed with
//! `Vector3<f64>` arrays.

use nalgebra::Vector3;
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};
use std::sync::{Arc, Mutex, PoisonError};

/// A point or vector of the working layout: `[x, y, z, 0]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, align(32))]
pub(crate) struct P4(pub [f64; 4]);

impl P4 {
    /// The zero vector.
    pub const ZERO: P4 = P4([0.0; 4]);

    #[inline(always)]
    pub fn from_v(v: &Vector3<f64>) -> P4 {
        P4([v.x, v.y, v.z, 0.0])
    }
    #[inline(always)]
    pub fn to_v(self) -> Vector3<f64> {
        Vector3::new(self.0[0], self.0[1], self.0[2])
    }
    /// `(x a.x + y a.y) + z a.z`, as nalgebra's `dot`.
    #[inline(always)]
    pub fn dot(self, o: P4) -> f64 {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }
    #[inline(always)]
    pub fn norm_squared(self) -> f64 {
        self.dot(self)
    }
    #[inline(always)]
    pub fn norm(self) -> f64 {
        self.norm_squared().sqrt()
    }
    /// Cross product (nalgebra's component formulas).
    #[inline(always)]
    pub fn cross(self, b: P4) -> P4 {
        let a = self.0;
        let b = b.0;
        P4([
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
            0.0,
        ])
    }
}

impl Add for P4 {
    type Output = P4;
    #[inline(always)]
    fn add(self, o: P4) -> P4 {
        P4([
            self.0[0] + o.0[0],
            self.0[1] + o.0[1],
            self.0[2] + o.0[2],
            self.0[3] + o.0[3],
        ])
    }
}

impl Sub for P4 {
    type Output = P4;
    #[inline(always)]
    fn sub(self, o: P4) -> P4 {
        P4([
            self.0[0] - o.0[0],
            self.0[1] - o.0[1],
            self.0[2] - o.0[2],
            self.0[3] - o.0[3],
        ])
    }
}

impl Mul<f64> for P4 {
    type Output = P4;
    #[inline(always)]
    fn mul(self, s: f64) -> P4 {
        P4([self.0[0] * s, self.0[1] * s, self.0[2] * s, self.0[3] * s])
    }
}

impl Neg for P4 {
    type Output = P4;
    #[inline(always)]
    fn neg(self) -> P4 {
        P4([-self.0[0], -self.0[1], -self.0[2], -self.0[3]])
    }
}

impl AddAssign for P4 {
    #[inline(always)]
    fn add_assign(&mut self, o: P4) {
        *self = *self + o;
    }
}

impl SubAssign for P4 {
    #[inline(always)]
    fn sub_assign(&mut self, o: P4) {
        *self = *self - o;
    }
}

/// Four distance constraints of one colour (they share no particle), prepared for one substep
/// length; lane `j` is one row.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
pub(crate) struct DistBatch {
    /// Rest lengths, m.
    pub rest: [f64; 4],
    /// `w_a / (w_a + w_b + alpha / h^2)` and the same for b.
    pub ka: [f64; 4],
    pub kb: [f64; 4],
    /// Particles.
    pub a: [u32; 4],
    pub b: [u32; 4],
}

/// A distance constraint prepared for one substep length.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DistRow {
    pub a: u32,
    pub b: u32,
    /// Rest length, m.
    pub rest: f64,
    /// `alpha / h^2`, 1/kg.
    pub at: f64,
    /// `1 / (w_a + w_b + alpha / h^2)`, kg.
    pub inv_denom: f64,
    /// `w_a / (w_a + w_b + alpha / h^2)` and the same for b.
    pub ka: f64,
    pub kb: f64,
}

/// An isometric bending hinge prepared for one substep length.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BendRow {
    pub ids: [u32; 4],
    /// Coefficients `K_i`.
    pub k: [f64; 4],
    /// `w_i K_i / (sum_j w_j K_j^2 + alpha / h^2)`.
    pub wk: [f64; 4],
    /// `alpha / h^2`.
    pub at: f64,
    /// `1 / (sum_j w_j K_j^2 + alpha / h^2)`.
    pub inv_denom: f64,
}

/// The first-iteration solver rows (all multipliers zero), laid out for the kernels: per colour,
/// the distance rows in batches of four and then the rest one by one.
#[derive(Debug, Clone, Default)]
pub(crate) struct OnceRows {
    pub batches: Vec<DistBatch>,
    pub tail: Vec<DistRow>,
    /// Per colour: end of its batches and end of its tail rows.
    pub colour_end: Vec<(usize, usize)>,
}

impl OnceRows {
    /// Splits colour-sorted rows (`colour_end`: end index of each colour) into batches and tails.
    pub fn build(rows: &[DistRow], colour_end: &[usize]) -> OnceRows {
        let mut out = OnceRows::default();
        let mut start = 0;
        for &end in colour_end {
            let mut k = start;
            while k + 4 <= end {
                let r = &rows[k..k + 4];
                out.batches.push(DistBatch {
                    rest: [0, 1, 2, 3].map(|j| r[j].rest),
                    ka: [0, 1, 2, 3].map(|j| r[j].ka),
                    kb: [0, 1, 2, 3].map(|j| r[j].kb),
                    a: [0, 1, 2, 3].map(|j| r[j].a),
                    b: [0, 1, 2, 3].map(|j| r[j].b),
                });
                k += 4;
            }
            out.tail.extend_from_slice(&rows[k..end]);
            out.colour_end.push((out.batches.len(), out.tail.len()));
            start = end;
        }
        out
    }
}

/// The solver rows of one substep length and one set of inverse masses: immutable once built,
/// and shared (behind an `Arc`, see [`RowCache`]) by the cloths of one compiled object whose rows
/// are bitwise the same.
#[derive(Debug, Default)]
pub(crate) struct SolverRows {
    /// Distance rows, colour-sorted (the multi-iteration solver).
    pub dist: Vec<DistRow>,
    /// The same in batches of four per colour (the one-iteration kernels).
    pub once: OnceRows,
    /// Bending rows, colour-sorted.
    pub bend: Vec<BendRow>,
}

/// Whether `a` and `b` have the same length and `eq` holds for each pair.
fn all_same<T>(a: &[T], b: &[T], eq: impl Fn(&T, &T) -> bool) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| eq(x, y))
}

/// Whether two float slices hold the same bits.
fn same_f64(a: &[f64], b: &[f64]) -> bool {
    all_same(a, b, |x, y| x.to_bits() == y.to_bits())
}

impl SolverRows {
    /// Whether `self` and `o` hold the same bits.
    fn same_bits(&self, o: &SolverRows) -> bool {
        let dist_eq = |a: &DistRow, b: &DistRow| {
            (a.a, a.b) == (b.a, b.b)
                && same_f64(
                    &[a.rest, a.at, a.inv_denom, a.ka, a.kb],
                    &[b.rest, b.at, b.inv_denom, b.ka, b.kb],
                )
        };
        all_same(&self.dist, &o.dist, dist_eq)
            && all_same(&self.once.tail, &o.once.tail, dist_eq)
            && self.once.colour_end == o.once.colour_end
            && all_same(&self.bend, &o.bend, |a, b| {
                a.ids == b.ids
                    && same_f64(&a.k, &b.k)
                    && same_f64(&a.wk, &b.wk)
                    && same_f64(&[a.at, a.inv_denom], &[b.at, b.inv_denom])
            })
            && all_same(&self.once.batches, &o.once.batches, |a, b| {
                (a.a, a.b) == (b.a, b.b)
                    && same_f64(&a.rest, &b.rest)
                    && same_f64(&a.ka, &b.ka)
                    && same_f64(&a.kb, &b.kb)
            })
    }
}

/// Most row sets a [`RowCache`] keeps (sets no cloth holds are dropped first).
const CACHED_ROWS: usize = 8;

/// Solver rows shared by the cloths of one compiled object (the envs of a vectorised env): the
/// rows are a pure function of the mesh, material, substep length and inverse masses, so a cloth
/// whose rows come out bitwise equal to a cached set takes that set and drops its own. 16 envs
/// of a cloth task then read one copy of their largest per-step data instead of 16, which
/// otherwise fall out of the caches between their steps (docs/bench-history.md, Tasks).
#[derive(Debug, Default)]
pub(crate) struct RowCache {
    entries: Mutex<Vec<Arc<SolverRows>>>,
}

impl RowCache {
    /// The cached set bitwise equal to `rows`, or `rows` itself (kept while there is room).
    pub(crate) fn share(&self, rows: SolverRows) -> Arc<SolverRows> {
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(e) = entries.iter().find(|e| e.same_bits(&rows)) {
            return Arc::clone(e);
        }
        let rows = Arc::new(rows);
        if entries.len() >= CACHED_ROWS {
            entries.retain(|e| Arc::strong_count(e) > 1);
        }
        if entries.len() < CACHED_ROWS {
            entries.push(Arc::clone(&rows));
        }
        rows
    }
}

use modesuite_engine::avx2_dispatch as dispatch;
pub(crate) use modesuite_engine::simd::Simd;

#[inline(always)]
fn dist_row_once(pos: &mut [P4], r: &DistRow) {
    let (a, b) = (r.a as usize, r.b as usize);
    let d = pos[a] - pos[b];
    let l = d.norm();
    if l < 1e-12 {
        return;
    }
    let s = (r.rest - l) / l;
    pos[a] += d * (s * r.ka);
    pos[b] -= d * (s * r.kb);
}

/// Four divisions at once.
trait Div4 {
    fn div(a: [f64; 4], b: [f64; 4]) -> [f64; 4];
}

/// Lane by lane (any target).
struct DivLanes;

impl Div4 for DivLanes {
    #[inline(always)]
    fn div(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        std::array::from_fn(|j| a[j] / b[j])
    }
}

/// One AVX `vdivpd` (inlined only into AVX2 functions).
#[cfg(target_arch = "x86_64")]
struct DivAvx;

#[cfg(target_arch = "x86_64")]
impl Div4 for DivAvx {
    #[inline(always)]
    fn div(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        use std::arch::x86_64::{_mm256_div_pd, _mm256_loadu_pd, _mm256_storeu_pd};
        let mut out = [0.0; 4];
        // SAFETY: used only by `distances_once_avx2` and `tethers_avx2`, which run where AVX2
        // was detected; the pointers are to four-element arrays.
        unsafe {
            let q = _mm256_div_pd(_mm256_loadu_pd(a.as_ptr()), _mm256_loadu_pd(b.as_ptr()));
            _mm256_storeu_pd(out.as_mut_ptr(), q);
        }
        out
    }
}

#[inline(always)]
fn distances_once_body<Q: Div4>(pos: &mut [P4], rows: &OnceRows) {
    let (mut b0, mut t0) = (0, 0);
    for &(b1, t1) in &rows.colour_end {
        for r in &rows.batches[b0..b1] {
            let mut pa = [P4::ZERO; 4];
            let mut pb = [P4::ZERO; 4];
            for j in 0..4 {
                pa[j] = pos[r.a[j] as usize];
                pb[j] = pos[r.b[j] as usize];
            }
            let d: [P4; 4] = std::array::from_fn(|j| pa[j] - pb[j]);
            let l: [f64; 4] = std::array::from_fn(|j| d[j].norm());
            // `if l < 1e-12 { 0 } else { (l0 - l) / l }`: the guarded denominator keeps the
            // quotient finite, so a skipped row is a multiplication by zero and the four
            // divisions are one instruction (LLVM does not vectorise them by itself)
            let mut num = [0.0; 4];
            let mut den = [0.0; 4];
            let mut on = [0.0; 4];
            for j in 0..4 {
                num[j] = r.rest[j] - l[j];
                den[j] = l[j].max(1e-12);
                on[j] = if l[j] < 1e-12 { 0.0 } else { 1.0 };
            }
            let q = Q::div(num, den);
            let s: [f64; 4] = std::array::from_fn(|j| q[j] * on[j]);
            let sa: [f64; 4] = std::array::from_fn(|j| s[j] * r.ka[j]);
            let sb: [f64; 4] = std::array::from_fn(|j| s[j] * r.kb[j]);
            // rows of one colour share no particle: write all eight back
            for j in 0..4 {
                pos[r.a[j] as usize] = pa[j] + d[j] * sa[j];
                pos[r.b[j] as usize] = pb[j] - d[j] * sb[j];
            }
        }
        for r in &rows.tail[t0..t1] {
            dist_row_once(pos, r);
        }
        (b0, t0) = (b1, t1);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn distances_once_avx2(pos: &mut [P4], rows: &OnceRows) {
    distances_once_body::<DivAvx>(pos, rows)
}

/// One Gauss-Seidel sweep over the distance constraints for the first iteration of a substep
/// (XPBD with zero multipliers: `dx_a = w_a (l0 - l) / (w_a + w_b + alpha~) n`), four rows of a
/// colour at a time.
#[inline(never)]
pub(crate) fn distances_once(simd: Simd, pos: &mut [P4], rows: &OnceRows) {
    #[cfg(target_arch = "x86_64")]
    if simd.avx2() {
        // SAFETY: a `Simd` with `avx2()` true is made only by `Simd::detect`, where the CPU
        // has the feature.
        return unsafe { distances_once_avx2(pos, rows) };
    }
    let _ = simd;
    distances_once_body::<DivLanes>(pos, rows)
}

#[inline(always)]
fn bending_once_body(pos: &mut [P4], rows: &[BendRow]) {
    for r in rows {
        let [i0, i1, i2, i3] = r.ids.map(|i| i as usize);
        let (x0, x1, x2, x3) = (pos[i0], pos[i1], pos[i2], pos[i3]);
        let k = r.k;
        let num = -(x0 * k[0] + x1 * k[1] + x2 * k[2] + x3 * k[3]);
        // the four particles of a hinge are distinct
        pos[i0] = x0 + num * r.wk[0];
        pos[i1] = x1 + num * r.wk[1];
        pos[i2] = x2 + num * r.wk[2];
        pos[i3] = x3 + num * r.wk[3];
    }
}

dispatch! {
    /// One sweep over the isometric bending hinges for the first iteration of a substep: the
    /// constraint `C = sum_i K_i x_i` is linear, `dx_i = -w_i K_i C / (sum_j w_j K_j^2 + alpha~)`.
    pub(crate) fn bending_once / bending_once_avx2 => bending_once_body(pos: &mut [P4], rows: &[BendRow])
}

#[inline(always)]
fn velocities_body(x: &[P4], v: &mut [P4], prev: &[P4], inv_h: f64) {
    let n = x.len();
    let (v, prev) = (&mut v[..n], &prev[..n]);
    for i in 0..n {
        v[i] = (x[i] - prev[i]) * inv_h;
    }
}

dispatch! {
    /// End of a substep: `v = (x - prev) / h`.
    pub(crate) fn velocities / velocities_avx2 => velocities_body(x: &[P4], v: &mut [P4], prev: &[P4], inv_h: f64)
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn advance_body(
    x: &mut [P4],
    v: &mut [P4],
    prev: &mut [P4],
    inv_mass: &[f64],
    inv_h: Option<f64>,
    damp: f64,
    gh: P4,
    h: f64,
) {
    let n = x.len();
    let (v, prev, inv_mass) = (&mut v[..n], &mut prev[..n], &inv_mass[..n]);
    for i in 0..n {
        let xi = x[i];
        let mut vi = match inv_h {
            Some(k) => (xi - prev[i]) * k,
            None => v[i],
        };
        prev[i] = xi;
        if inv_mass[i] > 0.0 {
            // damping before gravity so that the static equilibrium is exact
            vi = vi * damp + gh;
            x[i] = xi + vi * h;
        }
        v[i] = vi;
    }
}

dispatch! {
    /// Start of a substep: with `inv_h = Some(1 / h)` first the velocities of the substep before,
    /// `v = (x - prev) / h` (one pass over the particles instead of two); then `prev = x`, and for
    /// free particles `v = v damp + g h`, `x += v h`.
    pub(crate) fn advance / advance_avx2 => advance_body(
        x: &mut [P4], v: &mut [P4], prev: &mut [P4], inv_mass: &[f64], inv_h: Option<f64>,
        damp: f64, gh: P4, h: f64
    )
}

#[inline(always)]
fn tether_rows_body<Q: Div4>(pos: &mut [P4], rows: &[(u32, u32, f64)]) {
    let mut chunks = rows.chunks_exact(4);
    for r in &mut chunks {
        let pi: [P4; 4] = std::array::from_fn(|j| pos[r[j].0 as usize]);
        let pa: [P4; 4] = std::array::from_fn(|j| pos[r[j].1 as usize]);
        let d: [P4; 4] = std::array::from_fn(|j| pi[j] - pa[j]);
        let l: [f64; 4] = std::array::from_fn(|j| d[j].norm());
        // `if c > 0 { c / l } else { 0 }`: where c > 0, l > 0 is the divisor; elsewhere 0 / den
        let c: [f64; 4] = std::array::from_fn(|j| (l[j] - r[j].2).max(0.0));
        let den: [f64; 4] = std::array::from_fn(|j| l[j].max(f64::MIN_POSITIVE));
        let s = Q::div(c, den);
        // each row moves only its own particle (the anchors are pinned and have no row)
        for j in 0..4 {
            pos[r[j].0 as usize] = pi[j] - d[j] * s[j];
        }
    }
    for &(i, a, len) in chunks.remainder() {
        let d = pos[i as usize] - pos[a as usize];
        let l = d.norm();
        let c = (l - len).max(0.0);
        let s = if c > 0.0 { c / l } else { 0.0 };
        pos[i as usize] -= d * s;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tethers_avx2(pos: &mut [P4], rows: &[(u32, u32, f64)]) {
    tether_rows_body::<DivAvx>(pos, rows)
}

/// Long-range tethers to pinned particles, rows `(particle, anchor, length)`: a particle farther
/// from its anchor than the length is moved back onto the sphere. Four rows at a time.
#[inline(never)]
pub(crate) fn tethers(simd: Simd, pos: &mut [P4], rows: &[(u32, u32, f64)]) {
    #[cfg(target_arch = "x86_64")]
    if simd.avx2() {
        // SAFETY: a `Simd` with `avx2()` true is made only by `Simd::detect`, where the CPU
        // has the feature.
        return unsafe { tethers_avx2(pos, rows) };
    }
    let _ = simd;
    tether_rows_body::<DivLanes>(pos, rows)
}
