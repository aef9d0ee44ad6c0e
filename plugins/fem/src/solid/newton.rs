//! The incremental potential (elastic part, value, gradient) and the exact Newton solve with
//! line search.

use super::{max_component, FemSolid, Problem, StepStats};
use crate::error::FemError;
use crate::model::KernelStats;
use crate::sparse::{dot, pcg};
use nalgebra::{Matrix3, Vector3};

impl FemSolid {
    /// Elastic (and stiffness-damping) gradient and Hessian at the current positions, scaled by
    /// this solid's Young's modulus over the model's; returns the number of inverted quadrature
    /// points.
    fn eval_elastic(
        &self,
        grad: &mut [Vector3<f64>],
        hess: &mut [Matrix3<f64>],
        project: bool,
        damping: Option<(&[Vector3<f64>], f64)>,
    ) -> usize {
        let inverted = self
            .model
            .eval(&self.pos, grad, Some(&mut *hess), project, damping)
            .inverted;
        let k = self.stiffness_scale;
        if k != 1.0 {
            grad.iter_mut().for_each(|g| *g *= k);
            hess.iter_mut().for_each(|b| *b *= k);
        }
        inverted
    }

    /// Total incremental potential at `x`.
    pub(super) fn potential(&self, p: &Problem, x: &[Vector3<f64>]) -> f64 {
        let damping = (p.c_kdamp > 0.0).then_some((&self.xprev[..], p.c_kdamp));
        self.potential_with(p, x, self.model.energy_only(x, damping).energy)
    }

    /// The incremental potential at `x` given its (unscaled) elastic energy.
    pub(super) fn potential_with(&self, p: &Problem, x: &[Vector3<f64>], elastic: f64) -> f64 {
        let mut e = elastic * self.stiffness_scale;
        for i in 0..self.n_nodes() {
            let m = self.model.mass[i];
            if p.c_mass > 0.0 {
                e += 0.5 * m * p.c_mass * (x[i] - self.xhat[i]).norm_squared();
            }
            if p.c_damp > 0.0 {
                e += 0.5 * m * p.c_damp * (x[i] - self.xprev[i]).norm_squared();
            }
            e -= (self.ext_force[i] + self.fric[i] + p.gravity * m).dot(&x[i]);
        }
        for c in &self.penalties {
            let i = c.node as usize;
            e += c.energy(&x[i], &self.xprev[i]);
        }
        e + self.grasp_energy_grad(x, None)
    }

