//! Penalty contacts ([`FemConfig::penalty_contacts`]): the step's contact candidates as energies
//! of the incremental potential (the terms are [`PenaltyContact`]'s), their memory for the next
//! step's lagged friction, and their reactions on the rigid bodies.
//!
//! [`FemConfig::penalty_contacts`]: crate::FemConfig::penalty_contacts

use super::{ContactMemory, FemSolid, PenaltyContact, SLIP_SPEED};
use crate::coupling::Reaction;
use nalgebra::Vector3;

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
