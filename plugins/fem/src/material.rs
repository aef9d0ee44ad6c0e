//! Hyperelastic material: Stable Neo-Hookean (Smith, de Goes, Kim 2018, "Stable Neo-Hookean Flesh
//! Simulation", ACM TOG 37(2)).
//!
//! Energy density (per unit rest volume, J/m^3), with `I_C = tr(F^T F)`, `J = det F`:
//!
//! ```text
//! Psi(F) = mu/2 (I_C - 3) + lambda/2 [(J - alpha)^2 - (1 - alpha)^2] - mu/2 ln((I_C + 1) / 4),
//! alpha  = 1 + 3 mu / (4 lambda)
//! ```
//!
//! The constant terms are subtracted so that `Psi(I) = 0` exactly (the paper's energy has a
//! constant offset, which changes no force). `alpha` makes the rest state stress free
//! (`P(I) = 0`). The energy is defined and smooth for inverted elements (`J <= 0`), which is what
//! lets crushed elements recover.
//!
//! Linearising `P` at `F = I` gives `dP = 3/4 mu (dF + dF^T) + (lambda - 5/8 mu) tr(dF) I`, so the
//! small-strain Lamé parameters are `mu_L = 3/4 mu`, `lambda_L = lambda - 5/8 mu`. The corrected
//! mapping (Smith et al. 2018, sec. 3.4) inverts this: `mu = 4/3 mu_L`, `lambda = lambda_L + 5/6 mu_L`,
//! so that the Young's modulus and Poisson ratio a user enters come back at small strain.

use crate::error::FemError;
use nalgebra::{Matrix3, SMatrix, Vector3};

/// 9x9 matrix, the derivative of the first Piola-Kirchhoff stress with respect to the deformation
/// gradient, both flattened column-major (`vec(F)[i + 3 j] = F[(i, j)]`).
pub type Matrix9 = SMatrix<f64, 9, 9>;

/// User-facing material description (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Young's modulus (Pa), > 0.
    pub youngs_modulus: f64,
    /// Poisson ratio, in (-1, 0.5).
    pub poisson_ratio: f64,
    /// Mass density (kg/m^3), > 0.
    pub density: f64,
}

impl Material {
    /// Validated material.
    pub fn new(youngs_modulus: f64, poisson_ratio: f64, density: f64) -> Result<Self, FemError> {
        let m = Material {
            youngs_modulus,
            poisson_ratio,
            density,
        };
        m.validate()?;
        Ok(m)
    }

    /// Checks every field is finite and in range.
    pub fn validate(&self) -> Result<(), FemError> {
        if !(self.youngs_modulus.is_finite() && self.youngs_modulus > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "material.youngs_modulus",
                value: self.youngs_modulus,
                expected: "finite and > 0 (Pa)",
            });
        }
        if !(self.poisson_ratio.is_finite()
            && self.poisson_ratio > -1.0
            && self.poisson_ratio < 0.5)
        {
            return Err(FemError::InvalidParameter {
                name: "material.poisson_ratio",
                value: self.poisson_ratio,
                expected: "in (-1, 0.5)",
            });
        }
        if !(self.density.is_finite() && self.density > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "material.density",
                value: self.density,
                expected: "finite and > 0 (kg/m^3)",
            });
        }
        Ok(())
    }

    /// Small-strain Lamé parameters `(mu, lambda)` (Pa) of this material.
    pub fn lame(&self) -> (f64, f64) {
        lame_parameters(self.youngs_modulus, self.poisson_ratio)
    }
}

/// Classical Lamé parameters `(mu, lambda)` (Pa) from Young's modulus (Pa) and Poisson ratio:
/// `mu = E / (2 (1 + nu))`, `lambda = E nu / ((1 + nu)(1 - 2 nu))`.
pub fn lame_parameters(youngs_modulus: f64, poisson_ratio: f64) -> (f64, f64) {
    let e = youngs_modulus;
    let nu = poisson_ratio;
    (
        e / (2.0 * (1.0 + nu)),
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
    )
}

/// Stable Neo-Hookean energy with its parameters (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StableNeoHookean {
    /// Energy parameter `mu` (Pa); not the small-strain shear modulus (that is `3/4 mu`).
    pub mu: f64,
    /// Energy parameter `lambda` (Pa).
    pub lambda: f64,
    /// Rest-stability offset `1 + 3 mu / (4 lambda)`.
    pub alpha: f64,
}