    /// Newton solve of the incremental potential from `self.pos` with the active constraints.
    pub(super) fn newton(
        &mut self,
        p: &Problem,
        max_iter: usize,
        line_search: bool,
        stats: &mut StepStats,
    ) -> Result<(), FemError> {
        let n = self.n_nodes();
        let tol_x = self.config.newton_tolerance * self.model.length_scale;
        stats.converged = false;
        // set only by a chord solve that ends with the gradient at `pos` evaluated
        self.grad_at_pos = None;
        let c_stiff_pre = 1.0 + p.c_kdamp;
        let c_mass_pre = p.c_mass + p.c_damp;
        // constrained components to targets
        self.predict_constrained(p, stats)?;
        if self.config.quasi_newton && line_search {
            // chord iterations first; exact Newton takes over when they stall (strong nonlinearity)
            if self.chord(p, 8, stats)? {
                return Ok(());
            }
        }
        // exact Hessian first; per-quadrature-point PSD projection once it proves indefinite
        let mut project = false;
        for _it in 0..max_iter {
            stats.factorizations += self.ensure_precond(c_mass_pre, c_stiff_pre)?;
            stats.newton_iterations += 1;
            let mut egrad = std::mem::take(&mut self.egrad);
            let mut hess = std::mem::take(&mut self.hess);
            let damping = (p.c_kdamp > 0.0).then_some((&self.xprev[..], p.c_kdamp));
            self.eval_elastic(&mut egrad, &mut hess, project, damping);
            // gradient
            let mut grad = std::mem::take(&mut self.grad);
            self.assemble_gradient(p, &self.pos, &egrad, &mut grad);
            let pat = &self.model.pattern;
            for i in 0..n {
                let m = self.model.mass[i];
                hess[pat.diag[i] as usize] += Matrix3::identity() * (m * (p.c_mass + p.c_damp));
            }
            for g in &self.grasps {
                for &i in &g.nodes {
                    hess[pat.diag[i as usize] as usize] += Matrix3::identity() * g.params.stiffness;
                }
            }
            for c in &self.penalties {
                let i = c.node as usize;
                hess[pat.diag[i] as usize] += c.hessian(&self.pos[i], &self.xprev[i]);
            }
            // grasp low-rank corrections (saturated grasps), per grasp: (H_h - K I) / n^2 on the mean
            let mut lowrank: Vec<(usize, Matrix3<f64>)> = Vec::new();
            for (gi, g) in self.grasps.iter().enumerate() {
                let nn = g.nodes.len() as f64;
                let kk = nn * g.params.stiffness;
                let dbar: Vector3<f64> = g
                    .nodes
                    .iter()
                    .zip(&g.anchor)
                    .map(|(&i, a)| self.pos[i as usize] - a)
                    .sum::<Vector3<f64>>()
                    / nn;
                let r = dbar.norm();
                if kk * r > g.params.force_limit {
                    let u = dbar / r;
                    let hh = (Matrix3::identity() - u * u.transpose()) * (g.params.force_limit / r);
                    lowrank.push((gi, (hh - Matrix3::identity() * kk) / (nn * nn)));
                }
            }
            self.egrad = egrad;
            // solve H d = -g (filtered)
            for gi in grad.iter_mut() {
                *gi = -*gi;
            }
            Self::apply_filter(&self.active, &mut grad);
            let gnorm = max_component(&grad);
            if gnorm == 0.0 {
                self.grad = grad;
                self.hess = hess;
                stats.converged = true;
                break;
            }
            let mut delta = std::mem::take(&mut self.delta);
            let mut cg = std::mem::take(&mut self.cg);
            let (_, pre) = self.precond.as_mut().expect("factored above");
            let active = &self.active;
            let grasps = &self.grasps;
            let res = pcg(
                |v, y| {
                    pat.spmv(&hess, v, y);
                    for (gi, m) in &lowrank {
                        let g = &grasps[*gi];
                        let s: Vector3<f64> = g.nodes.iter().map(|&i| v[i as usize]).sum();
                        let add = m * s;
                        for &i in &g.nodes {
                            y[i as usize] += add;
                        }
                    }
                },
                |z| pre.solve_in_place(z),
                |v| Self::apply_filter(active, v),
                &grad,
                &mut delta,
                self.config.linear_tolerance,
                self.config.linear_max_iterations,
                &mut cg,
            );
            self.cg = cg;
            stats.linear_iterations += res.iterations;
            self.last_linear_iterations = res.iterations;
            if !project && dot(&grad, &delta) <= 0.0 {
                // not a descent direction: redo this iteration with the projected Hessian
                project = true;
                self.grad = grad;
                self.hess = hess;
                self.delta = delta;
                continue;
            }
            let step_max = max_component(&delta);
            if !step_max.is_finite() {
                self.grad = grad;
                self.hess = hess;
                self.delta = delta;
                return Err(FemError::Exploded {
                    step: self.steps,
                    max_speed: f64::INFINITY,
                });
            }
            let mut alpha = 1.0;
            if line_search && step_max > tol_x {
                let mut trial = std::mem::take(&mut self.trial);
                let e0 = self.potential(p, &self.pos);
                // grad holds -g; slope = g . d = -(grad . d)
                let slope = -dot(&grad, &delta);
                let mut accepted = false;
                for _ in 0..30 {
                    for i in 0..n {
                        trial[i] = self.pos[i] + delta[i] * alpha;
                    }
                    let e1 = self.potential(p, &trial);
                    if e1.is_finite() && e1 <= e0 + 1e-4 * alpha * slope + 1e-12 * e0.abs() {
                        accepted = true;
                        break;
                    }
                    alpha *= 0.5;
                }
                self.trial = trial;
                if !accepted {
                    alpha = 0.0;
                }
            }
            if alpha == 0.0 && !project {
                // no decrease along the exact-Hessian direction: retry with the projected Hessian
                project = true;
                self.grad = grad;
                self.hess = hess;
                self.delta = delta;
                continue;
            }
            for i in 0..n {
                self.pos[i] += delta[i] * alpha;
            }
            self.grad = grad;
            self.hess = hess;
            self.delta = delta;
            if step_max * alpha <= tol_x {
                // `gnorm`: the filtered residual at the start of this iteration
                stats.converged =
                    (alpha > 0.0 || step_max <= tol_x) && gnorm <= self.residual_bound(p);
                break;
            }
            if alpha == 0.0 {
                break;
            }
            if self.last_linear_iterations > self.config.refactor_iterations {
                // the rest-state preconditioner no longer fits the current shape: refactor here
                self.precond_at = Some(self.pos.clone());
                self.precond_gen += 1;
                self.precond = None;
            }
        }
        Ok(())
    }

