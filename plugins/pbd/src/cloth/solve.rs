//! The constraint projections of a substep: attachments, tethers, contacts (particles and
//! edge midpoints), friction, and the distance and bending sweeps.

use super::Cloth;
use crate::lanes::{self, BendRow, DistRow, P4};
use nalgebra::{Point3, Vector3};

impl Cloth {
    pub(super) fn solve_attachments(&mut self, alpha_t: f64, h: f64) {
        let limit_scale = h * h;
        for a in &mut self.attachments {
            if a.kinematic {
                continue;
            }
            let Some(f) = a.frame else { continue };
            let pose = self.frame_now[f as usize];
            let mut total = Vector3::zeros();
            for (k, &p) in a.particles.iter().enumerate() {
                let w = self.inv_mass[p as usize];
                if w == 0.0 {
                    a.cand[k] = a.lambda[k];
                    continue;
                }
                let target = pose.transform_point(&Point3::from(a.local[k])).coords;
                let c = self.x[p as usize].to_v() - target;
                let dl = (-c - a.lambda[k] * alpha_t) / (w + alpha_t);
                a.cand[k] = a.lambda[k] + dl;
                total += a.cand[k];
            }
            let tn = total.norm();
            let lim = a.max_force * limit_scale;
            let scale = if tn > lim { lim / tn } else { 1.0 };
            for (k, &p) in a.particles.iter().enumerate() {
                let nl = a.cand[k] * scale;
                let w = self.inv_mass[p as usize];
                self.x[p as usize] += P4::from_v(&((nl - a.lambda[k]) * w));
                a.lambda[k] = nl;
            }
        }
    }

    /// Long-range attachments: a particle farther from its (kinematic, never moving) anchor than
    /// the tether length is moved back onto the sphere. Branch-free over the compact rows, four at
    /// a time ([`lanes::tethers`]; whether a tether is active is data dependent and mispredicted
    /// often); anchors have zero inverse mass, so rows touch only their own particle and their
    /// order does not matter.
    pub(super) fn solve_tethers(&mut self) {
        lanes::tethers(self.avx2, &mut self.x, &self.tether_rows);
    }

    /// Tethers anchored at grasped particles ([`SolverSettings::grasp_tethers`]), "follow the
    /// leader" along the shortest-path tree from the grasp (Müller, Kim, Chentanez, "Fast
    /// simulation of inextensible hair and fur", 2012): in tree order (parents first) a particle
    /// farther from its parent than their edge's rest length times
    /// `1 + SolverSettings::grasp_tether_slack` is moved back onto that sphere; the parent is not
    /// moved (the slack keeps the sweep off in the cloth's ordinary slightly stretched state:
    /// with none, it pulled the whole sheet towards the grasp by the sum of the edges' small
    /// stretches at every substep, and the sheet flew off the table). One sweep carries a pull
    /// across the whole sheet, and, unlike straight-line tethers, along the cloth around a
    /// table's edge (a straight tether pressed the particles hanging over the far edge into the
    /// table's side, where friction held them).
    ///
    /// The sweep is a limit on stretch, not a load path: its corrections are neither reported
    /// to the gripper's body nor counted against the grasp's force limit (the grasp attachment
    /// itself still carries and reports the pull of its neighbours). Counting the impulse of
    /// the corrections overstated the load, because the contacts undo part of them at every
    /// substep: it reached the grasp's whole limit (130 N for Spot) while a cover slid off a
    /// table and dragged Spot back to the table (Spot Uncover: 5 of 8 seeds with it, 8 of 8
    /// without).
    ///
    /// [`SolverSettings::grasp_tethers`]: crate::material::SolverSettings::grasp_tethers
    pub(super) fn solve_grasp_tethers(&mut self) {
        for &(i, par, len) in &self.grasp_tether_rows {
            let d = self.x[i as usize] - self.x[par as usize];
            let l = d.norm();
            if l > len {
                self.x[i as usize] -= d * ((l - len) / l);
            }
        }
    }

    /// Keeps mesh-edge midpoints outside the colliders (so that an edge does not cut a
    /// collider's corner between two particles). Friction is applied after the iterations.
    pub(super) fn solve_edge_contacts(&mut self, t_end: f64, half: f64, h: f64) {
        for c in 0..self.e_edge.len() {
            let [a, b] = self.edge[self.e_edge[c] as usize];
            let (a, b) = (a as usize, b as usize);
            let (wa, wb) = (self.inv_mass[a], self.inv_mass[b]);
            let n = self.e_normal[c];
            let plane = self.e_point[c] + self.e_vel[c] * t_end;
            let mid = (self.x[a] + self.x[b]) * 0.5;
            let gap = n.dot(mid - plane) - half;
            if gap < 0.0 {
                let lam = -gap / (0.25 * (wa + wb));
                self.x[a] += n * (0.5 * wa * lam);
                self.x[b] += n * (0.5 * wb * lam);
                let moved = 0.5 * lam * (self.mass[a] * wa + self.mass[b] * wb);
                self.e_impulse[c] += n * (moved / h);
                self.e_dn[c] -= gap;
            }
        }
    }