/// Cofactor matrix `cof F = det(F) F^{-T}`, columns `f1 x f2`, `f2 x f0`, `f0 x f1`.
#[inline]
pub fn cofactor(f: &Matrix3<f64>) -> Matrix3<f64> {
    let f0 = f.column(0).into_owned();
    let f1 = f.column(1).into_owned();
    let f2 = f.column(2).into_owned();
    Matrix3::from_columns(&[f1.cross(&f2), f2.cross(&f0), f0.cross(&f1)])
}

#[inline]
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

impl StableNeoHookean {
    /// Energy with the raw parameters `mu`, `lambda` (Pa) of the energy (no correction).
    pub fn from_energy_parameters(mu: f64, lambda: f64) -> Self {
        StableNeoHookean {
            mu,
            lambda,
            alpha: 1.0 + 0.75 * mu / lambda,
        }
    }

    /// Energy whose small-strain response has the given Young's modulus and Poisson ratio, using
    /// the corrected mapping `mu = 4/3 mu_L`, `lambda = lambda_L + 5/6 mu_L`.
    pub fn from_young_poisson(youngs_modulus: f64, poisson_ratio: f64) -> Self {
        let (mu_l, lambda_l) = lame_parameters(youngs_modulus, poisson_ratio);
        Self::from_energy_parameters(4.0 / 3.0 * mu_l, lambda_l + 5.0 / 6.0 * mu_l)
    }

    /// Small-strain Lamé parameters `(mu_L, lambda_L)` this energy linearises to.
    pub fn small_strain_lame(&self) -> (f64, f64) {
        (0.75 * self.mu, self.lambda - 0.625 * self.mu)
    }

    /// Energy density `Psi(F)` (J/m^3).
    #[inline]
    pub fn energy(&self, f: &Matrix3<f64>) -> f64 {
        let ic = f.norm_squared();
        let j = f.determinant();
        let a = self.alpha;
        0.5 * self.mu * (ic - 3.0) + 0.5 * self.lambda * ((j - a) * (j - a) - (1.0 - a) * (1.0 - a))
            - 0.5 * self.mu * ((ic + 1.0) / 4.0).ln()
    }

    /// First Piola-Kirchhoff stress `P = dPsi/dF` (Pa).
    #[inline]
    pub fn pk1(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        let ic = f.norm_squared();
        let cof = cofactor(f);
        let j = f.column(0).dot(&cof.column(0));
        f * (self.mu * (1.0 - 1.0 / (ic + 1.0))) + cof * (self.lambda * (j - self.alpha))
    }

    /// Energy density, stress and stress derivative `dP/dF` (9x9, column-major vec) at `F`.
    #[inline]
    pub fn eval(&self, f: &Matrix3<f64>) -> (f64, Matrix3<f64>, Matrix9) {
        let ic = f.norm_squared();
        let cof = cofactor(f);
        let j = f.column(0).dot(&cof.column(0));
        let a = self.alpha;
        let psi = 0.5 * self.mu * (ic - 3.0)
            + 0.5 * self.lambda * ((j - a) * (j - a) - (1.0 - a) * (1.0 - a))
            - 0.5 * self.mu * ((ic + 1.0) / 4.0).ln();
        let s = self.mu * (1.0 - 1.0 / (ic + 1.0));
        let c = self.lambda * (j - a);
        let p = f * s + cof * c;
        let mut h = Matrix9::from_diagonal_element(s);
        let r = 2.0 * self.mu / ((ic + 1.0) * (ic + 1.0));
        let fv = f.as_slice();
        let gv = cof.as_slice();
        for col in 0..9 {
            for row in 0..9 {
                h[(row, col)] += r * fv[row] * fv[col] + self.lambda * gv[row] * gv[col];
            }
        }
        // lambda (J - alpha) d^2 J / dF^2: blocks (a, b) over the columns f0, f1, f2 of F.
        let f0 = f.column(0).into_owned();
        let f1 = f.column(1).into_owned();
        let f2 = f.column(2).into_owned();
        let blocks = [(0, 1, -skew(&f2)), (0, 2, skew(&f1)), (1, 2, -skew(&f0))];
        for (ba, bb, m) in blocks.iter() {
            for i in 0..3 {
                for k in 0..3 {
                    h[(3 * ba + i, 3 * bb + k)] += c * m[(i, k)];
                    h[(3 * bb + k, 3 * ba + i)] += c * m[(i, k)];
                }
            }
        }
        (psi, p, h)
    }
}