    /// Gradient of the potential at the current positions (for constraint forces), into `self.grad`.
    pub(super) fn final_gradient(&mut self, p: &Problem) -> usize {
        let mut egrad = std::mem::take(&mut self.egrad);
        let mut grad = std::mem::take(&mut self.grad);
        let inverted = self
            .gradient_at(p, &self.pos, &mut egrad, &mut grad, false)
            .inverted;
        self.egrad = egrad;
        self.grad = grad;
        inverted
    }

    /// [`FemSolid::final_gradient`] after a Newton solve: the chord's own evaluation at `pos`
    /// when it left one, else a new one.
    pub(super) fn gradient_after_solve(&mut self, p: &Problem) -> usize {
        match self.grad_at_pos.take() {
            Some(inverted) => inverted,
            None => self.final_gradient(p),
        }
    }

    /// The incremental potential's gradient at `x` into `grad` (its elastic part, scaled, into
    /// `egrad`), with the unscaled elastic energy when `with_energy` (else 0).
    pub(super) fn gradient_at(
        &self,
        p: &Problem,
        x: &[Vector3<f64>],
        egrad: &mut [Vector3<f64>],
        grad: &mut [Vector3<f64>],
        with_energy: bool,
    ) -> KernelStats {
        let damping = (p.c_kdamp > 0.0).then_some((&self.xprev[..], p.c_kdamp));
        let stats = self.model.kernel(x, Some(egrad), damping, with_energy);
        let k = self.stiffness_scale;
        if k != 1.0 {
            egrad.iter_mut().for_each(|g| *g *= k);
        }
        self.assemble_gradient(p, x, egrad, grad);
        stats
    }

    /// The incremental potential's gradient at `x` from the (scaled) elastic one.
    fn assemble_gradient(
        &self,
        p: &Problem,
        x: &[Vector3<f64>],
        egrad: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
    ) {
        for i in 0..self.n_nodes() {
            let m = self.model.mass[i];
            let mut g = egrad[i] - self.ext_force[i] - self.fric[i] - p.gravity * m;
            if p.c_mass > 0.0 {
                g += (x[i] - self.xhat[i]) * (m * p.c_mass);
            }
            if p.c_damp > 0.0 {
                g += (x[i] - self.xprev[i]) * (m * p.c_damp);
            }
            grad[i] = g;
        }
        for c in &self.penalties {
            let i = c.node as usize;
            grad[i] += c.gradient(&x[i], &self.xprev[i]);
        }
        self.grasp_energy_grad(x, Some(grad));
    }
}
