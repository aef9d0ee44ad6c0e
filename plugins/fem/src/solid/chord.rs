//! The chord (quasi-Newton) solver: the constrained predictor, the residual bound of a converged
//! step, and chord iterations with the cached factor.

use super::{finite3, max_component, ConKind, FemSolid, Problem, StepStats};
use crate::error::FemError;
use crate::sparse::{dot, pcg};
use nalgebra::Vector3;

impl FemSolid {
    /// Moves the constrained components to their targets. World constraints and attachments are
    /// set directly; contact displacements `d` go through a linearised predictor, so that the free
    /// nodes follow: `x += d + u` with `A u = -(g + A d)` on the free components (`A` the factored
    /// matrix without contact penalties, `g` the gradient at `x`; filtered PCG, factor as
    /// preconditioner). Setting only the contact nodes would invert every element of a thin body
    /// whose contact side moves by more than its thickness in one step (a collider moving at 1 m/s
    /// against a 4 mm belt), and Newton then crawls out of the inverted state in tiny line-search
    /// steps.
    pub(super) fn predict_constrained(
        &mut self,
        p: &Problem,
        stats: &mut StepStats,
    ) -> Result<(), FemError> {
        let n = self.n_nodes();
        let tol_x = self.config.newton_tolerance * self.model.length_scale;
        let has_contacts = self
            .active
            .iter()
            .any(|c| matches!(c.kind, ConKind::Contact));
        let mut d = if has_contacts {
            vec![Vector3::zeros(); n]
        } else {
            Vec::new()
        };
        let mut contact_moves = false;
        for c in &self.active {
            let i = c.node as usize;
            let di = c.proj * (c.target - self.pos[i]);
            if matches!(c.kind, ConKind::Contact) {
                d[i] = di;
                contact_moves |= di.amax() > tol_x;
            } else {
                self.pos[i] += di;
            }
        }
        if contact_moves {
            stats.factorizations += self.ensure_precond(p.c_mass + p.c_damp, 1.0 + p.c_kdamp)?;
            self.final_gradient(p);
            let mut r = vec![Vector3::zeros(); n];
            self.model.pattern.spmv(&self.precond_mat, &d, &mut r);
            for (ri, gi) in r.iter_mut().zip(&self.grad) {
                *ri = -(*ri + *gi);
            }
            Self::apply_filter(&self.active, &mut r);
            let mut u = std::mem::take(&mut self.delta);
            let mut cg = std::mem::take(&mut self.cg);
            let (_, pre) = self.precond.as_mut().expect("factored above");
            let pat = &self.model.pattern;
            let mat = &self.precond_mat;
            let active = &self.active;
            let res = pcg(
                |v, y| pat.spmv(mat, v, y),
                |z| pre.solve_in_place(z),
                |v| Self::apply_filter(active, v),
                &r,
                &mut u,
                1e-3,
                self.config.linear_max_iterations,
                &mut cg,
            );
            self.cg = cg;
            stats.linear_iterations += res.iterations;
            if u.iter().all(finite3) {
                for (di, ui) in d.iter_mut().zip(&u) {
                    *di += *ui;
                }
            }
            self.delta = u;
        }
        for (x, di) in self.pos.iter_mut().zip(&d) {
            *x += *di;
        }
        Ok(())
    }

    /// Largest residual force (N, any component) with which a dynamic step's small final step
    /// counts as convergence: a tenth of the force that would move the heaviest node by the
    /// solid's size within the step (`m l / dt^2`; no bound for statics). Converged steps of the
    /// task scenes end with residuals under 2 N where this bound is 60 to 600 N; a chord matrix
    /// gone bad (Spot Lift, held-out seed 37) took steps of 1e-19 m at residuals of 4e3 N and
    /// more, which the step-size test alone accepted, and the belt flew apart unreported.
    pub(super) fn residual_bound(&self, p: &Problem) -> f64 {
        if p.c_mass > 0.0 {
            let m = self.model.mass.iter().fold(0.0f64, |a, &b| a.max(b));
            0.1 * m * self.model.length_scale * p.c_mass
        } else {
            f64::INFINITY
        }
    }