/// Whether the symmetric 9x9 `h` is accepted as positive semi-definite unchanged: a Cholesky
/// factorisation of `H + 1e-9 tr(H)/9 I` succeeds (the common case near rest). The rest Hessian is
/// only semi-definite (rotations are zero modes), hence the shift: eigenvalues above
/// `-1e-9 tr(H)/9` pass.
#[inline]
fn psd_within_shift(h: &Matrix9) -> bool {
    let shift = 1e-9 * h.trace().abs() / 9.0;
    (h + Matrix9::identity() * shift).cholesky().is_some()
}

/// Makes a symmetric 9x9 matrix positive semi-definite: returns it unchanged when a Cholesky
/// factorisation of `H + 1e-9 tr(H)/9 I` succeeds (the common case near rest), otherwise clamps
/// its negative eigenvalues to zero by a numerical eigen-decomposition (Teran et al. 2005 style
/// projection, done on the 9x9 stress derivative). General but slow; the solver uses the analytic
/// [`StableNeoHookean::project_hessian`], which falls back to this only where the 3x3 SVD or
/// eigen-solve does not converge, and the tests use it as the reference.
pub fn project_psd(h: &Matrix9) -> Matrix9 {
    if psd_within_shift(h) {
        return *h;
    }
    let eig = h.symmetric_eigen();
    let mut out = Matrix9::zeros();
    for k in 0..9 {
        let lam = eig.eigenvalues[k];
        if lam > 0.0 {
            let v = eig.eigenvectors.column(k);
            out += v * v.transpose() * lam;
        }
    }
    out
}

impl StableNeoHookean {
    /// `dP/dF` at `F` (the `h` returned by [`StableNeoHookean::eval`] for this `f`) made positive
    /// semi-definite: returned unchanged when it passes the same shifted Cholesky test as
    /// [`project_psd`], otherwise its negative eigenvalues are clamped to zero using the analytic
    /// eigensystem of the energy (Smith, de Goes, Kim 2019, "Analytic Eigensystems for Isotropic
    /// Distortion Energies", applied to the energy of this module).
    ///
    /// With the rotation-variant SVD `F = U diag(s) V^T` (`U`, `V` rotations, `s_2` negative when
    /// `F` is inverted), `Ic = |F|^2`, `J = det F`, `a = mu (1 - 1/(Ic + 1))`,
    /// `b = 2 mu / (Ic + 1)^2` and `c = lambda (J - alpha)`, the nine eigenpairs of `dP/dF` are,
    /// for each pair `(i, j)` with third index `k`:
    ///
    /// ```text
    /// twist  (u_i v_j^T - u_j v_i^T) / sqrt 2   eigenvalue a + c s_k
    /// flip   (u_i v_j^T + u_j v_i^T) / sqrt 2   eigenvalue a - c s_k
    /// ```
    ///
    /// and three scaling modes `U diag(z) V^T`, `z` the eigenvectors of the 3x3 matrix
    /// `a I + b s s^T + lambda g g^T + c [[0, s_2, s_1], [s_2, 0, s_0], [s_1, s_0, 0]]` with
    /// `g = (s_1 s_2, s_0 s_2, s_0 s_1)` (the gradient of `J` in the singular values). The
    /// projection subtracts `l_m q_m q_m^T` for each negative eigenvalue `l_m`. Should the
    /// 3x3 SVD or eigen-solve not converge (non-finite `F`), the numerical [`project_psd`] is used.
    pub fn project_hessian(&self, f: &Matrix3<f64>, h: &Matrix9) -> Matrix9 {
        if psd_within_shift(h) {
            return *h;
        }
        self.clamp_modes(f, h).unwrap_or_else(|| project_psd(h))
    }

