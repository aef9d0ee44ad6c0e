//! The step: rigid contacts gathered once per step (and requeried for moved particles) and the
//! XPBD substeps.

use super::solve::{solve_bending, solve_distances};
use super::{finite3, Cloth, StepStats};
use crate::coupling::{ContactQuery, Reaction};
use crate::error::PbdError;
use crate::lanes::{self, P4};
use modesuite_engine::math::interpolate_pose;
use nalgebra::{Point3, Translation3, Vector3};

impl Cloth {
    // ------------------------------------------------------------------ stepping

    /// Advances the cloth by `dt` seconds under `gravity` (m/s^2, world frame), colliding with the
    /// colliders `query` reports; impulses applied on rigid bodies are appended to `reactions`.
    ///
    /// On a non-finite result the state is rolled back to the start of the step and an error is
    /// returned (nothing is appended to `reactions`).
    pub fn step(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, PbdError> {
        crate::error::check_param("dt", dt, 0.0, true, "a finite time step > 0 s")?;
        if !finite3(gravity) {
            return Err(PbdError::InvalidParameter {
                field: "gravity",
                value: format!("{gravity:?}"),
                expected: "a finite vector",
            });
        }
        self.save_pos.copy_from_slice(&self.pos);
        self.save_vel.copy_from_slice(&self.vel);
        let saved_att: Vec<(Vec<Vector3<f64>>, bool, Vector3<f64>)> = self
            .attachments
            .iter()
            .map(|a| (a.local.clone(), a.slipped, a.impulse))
            .collect();
        for d in &self.drives {
            let moved = (self.time + dt).clamp(d.start, d.stop) - d.start;
            self.frames[d.frame as usize].target =
                Translation3::from(d.velocity * moved) * d.origin;
        }
        let result = self.step_inner(dt, gravity, query);
        let result = result.and_then(|stats| {
            match self
                .pos
                .iter()
                .zip(&self.vel)
                .position(|(x, v)| !(finite3(x) && finite3(v)))
            {
                Some(p) => Err(PbdError::NonFinite {
                    particle: p,
                    step: self.steps,
                }),
                None => Ok(stats),
            }
        });
        match result {
            Ok(stats) => {
                for f in &mut self.frames {
                    f.prev = f.target;
                }
                self.time += dt;
                self.steps += 1;
                // reactions: rigid contacts
                for c in 0..self.c_particle.len() {
                    let imp = self.c_impulse[c].to_v();
                    if self.c_body[c] != u32::MAX && imp != Vector3::zeros() {
                        reactions.push(Reaction {
                            body: self.c_body[c],
                            point: self.c_point[c].to_v(),
                            impulse: -imp,
                        });
                    }
                }
                for c in 0..self.e_edge.len() {
                    let imp = self.e_impulse[c].to_v();
                    if self.e_body[c] != u32::MAX && imp != Vector3::zeros() {
                        reactions.push(Reaction {
                            body: self.e_body[c],
                            point: self.e_point[c].to_v(),
                            impulse: -imp,
                        });
                    }
                }
                // reactions: force-limited frame attachments
                for a in &self.attachments {
                    if a.kinematic {
                        continue;
                    }
                    if let Some(f) = a.frame {
                        let body = self.frames[f as usize].body;
                        if body != u32::MAX && a.impulse != Vector3::zeros() {
                            let c: Vector3<f64> = a
                                .particles
                                .iter()
                                .map(|&p| self.pos[p as usize])
                                .sum::<Vector3<f64>>()
                                / a.particles.len() as f64;
                            reactions.push(Reaction {
                                body,
                                point: c,
                                impulse: -a.impulse,
                            });
                        }
                    }
                }
                Ok(stats)
            }
            Err(e) => {
                self.pos.copy_from_slice(&self.save_pos);
                self.vel.copy_from_slice(&self.save_vel);
                for (a, (l, s, i)) in self.attachments.iter_mut().zip(saved_att) {
                    a.local = l;
                    a.slipped = s;
                    a.impulse = i;
                }
                Err(e)
            }
        }
    }

    /// Appends the contacts in `query_buf` (queried at time `t_query` into the step) for
    /// particle `i`, validated; stores the plane point at the start of the step.
    fn push_queried(&mut self, i: usize, t_query: f64) -> Result<(), PbdError> {
        for k in 0..self.query_buf.len() {
            let c = self.query_buf[k];
            let ok = finite3(&c.point)
                && finite3(&c.normal)
                && finite3(&c.velocity)
                && c.friction.is_finite()
                && c.friction >= 0.0
                && c.distance.is_finite();
            let nn = c.normal.norm();
            if !ok || nn.is_nan() || nn <= 0.5 {
                return Err(PbdError::NonFiniteContact { particle: i });
            }
            self.c_particle.push(i as u32);
            self.c_point
                .push(P4::from_v(&(c.point - c.velocity * t_query)));
            self.c_normal.push(P4::from_v(&(c.normal / nn)));
            self.c_vel.push(P4::from_v(&c.velocity));
            self.c_mu.push((self.material.friction * c.friction).sqrt());
            self.c_body.push(c.body);
            self.c_dn.push(0.0);
            self.c_impulse.push(P4::ZERO);
        }
        Ok(())
    }

    /// Conservative guard against tunnelling: a particle that constraint corrections moved
    /// farther from where its colliders were last queried than that query's radius is queried
    /// again from its position at the start of the substep (outside the colliders), and the new
    /// planes are enforced before the substep ends.
    fn requery_moved(&mut self, query: &dyn ContactQuery, t_start: f64) -> Result<(), PbdError> {
        let half = 0.5 * self.material.thickness;
        for i in 0..self.x.len() {
            let g = self.guard_radius[i];
            if self.inv_mass[i] == 0.0 || (self.x[i] - self.guard_origin[i]).norm_squared() <= g * g
            {
                continue;
            }
            let from = self.prev[i];
            let r = half + (self.x[i] - from).norm() + self.settings.contact_margin;
            self.query_buf.clear();
            query.contacts_near(&from.to_v(), r, &mut self.query_buf);
            self.push_queried(i, t_start)?;
            self.guard_origin[i] = from;
            self.guard_radius[i] = r - half;
        }
        Ok(())
    }

    fn gather_contacts(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
    ) -> Result<(), PbdError> {
        self.c_particle.clear();
        self.c_point.clear();
        self.c_normal.clear();
        self.c_vel.clear();
        self.c_mu.clear();
        self.c_body.clear();
        self.c_dn.clear();
        self.c_impulse.clear();
        let half = 0.5 * self.material.thickness;
        let gdt = gravity.norm() * dt;
        let margin = self.settings.contact_margin;
        // query distance of a point moving at `speed`: half the thickness, the step's travel
        let radius = |speed: f64| half + (speed + gdt) * dt + margin;
        // every query below (particles, and edge midpoints with their endpoints' larger speed)
        // lies inside the particles' box padded by the largest query distance: the rigid world
        // narrows its colliders to that region once (same contacts, same order)
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        let mut reach: f64 = 0.0;
        for (x, v) in self.pos.iter().zip(&self.vel) {
            lo = lo.inf(x);
            hi = hi.sup(x);
            reach = reach.max(radius(v.norm()));
        }
        let pad = Vector3::repeat(reach * 1.01 + 1e-4);
        let region = if self.pos.is_empty() {
            None
        } else {
            query.region(&(lo - pad), &(hi + pad))
        };
        let query: &dyn ContactQuery = region.as_deref().unwrap_or(query);
        for i in 0..self.pos.len() {
            // pinned particles are queried too (their normals decide edge contacts) but never
            // moved by contacts
            let r = radius(self.vel[i].norm());
            self.query_buf.clear();
            query.contacts_near(&self.pos[i], r, &mut self.query_buf);
            self.push_queried(i, 0.0)?;
            self.guard_origin[i] = P4::from_v(&self.pos[i]);
            self.guard_radius[i] = r - half;
        }
        let m = self.c_particle.len();
        debug_assert_eq!(self.c_dn.len(), m);
        // midpoints of the mesh edges next to a touching particle
        self.e_edge.clear();
        self.e_point.clear();
        self.e_normal.clear();
        self.e_vel.clear();
        self.e_body.clear();
        self.e_mu.clear();
        // contacts are gathered in particle order: CSR starts
        self.contact_start.iter_mut().for_each(|c| *c = 0);
        for &p in &self.c_particle {
            self.contact_start[p as usize + 1] += 1;
        }
        for i in 0..self.pos.len() {
            self.contact_start[i + 1] += self.contact_start[i];
        }
        // An edge whose endpoints touch the same body through differently oriented surfaces
        // (e.g. the top and a side of a box) may cut the collider's corner between them.
        let wraps = |ca: std::ops::Range<usize>, cb: std::ops::Range<usize>| -> bool {
            ca.clone().any(|i| {
                cb.clone().any(|j| {
                    self.c_body[i] == self.c_body[j]
                        && self.c_normal[i].dot(self.c_normal[j]) < 0.985
                })
            })
        };
        for (k, &[a, b]) in self.edge.iter().enumerate() {
            let (a, b) = (a as usize, b as usize);
            let ca = self.contact_start[a] as usize..self.contact_start[a + 1] as usize;
            let cb = self.contact_start[b] as usize..self.contact_start[b + 1] as usize;
            if !self.settings.edge_contacts
                || self.inv_mass[a] + self.inv_mass[b] == 0.0
                || ca.is_empty()
                || cb.is_empty()
                || !wraps(ca, cb)
            {
                continue;
            }
            let mid = (self.pos[a] + self.pos[b]) * 0.5;
            let speed = self.vel[a].norm().max(self.vel[b].norm());
            let r = radius(speed);
            self.query_buf.clear();
            query.contacts_near(&mid, r, &mut self.query_buf);
            for c in &self.query_buf {
                let nn = c.normal.norm();
                let ok = finite3(&c.point) && finite3(&c.normal) && finite3(&c.velocity);
                if !ok || nn.is_nan() || nn <= 0.5 {
                    return Err(PbdError::NonFiniteContact { particle: a });
                }
                self.e_edge.push(k as u32);
                self.e_point.push(P4::from_v(&c.point));
                self.e_normal.push(P4::from_v(&(c.normal / nn)));
                self.e_vel.push(P4::from_v(&c.velocity));
                self.e_body.push(c.body);
                self.e_mu
                    .push((self.material.friction * c.friction.max(0.0)).sqrt());
            }
        }
        self.e_impulse.clear();
        self.e_impulse.resize(self.e_edge.len(), P4::ZERO);
        self.e_dn.clear();
        self.e_dn.resize(self.e_edge.len(), 0.0);
        Ok(())
    }

    fn step_inner(
        &mut self,
        dt: f64,
        gravity: &Vector3<f64>,
        query: &dyn ContactQuery,
    ) -> Result<StepStats, PbdError> {
        let ns = self.settings.substeps as usize;
        let h = dt / ns as f64;
        let inv_h2 = 1.0 / (h * h);
        self.refresh_caches(h);
        self.gather_contacts(dt, gravity, query)?;
        let mut self_pairs = 0;
        if self.settings.self_collision && !self.triangles.is_empty() {
            self_pairs = self.selfc.gather(
                &self.pos,
                &self.rest,
                &self.triangles,
                self.material.thickness,
                self.settings.self_collision_margin,
            );
        }
        for a in &mut self.attachments {
            a.slipped = false;
            a.impulse = Vector3::zeros();
        }
        let damp = 1.0 / (1.0 + self.material.damping * h);
        let half = 0.5 * self.material.thickness;
        let att_alpha = self.settings.attachment_compliance * inv_h2;
        for ((x, v), (p, u)) in self
            .x
            .iter_mut()
            .zip(&mut self.v)
            .zip(self.pos.iter().zip(&self.vel))
        {
            *x = P4::from_v(p);
            *v = P4::from_v(u);
        }
        let g4 = P4::from_v(gravity);
        for s in 0..ns {
            let t_end = (s + 1) as f64 * h;
            let frac = (s + 1) as f64 / ns as f64;
            self.frame_now.clear();
            for f in &self.frames {
                self.frame_now
                    .push(interpolate_pose(&f.prev, &f.target, frac));
            }
            // velocities of the substep before (if any), then predict, in one pass
            lanes::advance(
                self.avx2,
                &mut self.x,
                &mut self.v,
                &mut self.prev,
                &self.inv_mass,
                (s > 0).then_some(1.0 / h),
                damp,
                g4 * h,
                h,
            );
            // kinematic pins
            for a in &self.attachments {
                if a.kinematic {
                    for (k, &p) in a.particles.iter().enumerate() {
                        self.x[p as usize] = P4::from_v(&match a.frame {
                            None => a.local[k],
                            Some(f) => {
                                self.frame_now[f as usize]
                                    .transform_point(&Point3::from(a.local[k]))
                                    .coords
                            }
                        });
                    }
                }
            }
            self.e_dn.iter_mut().for_each(|d| *d = 0.0);
            if self.settings.iterations > 1 {
                self.dist_lambda.iter_mut().for_each(|l| *l = 0.0);
                self.bend_lambda.iter_mut().for_each(|l| *l = P4::ZERO);
            }
            self.c_dn.iter_mut().for_each(|d| *d = 0.0);
            for a in &mut self.attachments {
                a.lambda.iter_mut().for_each(|l| *l = Vector3::zeros());
            }
            for _ in 0..self.settings.iterations {
                if self.settings.iterations == 1 {
                    // multipliers start at zero and are not needed afterwards
                    lanes::distances_once(self.avx2, &mut self.x, &self.rows.once);
                    lanes::bending_once(self.avx2, &mut self.x, &self.rows.bend);
                } else {
                    solve_distances(&mut self.x, &self.rows.dist, &mut self.dist_lambda);
                    solve_bending(&mut self.x, &self.rows.bend, &mut self.bend_lambda);
                }
                self.solve_attachments(att_alpha, h);
                self.solve_tethers();
                if self_pairs > 0 {
                    self.selfc.solve(
                        &mut self.x,
                        &self.inv_mass,
                        &self.triangles,
                        self.material.thickness,
                    );
                }
                self.solve_edge_contacts(t_end, half, h);
                self.solve_contacts_normal(t_end, half);
            }
            self.requery_moved(query, s as f64 * h)?;
            self.apply_edge_friction(h);
            self.apply_friction(h);
            // friction of one contact may push a particle into another contact's plane
            self.reproject_contacts(t_end, half, h);
            if !self.grasp_tether_rows.is_empty() {
                // after friction, so that a tether pulling a particle into a collider (cloth
                // hanging over a table's far edge, pulled from the near one) does not make a
                // normal correction that friction then turns into a lock; the contacts are
                // projected once more (normal only)
                self.solve_grasp_tethers();
                self.reproject_contacts(t_end, half, h);
            }
            // slip: re-anchor attachments that hit their limit at the positions they reached
            for a in &mut self.attachments {
                if a.kinematic {
                    continue;
                }
                let total: Vector3<f64> = a.lambda.iter().sum();
                a.impulse += total / h;
                if total.norm() * inv_h2 >= a.max_force * (1.0 - 1e-12) {
                    a.slipped = true;
                    if let Some(f) = a.frame {
                        let pose = self.frame_now[f as usize];
                        for (k, &p) in a.particles.iter().enumerate() {
                            a.local[k] = pose
                                .inverse_transform_point(&Point3::from(self.x[p as usize].to_v()))
                                .coords;
                        }
                    }
                }
            }
        }
        // velocities of the last substep (the others are computed by `advance`)
        lanes::velocities(self.avx2, &self.x, &mut self.v, &self.prev, 1.0 / h);
        for ((x, v), (p, u)) in self
            .x
            .iter()
            .zip(&self.v)
            .zip(self.pos.iter_mut().zip(&mut self.vel))
        {
            *p = x.to_v();
            *u = v.to_v();
        }
        let max_speed = self.vel.iter().map(|v| v.norm()).fold(0.0, f64::max);
        Ok(StepStats {
            contacts: self.c_particle.len(),
            self_collision_pairs: self_pairs,
            max_speed,
            slipping_attachments: self.attachments.iter().filter(|a| a.slipped).count(),
        })
    }
}