    /// Chord (quasi-Newton) iterations with the cached factor as the Newton matrix, Armijo line
    /// search on the potential, and a refactor at the current shape when the contraction rate
    /// exceeds 0.5 (the reference shape no longer represents the tangent).
    pub(super) fn chord(
        &mut self,
        p: &Problem,
        max_iter: usize,
        stats: &mut StepStats,
    ) -> Result<bool, FemError> {
        let n = self.n_nodes();
        let tol_x = self.config.newton_tolerance * self.model.length_scale;
        let c_stiff_pre = 1.0 + p.c_kdamp;
        let c_mass_pre = p.c_mass + p.c_damp;
        let mut prev_step = f64::INFINITY;
        let mut refactored = false;
        // potential at `self.pos` once a line search has evaluated it there (the accepted trial is
        // bitwise the new position)
        let mut e_pos: Option<f64> = None;
        if self.config.warped_chord {
            let x_ref = self.precond_at.as_ref().unwrap_or(&self.model.mesh.rest);
            self.warp
                .update(&self.model.mesh.elements, x_ref, &self.pos);
            // contact penalties (and penalty contacts' Hessians where the factor holds them)
            // sit in the factor along world directions: those nodes stay unturned
            self.warp.unwarp(
                self.active
                    .iter()
                    .filter(|c| matches!(c.kind, ConKind::Contact))
                    .map(|c| c.node)
                    .chain(self.penalty_factor.iter().map(|c| c.0)),
            );
        } else {
            self.warp.reset();
        }
        // `Some(inverted)`: `grad` holds the gradient at `pos` (evaluated with the line search's
        // first trial, which became `pos`)
        let mut grad_ready: Option<usize> = None;
        for _ in 0..max_iter {
            stats.factorizations += self.ensure_precond(c_mass_pre, c_stiff_pre)?;
            stats.newton_iterations += 1;
            if grad_ready.take().is_none() {
                self.final_gradient(p);
            }
            let mut delta = std::mem::take(&mut self.delta);
            for (d, g) in delta.iter_mut().zip(&self.grad) {
                *d = -*g;
            }
            Self::apply_filter(&self.active, &mut delta);
            let r = delta.clone();
            // constraints the factor does not contain (contacts) need a filtered PCG on the factored
            // matrix; otherwise one triangular solve is the exact chord step
            let needs_pcg = self
                .active
                .iter()
                .any(|c| matches!(c.kind, ConKind::Contact));
            let (_, pre) = self.precond.as_mut().expect("factored above");
            if needs_pcg {
                let mut cg = std::mem::take(&mut self.cg);
                let pat = &self.model.pattern;
                let mat = &self.precond_mat;
                let active = &self.active;
                let warp = &self.warp;
                // the line search's buffer is free until the line search
                let mut tmp = std::mem::take(&mut self.trial);
                let res = pcg(
                    |v, y| warp.apply(v, y, &mut tmp, |u, out| pat.spmv(mat, u, out)),
                    |z| {
                        warp.turn_back(z);
                        pre.solve_in_place(z);
                        warp.turn(z);
                    },
                    |v| Self::apply_filter(active, v),
                    &r,
                    &mut delta,
                    1e-3,
                    self.config.linear_max_iterations,
                    &mut cg,
                );
                self.trial = tmp;
                self.cg = cg;
                stats.linear_iterations += res.iterations;
            } else {
                self.warp.turn_back(&mut delta);
                pre.solve_in_place(&mut delta);
                self.warp.turn(&mut delta);
                Self::apply_filter(&self.active, &mut delta);
                stats.linear_iterations += 1;
            }
            let step_max = max_component(&delta);
            if !step_max.is_finite() {
                self.delta = delta;
                return Err(FemError::Exploded {
                    step: self.steps,
                    max_speed: f64::INFINITY,
                });
            }
            let mut alpha = 1.0;
            if step_max > tol_x {
                let mut trial = std::mem::take(&mut self.trial);
                let e0 = match e_pos {
                    Some(e) => e,
                    None => self.potential(p, &self.pos),
                };
                let slope = -dot(&r, &delta);
                let mut accepted = None;
                // a warped step is taken whole or not at all: one that needs damping means the
                // rotations do not fit this shape (a belt crushed by a fast box), and its damped
                // version would move the state in a poor direction; the refactor below follows
                let warped = self.warp.is_on();
                for k in 0..30 {
                    for i in 0..n {
                        trial[i] = self.pos[i] + delta[i] * alpha;
                    }
                    // the full step (usually taken) evaluates the gradient with the energy, in
                    // one pass: the next iteration's gradient if the step is accepted
                    let e1 = if k == 0 {
                        let mut egrad = std::mem::take(&mut self.trial_egrad);
                        let mut grad = std::mem::take(&mut self.trial_grad);
                        let st = self.gradient_at(p, &trial, &mut egrad, &mut grad, true);
                        self.trial_egrad = egrad;
                        self.trial_grad = grad;
                        grad_ready = Some(st.inverted);
                        self.potential_with(p, &trial, st.energy)
                    } else {
                        grad_ready = None;
                        self.potential(p, &trial)
                    };
                    if e1.is_finite() && e1 <= e0 + 1e-4 * alpha * slope + 1e-12 * e0.abs() {
                        accepted = Some(e1);
                        break;
                    }
                    if warped {
                        break;
                    }
                    alpha *= 0.5;
                }
                self.trial = trial;
                if accepted.is_none() {
                    alpha = 0.0;
                }
                // rejected: the position stays and so does its potential
                e_pos = accepted.or(Some(e0));
            } else {
                e_pos = None;
            }
            for i in 0..n {
                self.pos[i] += delta[i] * alpha;
            }
            self.delta = delta;
            if alpha == 1.0 && grad_ready.is_some() {
                // `pos` is bitwise the first trial point
                std::mem::swap(&mut self.egrad, &mut self.trial_egrad);
                std::mem::swap(&mut self.grad, &mut self.trial_grad);
            } else {
                grad_ready = None;
            }
            let moved = step_max * alpha;
            if alpha > 0.0 && moved <= tol_x || step_max <= tol_x {
                if max_component(&r) > self.residual_bound(p) {
                    // a tiny step at a large residual: the chord matrix no longer describes this
                    // shape (it is not convergence); exact Newton takes over
                    return Ok(false);
                }
                stats.converged = true;
                self.grad_at_pos = grad_ready;
                return Ok(true);
            }
            if (alpha < 1.0 || moved > 0.5 * prev_step) && !refactored {
                // slow or damped convergence: refactor the matrix at the current shape (once per solve)
                self.precond_at = Some(self.pos.clone());
                self.precond_gen += 1;
                self.precond = None;
                self.warp.reset();
                refactored = true;
            } else if alpha == 0.0 {
                return Ok(false);
            }
            prev_step = moved;
        }
        Ok(false)
    }
}
