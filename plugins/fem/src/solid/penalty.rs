//! Penalty contacts ([`FemConfig::penalty_contacts`]): the step's contact candidates as energies
//! of the incremental potential (the terms are [`PenaltyContact`]'s), their memory for the next
//! step's lagged friction, and their reactions on the rigid bodies.
//!
//! [`FemConfig::penalty_contacts`]: crate::FemConfig::penalty_contacts

use super::{quantised_normal, ContactMemory, FemSolid, PenaltyContact, SLIP_SPEED};
use crate::coupling::Reaction;
use nalgebra::Vector3;

/// A stiffness rounded to a quarter power of two (0 stays 0): the factored matrix holds the
/// penalty contacts' Hessians to within 19 %, and a steady contact set reuses its factor.
fn quantised_stiffness(k: f64) -> f64 {
    if k > 0.0 && k.is_finite() {
        ((k.log2() * 4.0).round() / 4.0).exp2()
    } else {
        0.0
    }
}

impl FemSolid {
    /// One penalty term per contact candidate of the step (in candidate order): stiffness
    /// `penalty_contacts m c_mass`, friction from the candidate's normal force (the last step's
    /// on this node and body, or the one stopping its predicted penetration), the collider's
    /// surface displacement over the step as the reference of the slip.
    /// (`step_once` empties the list after every solve.)
    pub(super) fn build_penalties(&mut self, dt: f64, c_mass: f64) {
        for c in &self.candidates {
            let m = self.model.mass[c.node as usize];
            self.penalties.push(PenaltyContact {
                node: c.node,
                point: c.contact.point,
                normal: c.contact.normal,
                stiffness: self.config.penalty_contacts * m * c_mass,
                mu_lambda: c.contact.friction * c.normal_force.max(0.0),
                shift: c.contact.velocity * dt,
                eps: SLIP_SPEED * dt,
            });
        }
    }

    /// The penalty contacts' Hessians for the factored matrix (the chord matrix and the
    /// preconditioner) of this step, into `penalty_factor`: per contact, `k_t I + (k_n - k_t)
    /// n n^T` with the contact's Hessian stiffnesses (`PenaltyContact::stiffnesses`), both
    /// rounded ([`quantised_stiffness`]), as entries
    /// with non-negative stiffness (the plane's two directions when `k_t > k_n`), at the
    /// step's predicted positions `x_n + dt v_n` (a function of the state: a steady contact
    /// set keeps its factor from step to step, and one evaluation per Newton iteration
    /// refactored three to four times per step in a Spot Bend episode for nothing). Without
    /// them the factor lacked the contacts' stiffness (the sticking friction's is hundreds of
    /// times a node's inertia), the chord stalled and exact Newton's conjugate gradients
    /// needed 100-250 iterations per solve under a heavy box (a 20 kg box on a belt: 3.9 steps/s,
    /// 43 with them). Left out when their columns would cost less as conjugate-gradient
    /// iterations (about one per column, each a solve with the factor) than a factorisation.
    pub(super) fn penalty_blocks(&mut self, dt: f64) {
        let mut out = std::mem::take(&mut self.penalty_factor);
        out.clear();
        for p in &self.penalties {
            let i = p.node as usize;
            let x = self.xprev[i] + self.vprev[i] * dt;
            let (kn, kt) = p.stiffnesses(&x, &self.xprev[i]);
            let (kn, kt) = (quantised_stiffness(kn), quantised_stiffness(kt));
            if kn == 0.0 && kt == 0.0 {
                continue;
            }
            let n = quantised_normal(&p.normal);
            let Some(unit) = n.try_normalize(1e-12) else {
                continue;
            };
            if kn >= kt {
                if kt > 0.0 {
                    out.push((p.node, n, true, Some(kt)));
                }
                if kn > kt {
                    out.push((p.node, n, false, Some(kn - kt)));
                }
            } else {
                if kn > 0.0 {
                    out.push((p.node, n, true, Some(kn)));
                }
                let axis = if unit.x.abs() < 0.6 {
                    Vector3::x()
                } else {
                    Vector3::y()
                };
                let t1 = unit.cross(&axis).normalize();
                let t2 = unit.cross(&t1);
                out.push((p.node, t1, false, Some(kt - kn)));
                out.push((p.node, t2, false, Some(kt - kn)));
            }
        }
        let columns: usize = out.iter().map(|c| if c.2 { 3 } else { 1 }).sum();
        let (factor_cost, solve_cost) = self.profile_costs;
        if (columns as f64) * solve_cost < factor_cost {
            out.clear();
        }
        self.penalty_factor = out;
    }

    /// Contact memory of the penetrating penalty contacts at the step's end (normal force,
    /// sticking or sliding, slip direction), for the next step's lagged friction.
    pub(super) fn remember_penalties(&mut self) {
        for (p, c) in self.penalties.iter().zip(&self.candidates) {
            let i = p.node as usize;
            let gap = p.gap(&self.pos[i]);
            if gap >= 0.0 {
                continue;
            }
            let u = p.slip(&self.pos[i], &self.xprev[i]);
            let y = u.norm();
            self.contact_memory.push(ContactMemory {
                node: p.node,
                body: c.contact.body,
                stick: y < p.eps,
                slip_dir: if y > 0.0 { -u / y } else { Vector3::zeros() },
                normal_force: -gap * p.stiffness,
            });
        }
    }

    /// Pushes the impulses the penalty contacts applied on their bodies over the step (normal
    /// and friction) and returns the number of contacts pressing at its end.
    pub(super) fn penalty_reactions(&self, dt: f64, reactions: &mut Vec<Reaction>) -> usize {
        let mut pressing = 0;
        for (p, c) in self.penalties.iter().zip(&self.candidates) {
            let i = p.node as usize;
            let force_on_node = -p.gradient(&self.pos[i], &self.xprev[i]);
            if p.gap(&self.pos[i]) < 0.0 {
                pressing += 1;
            }
            if force_on_node != Vector3::zeros() {
                reactions.push(Reaction {
                    body: c.contact.body,
                    point: c.contact.point,
                    impulse: -force_on_node * dt,
                });
            }
        }
        pressing
    }
}