    /// The analytic clamp of [`StableNeoHookean::project_hessian`] without the Cholesky shortcut;
    /// `None` where a 3x3 decomposition does not converge.
    fn clamp_modes(&self, f: &Matrix3<f64>, h: &Matrix9) -> Option<Matrix9> {
        let svd = f.try_svd_unordered(true, true, f64::EPSILON, 100)?;
        let mut u = svd.u?;
        let mut v = svd.v_t?.transpose();
        // rotations: flipping a column of U or V flips the sign of that singular value
        if u.determinant() < 0.0 {
            u.column_mut(2).neg_mut();
        }
        if v.determinant() < 0.0 {
            v.column_mut(2).neg_mut();
        }
        let fv = f * v;
        let sig = Vector3::from_fn(|k, _| u.column(k).dot(&fv.column(k)));
        if !sig.iter().all(|x| x.is_finite()) {
            return None;
        }
        let ic = f.norm_squared();
        let j = f.determinant();
        let a = self.mu * (1.0 - 1.0 / (ic + 1.0));
        let b = 2.0 * self.mu / ((ic + 1.0) * (ic + 1.0));
        let c = self.lambda * (j - self.alpha);
        let mut out = *h;
        // out -= lam q q^T, written entry by entry as (q_r q_c) lam so that it stays symmetric
        let mut remove = |q: &Matrix3<f64>, lam: f64| {
            let q = q.as_slice();
            for col in 0..9 {
                for row in 0..9 {
                    out[(row, col)] -= q[row] * q[col] * lam;
                }
            }
        };
        let r2 = std::f64::consts::FRAC_1_SQRT_2;
        for (i, jj, k) in [(1, 2, 0), (0, 2, 1), (0, 1, 2)] {
            let twist = a + c * sig[k];
            let flip = a - c * sig[k];
            if twist < 0.0 || flip < 0.0 {
                let uv = u.column(i) * v.column(jj).transpose();
                let vu = u.column(jj) * v.column(i).transpose();
                if twist < 0.0 {
                    remove(&((uv - vu) * r2), twist);
                }
                if flip < 0.0 {
                    remove(&((uv + vu) * r2), flip);
                }
            }
        }
        let g = Vector3::new(sig[1] * sig[2], sig[0] * sig[2], sig[0] * sig[1]);
        let mut scaling = Matrix3::from_diagonal_element(a)
            + sig * sig.transpose() * b
            + g * g.transpose() * self.lambda;
        for (i, jj, k) in [(1, 2, 0), (0, 2, 1), (0, 1, 2)] {
            scaling[(i, jj)] += c * sig[k];
            scaling[(jj, i)] += c * sig[k];
        }
        // positive definite by Sylvester's criterion (the usual case): nothing to clamp
        let minor2 = scaling[(0, 0)] * scaling[(1, 1)] - scaling[(0, 1)] * scaling[(0, 1)];
        if scaling[(0, 0)] > 0.0 && minor2 > 0.0 && scaling.determinant() > 0.0 {
            return Some(out);
        }
        let eig = scaling.try_symmetric_eigen(f64::EPSILON, 100)?;
        for m in 0..3 {
            let lam = eig.eigenvalues[m];
            if lam < 0.0 {
                let z = eig.eigenvectors.column(m);
                remove(&(u * Matrix3::from_diagonal(&z) * v.transpose()), lam);
            }
        }
        Some(out)
    }
}