    pub(super) fn solve_contacts_normal(&mut self, t_end: f64, half: f64) {
        for c in 0..self.c_particle.len() {
            let p = self.c_particle[c] as usize;
            if self.inv_mass[p] == 0.0 {
                continue;
            }
            let n = self.c_normal[c];
            let plane = self.c_point[c] + self.c_vel[c] * t_end;
            let gap = n.dot(self.x[p] - plane) - half;
            if gap < 0.0 {
                self.x[p] -= n * gap;
                self.c_dn[c] -= gap;
            }
        }
    }

    /// Final normal projection after friction (positions and impulses, no friction).
    pub(super) fn reproject_contacts(&mut self, t_end: f64, half: f64, h: f64) {
        for c in 0..self.c_particle.len() {
            let p = self.c_particle[c] as usize;
            if self.inv_mass[p] == 0.0 {
                continue;
            }
            let n = self.c_normal[c];
            let plane = self.c_point[c] + self.c_vel[c] * t_end;
            let gap = n.dot(self.x[p] - plane) - half;
            if gap < 0.0 {
                self.x[p] -= n * gap;
                self.c_impulse[c] -= n * (gap * self.mass[p] / h);
            }
        }
    }

    pub(super) fn apply_edge_friction(&mut self, h: f64) {
        for c in 0..self.e_edge.len() {
            let dn = self.e_dn[c];
            if dn <= 0.0 {
                continue;
            }
            let [a, b] = self.edge[self.e_edge[c] as usize];
            let (a, b) = (a as usize, b as usize);
            let (wa, wb) = (self.inv_mass[a], self.inv_mass[b]);
            let n = self.e_normal[c];
            let mid = (self.x[a] + self.x[b]) * 0.5;
            let mid_prev = (self.prev[a] + self.prev[b]) * 0.5;
            let rel = (mid - mid_prev) - self.e_vel[c] * h;
            let tang = rel - n * n.dot(rel);
            let tl = tang.norm();
            let lim = self.e_mu[c] * dn;
            let target = if tl <= lim { -tang } else { -tang * (lim / tl) };
            // move the midpoint by `target`: dx_i = w_i / 2 * target / ((w_a + w_b) / 4)
            let s = 2.0 / (wa + wb);
            self.x[a] += target * (wa * s);
            self.x[b] += target * (wb * s);
            let moved = (self.mass[a] * wa + self.mass[b] * wb) * s;
            self.e_impulse[c] += target * (moved / h);
        }
    }

    pub(super) fn apply_friction(&mut self, h: f64) {
        for c in 0..self.c_particle.len() {
            let dn = self.c_dn[c];
            if dn <= 0.0 {
                continue;
            }
            let p = self.c_particle[c] as usize;
            let n = self.c_normal[c];
            let rel = (self.x[p] - self.prev[p]) - self.c_vel[c] * h;
            let tang = rel - n * n.dot(rel);
            let tl = tang.norm();
            let lim = self.c_mu[c] * dn;
            let corr = if tl <= lim { -tang } else { -tang * (lim / tl) };
            self.x[p] += corr;
            self.c_impulse[c] += (n * dn + corr) * (self.mass[p] / h);
        }
    }
}

/// One Gauss-Seidel sweep over distance constraints (XPBD, Macklin et al. 2016, eq. 18):
/// `dlambda = (-C - alpha~ lambda) / (w_a + w_b + alpha~)`, `dx_a = w_a dlambda n`.
#[inline(never)]
pub(super) fn solve_distances(pos: &mut [P4], rows: &[DistRow], lambda: &mut [f64]) {
    for (r, lam) in rows.iter().zip(lambda.iter_mut()) {
        let (a, b) = (r.a as usize, r.b as usize);
        let d = pos[a] - pos[b];
        let l = d.norm();
        if l < 1e-12 {
            continue;
        }
        let num = r.rest - l - r.at * *lam;
        *lam += num * r.inv_denom;
        let s = num / l;
        pos[a] += d * (s * r.ka);
        pos[b] -= d * (s * r.kb);
    }
}

/// One sweep over isometric bending hinges. The constraint `C = sum_i K_i x_i` is linear, so its
/// XPBD update is exact in one projection: `dlambda = (-C - alpha~ lambda) / (sum_i w_i K_i^2 +
/// alpha~)` (a 3-vector), `dx_i = w_i K_i dlambda`.
#[inline(never)]
pub(super) fn solve_bending(pos: &mut [P4], rows: &[BendRow], lambda: &mut [P4]) {
    for (r, lam) in rows.iter().zip(lambda.iter_mut()) {
        let [i0, i1, i2, i3] = r.ids.map(|i| i as usize);
        let k = r.k;
        let c = pos[i0] * k[0] + pos[i1] * k[1] + pos[i2] * k[2] + pos[i3] * k[3];
        let num = -c - *lam * r.at;
        *lam += num * r.inv_denom;
        pos[i0] += num * r.wk[0];
        pos[i1] += num * r.wk[1];
        pos[i2] += num * r.wk[2];
        pos[i3] += num * r.wk[3];
    }
}