/// Uniaxial-stress response of a homogeneous SNH block stretched to `stretch` along x with free
/// lateral faces: returns `(lateral_stretch, nominal_stress_xx)` (-, Pa) by a 1-D Newton solve of
/// `P_yy(diag(s, t, t)) = 0`. Semi-analytic reference for the stretch tests.
pub fn uniaxial_response(m: &StableNeoHookean, stretch: f64) -> (f64, f64) {
    let mut t = 1.0;
    for _ in 0..100 {
        let pyy = |t: f64| m.pk1(&Matrix3::from_diagonal(&Vector3::new(stretch, t, t)))[(1, 1)];
        let r = pyy(t);
        let h = 1e-6;
        let d = (pyy(t + h) - pyy(t - h)) / (2.0 * h);
        let dt = -r / d;
        t += dt;
        if dt.abs() < 1e-15 {
            break;
        }
    }
    let p = m.pk1(&Matrix3::from_diagonal(&Vector3::new(stretch, t, t)));
    (t, p[(0, 0)])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_f(seed: u64, scale: f64) -> Matrix3<f64> {
        // small deterministic LCG so the test needs no rand crate
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        Matrix3::identity() + Matrix3::from_fn(|_, _| scale * next())
    }

    #[test]
    fn lame_mapping_e280_nu04() {
        let (mu, lambda) = lame_parameters(280.0, 0.4);
        println!("Lame E=280 nu=0.4: mu = {mu} (100), lambda = {lambda} (400), tol 1e-12");
        assert!((mu - 100.0).abs() < 1e-12 && (lambda - 400.0).abs() < 1e-12);
        let snh = StableNeoHookean::from_young_poisson(280.0, 0.4);
        let (ml, ll) = snh.small_strain_lame();
        println!(
            "SNH corrected: mu = {} lambda = {} -> linearised mu_L = {ml} (100), lambda_L = {ll} (400)",
            snh.mu, snh.lambda
        );
        assert!(
            (snh.mu - 400.0 / 3.0).abs() < 1e-12
                && (snh.lambda - (400.0 + 500.0 / 6.0)).abs() < 1e-12
        );
        assert!((ml - 100.0).abs() < 1e-12 && (ll - 400.0).abs() < 1e-12);
        // the linearisation claim itself, checked on the analytic dP/dF at I against linear elasticity
        let (_, _, h) = snh.eval(&Matrix3::identity());
        let mut max_err: f64 = 0.0;
        for c in 0..9 {
            let mut df = Matrix3::zeros();
            df.as_mut_slice()[c] = 1.0;
            let lin = (df + df.transpose()) * ml + Matrix3::identity() * (ll * df.trace());
            let dp = h.column(c);
            for r in 0..9 {
                max_err = max_err.max((dp[r] - lin.as_slice()[r]).abs());
            }
        }
        println!("SNH dP/dF(I) vs linear elasticity(mu_L=100, lambda_L=400): max abs err {max_err:e} (tol 1e-10)");
        assert!(max_err < 1e-10);
    }

    #[test]
    fn material_at_rest() {
        let m = StableNeoHookean::from_young_poisson(1e6, 0.35);
        let psi = m.energy(&Matrix3::identity());
        let p = m.pk1(&Matrix3::identity()).norm();
        println!(
            "rest: Psi(I) = {psi:e} (0), |P(I)| = {p:e} Pa (<= 1e-12 mu = {:e})",
            1e-12 * m.mu
        );
        assert_eq!(psi, 0.0);
        assert!(p <= 1e-12 * m.mu);
    }

    #[test]
    fn stress_and_tangent_match_finite_differences() {
        let m = StableNeoHookean::from_young_poisson(1e6, 0.45);
        let mut worst_p: f64 = 0.0;
        let mut worst_h: f64 = 0.0;
        let mut inverted = 0;
        for seed in 0..40u64 {
            let mut f = sample_f(seed, 0.6);
            if seed % 3 == 0 {
                // force an inverted F
                f.set_column(2, &(-f.column(2)));
            }
            if f.determinant() < 0.0 {
                inverted += 1;
            }
            let (_, p, h) = m.eval(&f);
            let eps = 1e-6;
            let mut p_fd = Matrix3::zeros();
            let mut h_fd = Matrix9::zeros();
            for c in 0..9 {
                let mut fp = f;
                let mut fm = f;
                fp.as_mut_slice()[c] += eps;
                fm.as_mut_slice()[c] -= eps;
                p_fd.as_mut_slice()[c] = (m.energy(&fp) - m.energy(&fm)) / (2.0 * eps);
                let dp = (m.pk1(&fp) - m.pk1(&fm)) / (2.0 * eps);
                for r in 0..9 {
                    h_fd[(r, c)] = dp.as_slice()[r];
                }
            }
            worst_p = worst_p.max((p - p_fd).norm() / p.norm().max(m.mu));
            worst_h = worst_h.max((h - h_fd).norm() / h.norm());
        }
        println!(
            "P vs FD(Psi): max rel err {worst_p:e}; dP/dF vs FD(P): max rel err {worst_h:e} (tol 1e-6); {inverted} of 40 samples inverted"
        );
        assert!(inverted >= 10);
        assert!(worst_p <= 1e-6 && worst_h <= 1e-6);
    }

    #[test]
    fn psd_projection() {
        let m = StableNeoHookean::from_young_poisson(1e6, 0.3);
        let f = Matrix3::from_diagonal(&Vector3::new(0.3, -0.2, 1.5));
        let (_, _, h) = m.eval(&f);
        let hp = project_psd(&h);
        let min_before = h.symmetric_eigen().eigenvalues.min();
        let min_after = hp.symmetric_eigen().eigenvalues.min();
        println!("PSD projection at inverted F: min eig {min_before:e} -> {min_after:e}");
        assert!(min_before < 0.0 && min_after > -1e-9 * h.norm());
        let (_, _, h0) = m.eval(&Matrix3::identity());
        assert_eq!(project_psd(&h0), h0);
    }

    /// Reference for the analytic projection: numerical eigen-decomposition, every negative
    /// eigenvalue clamped (no Cholesky shortcut).
    fn clamp_numerical(h: &Matrix9) -> Matrix9 {
        let eig = h.symmetric_eigen();
        let mut out = Matrix9::zeros();
        for k in 0..9 {
            let v = eig.eigenvectors.column(k);
            out += v * v.transpose() * eig.eigenvalues[k].max(0.0);
        }
        out
    }

    fn rotation(seed: u64) -> Matrix3<f64> {
        let a = sample_f(seed, 2.0) - Matrix3::identity();
        nalgebra::Rotation3::from_scaled_axis(a.column(0).into_owned()).into_inner()
    }

    #[test]
    fn analytic_projection_matches_numerical() {
        let mut fs: Vec<(&str, Matrix3<f64>)> = vec![("rest", Matrix3::identity())];
        for seed in 0..60u64 {
            let mut f = sample_f(seed, if seed % 2 == 0 { 0.6 } else { 1.5 });
            if seed % 3 == 0 {
                f.set_column(2, &(-f.column(2)));
            }
            fs.push(("random", f));
        }
        let diags = [
            [1.0, 1.0 + 1e-10, 0.5],
            [1.3, 1.3 + 1e-13, -0.4],
            [0.7, 0.7, 0.7],
            [0.5, 0.5, -0.5],
            [1.0, 1.0, 0.0],
            [2.0, 0.0, 0.0],
            [1e-3, 1e-3, 1e-3],
            [1.8, 1.0, 1.0],
            [0.3, -0.2, 1.5],
            [1.0 + 1e-9, 1.0, 1.0 - 1e-9],
        ];
        for (i, d) in diags.iter().enumerate() {
            let sd = Matrix3::from_diagonal(&Vector3::from_column_slice(d));
            fs.push(("degenerate", sd));
            fs.push((
                "degenerate",
                rotation(100 + i as u64) * sd * rotation(200 + i as u64),
            ));
        }
        for k in 0..8u64 {
            fs.push(("rotation", rotation(300 + k)));
        }
        let mut worst: f64 = 0.0;
        let mut worst_full: f64 = 0.0;
        let mut worst_kind = "";
        let mut clamped = 0;
        let mut inverted = 0;
        for &(e, nu) in &[(1e6, 0.3), (1e6, 0.45), (2.5e5, 0.49)] {
            let m = StableNeoHookean::from_young_poisson(e, nu);
            for (kind, f) in &fs {
                let (_, _, h) = m.eval(f);
                let reference = clamp_numerical(&h);
                if (reference - h).norm() > 1e-12 * h.norm() {
                    clamped += 1;
                }
                if f.determinant() < 0.0 {
                    inverted += 1;
                }
                let analytic = m.clamp_modes(f, &h).expect("3x3 decompositions converge");
                let err = (analytic - reference).norm() / h.norm();
                if err > worst {
                    worst = err;
                    worst_kind = kind;
                }
                // with the shared Cholesky shortcut, the solver's entry point against the old one
                let full = (m.project_hessian(f, &h) - project_psd(&h)).norm() / h.norm();
                worst_full = worst_full.max(full);
            }
        }
        println!(
            "analytic vs numerical PSD clamp of dP/dF: max rel err {worst:e} ({worst_kind}; tol 1e-8), \
             project_hessian vs project_psd {worst_full:e} (tol 1e-8); {} cases, {clamped} with a \
             negative eigenvalue, {inverted} inverted",
            3 * fs.len()
        );
        assert!(worst <= 1e-8 && worst_full <= 1e-8);
        assert!(clamped >= 50 && inverted >= 30);
    }

    #[test]
    fn poisson_and_young_at_one_percent_strain() {
        for &(e, nu) in &[(1e6, 0.35), (2.5e5, 0.45), (1e8, 0.3)] {
            let m = StableNeoHookean::from_young_poisson(e, nu);
            let eps = 0.01;
            let (tp, pp) = uniaxial_response(&m, 1.0 + eps);
            let (tm, pm) = uniaxial_response(&m, 1.0 - eps);
            let e_eff = (pp - pm) / (2.0 * eps);
            let nu_eff = -(tp - tm) / (2.0 * eps);
            println!(
                "material uniaxial +-1%: E_eff/E = {:.6} (1 +- 1e-3), nu_eff = {nu_eff:.6} vs {nu} (+- 1e-3)",
                e_eff / e
            );
            assert!((e_eff / e - 1.0).abs() <= 1e-3 && (nu_eff - nu).abs() <= 1e-3);
        }
    }
}
