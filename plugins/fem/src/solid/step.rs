//! Stepping: the backward-Euler step (contact candidates, active-set rounds with friction,
//! reactions), step splitting on failure, and the static solves.

use super::{
    finite3, Candidate, ConKind, ContactMemory, FemSolid, Problem, StepStats, ACTIVATION_ROUNDS,
    FACING_COS, FRICTION_RTOL, MAX_STEP_HALVINGS, SLIP_SPEED,
};
use crate::coupling::{ContactQuery, PointContact, Reaction};
use crate::error::FemError;
use nalgebra::Vector3;

/// How a step's solve treats its contacts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Contacts {
    /// Constraints, with Coulomb friction by active-set rounds (sticking, sliding, released,
    /// activated).
    Rounds,
    /// As `Rounds`, but every contact with friction sticks and none is released: the last
    /// resort when the rounds fail even on the smallest part of a step (a body wedged between
    /// a kinematic hand and walls, whose rounds do not settle and whose explicit sliding
    /// forces can then fling nodes away). Sticking is a plain constraint with no force of its
    /// own; for that short part of a step the body holds on to what it touches. Its result
    /// passes the same speed check (on a PPO policy's Franka Bend episode it saved 4 of 6 such
    /// parts; the episode still ended with a blow-up).
    Stuck,
    /// Penalty energies with lagged friction ([`FemConfig::penalty_contacts`]).
    ///
    /// [`FemConfig::penalty_contacts`]: crate::FemConfig::penalty_contacts
    Penalty,
}

impl FemSolid {
    // ----------------------------------------------------------------- stepping

    /// Advances the solid by one backward-Euler step of `dt` (s) under `gravity` (m/s^2, world
    /// frame), with rigid contacts from `contacts`; appends to `reactions` the impulses (N s) the
    /// solid applied on rigid bodies through attachments, grasps and contacts. Kinematic
    /// attachments reach their bodies' poses (set by [`FemSolid::set_body_pose`]) at the end of
    /// the step. On a blow-up the state is rolled back and an error returned.
    pub fn step(
        &mut self,
        dt: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, FemError> {
        self.step_at(0.0, dt, gravity, contacts, reactions)
    }

    /// [`FemSolid::step`] for a step that starts `t0` seconds (>= 0) after the rigid state
    /// `contacts` describes: moving colliders are extrapolated at their surface velocity over
    /// `t0 + dt` (and searched for that much further), as the halves of a split step are.
    /// Several solid steps per rigid substep use it (`physics.deformable_substeps`).
    pub fn step_at(
        &mut self,
        t0: f64,
        dt: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
    ) -> Result<StepStats, FemError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "dt",
                value: dt,
                expected: "finite and > 0 (s)",
            });
        }
        if !(t0.is_finite() && t0 >= 0.0) {
            return Err(FemError::InvalidParameter {
                name: "t0",
                value: t0,
                expected: "finite and >= 0 (s)",
            });
        }
        if !finite3(&gravity) {
            return Err(FemError::NonFiniteInput("gravity"));
        }
        let impulse = std::mem::take(&mut self.impulse);
        let loads = (!impulse.is_empty()).then(|| self.ext_force.clone());
        for (f, j) in self.ext_force.iter_mut().zip(&impulse) {
            *f += j / dt;
        }
        let result = self.step_split(dt, t0, gravity, contacts, reactions, MAX_STEP_HALVINGS);
        if let Some(loads) = loads {
            self.ext_force = loads;
        }
        if result.is_ok() {
            self.steps += 1;
        }
        result
    }

    /// One step of `dt`, starting `t0` seconds after the rigid world's state that `contacts`
    /// describes; if its solve fails (does not converge, explodes, or meets a matrix that is not
    /// positive definite) and `halvings > 0`, it is rolled back and done as two half steps.
    /// A collider moving more than a thin body's thickness in one step (a box at 3 m/s against a
    /// 4 mm belt) is the usual cause; the halves see the collider at its interpolated position,
    /// and attachments and grasps follow their bodies half way in the first half (a held rod
    /// pushed into a wall: were the first half to take the whole motion, halving would double
    /// its strain rate instead of halving it).
    fn step_split(
        &mut self,
        dt: f64,
        t0: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
        halvings: u32,
    ) -> Result<StepStats, FemError> {
        let strict = halvings > 0;
        let mode = if self.config.penalty_contacts > 0.0 {
            Contacts::Penalty
        } else {
            Contacts::Rounds
        };
        match self.step_once(dt, t0, gravity, contacts, reactions, strict, mode) {
            Err(FemError::Exploded { .. } | FemError::NotPositiveDefinite(_))
                if !strict && mode == Contacts::Rounds =>
            {
                // the finest part failed too: once more with every touching contact stuck
                self.step_once(dt, t0, gravity, contacts, reactions, false, Contacts::Stuck)
            }
            Err(FemError::Exploded { .. } | FemError::NotPositiveDefinite(_)) if strict => {
                // rolled back to the start of this (part of the) step: keep it in case a half fails
                let start = self.get_state();
                let poses_start = self.poses_start.clone();
                let reactions_len = reactions.len();
                let h = 0.5 * dt;
                let mid = self.poses_between(0.5);
                let end = std::mem::replace(&mut self.poses, mid);
                let halves = self
                    .step_split(h, t0, gravity, contacts, reactions, halvings - 1)
                    .and_then(|a| {
                        self.poses.clone_from(&end);
                        self.step_split(h, t0 + h, gravity, contacts, reactions, halvings - 1)
                            .map(|b| (a, b))
                    });
                let (a, b) = match halves {
                    Ok(ab) => ab,
                    Err(e) => {
                        // (the state holds the poses of the step's end)
                        self.poses = end;
                        self.set_state(&start)?;
                        self.poses_start = poses_start;
                        reactions.truncate(reactions_len);
                        return Err(e);
                    }
                };
                Ok(StepStats {
                    active_set_rounds: a.active_set_rounds + b.active_set_rounds,
                    newton_iterations: a.newton_iterations + b.newton_iterations,
                    linear_iterations: a.linear_iterations + b.linear_iterations,
                    factorizations: a.factorizations + b.factorizations,
                    slipping_grasps: a.slipping_grasps.max(b.slipping_grasps),
                    halvings: 1 + a.halvings + b.halvings,
                    projected: a.projected + b.projected,
                    ..b
                })
            }
            r => r,
        }
    }

    /// One backward-Euler step; on failure (and, if `strict`, on a solve that did not converge)
    /// the state is rolled back and an error returned. `mode`: how its contacts are solved.
    #[allow(clippy::too_many_arguments)]
    fn step_once(
        &mut self,
        dt: f64,
        t0: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
        strict: bool,
        mode: Contacts,
    ) -> Result<StepStats, FemError> {
        let reactions_len = reactions.len();
        self.xprev.copy_from_slice(&self.pos);
        self.vprev.copy_from_slice(&self.vel);
        let grasp_backup: Vec<(Vec<Vector3<f64>>, f64)> = self
            .grasps
            .iter()
            .map(|g| (g.local.clone(), g.slip_distance))
            .collect();
        let precond_backup = self.precond_at.clone();
        let memory_backup = self.contact_memory.clone();
        let anchor_backup = self.factor_anchor.clone();
        let result = self.step_inner(dt, t0, gravity, contacts, reactions, mode);
        self.penalties.clear();
        self.penalty_factor.clear();
        let failed = match &result {
            Ok(stats) => {
                let mut max_speed: f64 = 0.0;
                let mut finite = true;
                for (x, v) in self.pos.iter().zip(&self.vel) {
                    finite &= finite3(x) && finite3(v);
                    max_speed = max_speed.max(v.norm());
                }
                if !finite {
                    Some(FemError::Exploded {
                        step: self.steps,
                        max_speed: f64::INFINITY,
                    })
                } else if max_speed > self.config.max_speed || (strict && !stats.converged) {
                    Some(FemError::Exploded {
                        step: self.steps,
                        max_speed,
                    })
                } else {
                    None
                }
            }
            Err(e) => Some(e.clone()),
        };
        if let Some(err) = failed {
            self.pos.copy_from_slice(&self.xprev);
            self.vel.copy_from_slice(&self.vprev);
            for (g, (l, s)) in self.grasps.iter_mut().zip(grasp_backup) {
                g.local = l;
                g.slip_distance = s;
            }
            self.precond_at = precond_backup;
            self.precond_gen += 1;
            self.contact_memory = memory_backup;
            // the state before the step, and no factor built at a discarded shape
            self.factor_anchor = anchor_backup;
            self.precond = None;
            reactions.truncate(reactions_len);
            return Err(err);
        }
        self.poses_start.clone_from(&self.poses);
        result
    }

    /// The step's solve, its contacts solved as `mode` says.
    fn step_inner(
        &mut self,
        dt: f64,
        t0: f64,
        gravity: Vector3<f64>,
        contacts: &dyn ContactQuery,
        reactions: &mut Vec<Reaction>,
        mode: Contacts,
    ) -> Result<StepStats, FemError> {
        let stuck = mode == Contacts::Stuck;
        let penalty = mode == Contacts::Penalty;
        let n = self.n_nodes();
        let mut stats = StepStats::default();
        let problem = Problem {
            c_mass: 1.0 / (dt * dt),
            c_damp: self.config.rayleigh_mass / dt,
            c_kdamp: self.config.rayleigh_stiffness / dt,
            gravity: Vector3::zeros(),
        };
        for i in 0..n {
            self.xhat[i] = self.pos[i] + self.vel[i] * dt + gravity * (dt * dt);
        }
        self.refresh_grasp_anchors();
        // contact candidates
        self.candidates.clear();
        // Fully constrained nodes need no contact; grasped nodes are pinched between the fingers,
        // whose contact the grasp spring stands for (a contact with the closing fingers would
        // fight the spring).
        let mut skip = self.full_constrained();
        for g in &self.grasps {
            for &n in &g.nodes {
                skip[n as usize] = true;
            }
        }
        let mut normals = std::mem::take(&mut self.normals);
        self.model.surface_normals(&self.pos, &mut normals);
        self.normals = normals;
        let mut out: Vec<PointContact> = Vec::new();
        let gdt2 = gravity.norm() * dt * dt;
        for &i in &self.model.surface_nodes {
            if skip[i as usize] {
                continue;
            }
            let x = self.pos[i as usize];
            let reach = self.vel[i as usize].norm() * dt
                + gdt2
                + self.config.collider_speed_bound * (t0 + dt)
                + self.config.contact_margin;
            out.clear();
            contacts.contacts_near(&x, reach, &mut out);
            // keep the closest contact on a collider the node's surface faces
            let ns = self.normals[i as usize];
            let mut best: Option<PointContact> = None;
            for c in &out {
                let valid = finite3(&c.point)
                    && finite3(&c.normal)
                    && finite3(&c.velocity)
                    && c.distance.is_finite()
                    && c.friction.is_finite();
                if !valid {
                    return Err(FemError::NonFiniteInput("contact query result"));
                }
                let faces = ns == Vector3::zeros() || ns.dot(&c.normal) < -FACING_COS;
                if faces && best.is_none_or(|b| c.distance < b.distance) {
                    best = Some(*c);
                }
            }
            if let Some(mut c) = best {
                c.normal = c.normal.try_normalize(1e-12).unwrap_or(Vector3::z());
                // collider surface position at the end of the step
                c.point += c.velocity * (t0 + dt);
                let gap = (self.xhat[i as usize] - c.point).dot(&c.normal);
                let t = x + c.velocity * dt;
                let stick_target = t - c.normal * (t - c.point).dot(&c.normal);
                let vrel = self.vel[i as usize] - c.velocity;
                let vt = vrel - c.normal * vrel.dot(&c.normal);
                let speed = vt.norm();
                let mass = self.model.mass[i as usize];
                // The last step's contact on this node and body (if any) is the first guess:
                // active, its normal force, and sliding if it ended sliding (in its direction of
                // motion, or the old one if it barely moves). A new contact's normal force is
                // the one stopping the node's predicted penetration within the step.
                let memory = self
                    .contact_memory
                    .binary_search_by_key(&i, |m| m.node)
                    .ok()
                    .map(|k| self.contact_memory[k])
                    .filter(|m| m.body == c.body);
                let normal_force = match memory {
                    Some(m) => m.normal_force.max(0.0),
                    None => mass * (-gap).max(0.0) * problem.c_mass,
                };
                // a node slower than its kinetic friction can stop within the step starts
                // sticking (sliding, the friction would reverse it: one more round)
                let stop_speed = c.friction * normal_force * dt / mass;
                let remembered_slip = memory.filter(|m| !m.stick).map(|m| m.slip_dir);
                let sliding = remembered_slip.is_some() || speed > SLIP_SPEED.max(stop_speed);
                let slip_dir = match remembered_slip {
                    Some(d) if speed <= SLIP_SPEED => d,
                    _ if sliding => -vt / speed,
                    _ => Vector3::zeros(),
                };
                // (a remembered frictionless slide has no direction: with friction now, stick)
                let sliding = sliding && slip_dir != Vector3::zeros() && !stuck;
                self.candidates.push(Candidate {
                    node: i,
                    contact: c,
                    // (a node that was touching and is predicted within the margin touches)
                    active: !penalty
                        && (gap < 0.0 || (memory.is_some() && gap < self.config.contact_margin)),
                    stick: c.friction > 0.0 && !sliding,
                    stick_target,
                    normal_force,
                    friction_force: slip_dir * (c.friction * normal_force),
                    slip_dir,
                    secant: None,
                });
            }
        }
        // active-set rounds: contacts start sticking; a stuck contact whose tangential force
        // exceeds mu * normal force slides with kinetic friction mu * normal force opposing the
        // tendency; pulling (adhesive) contacts are released; penetrating ones activated
        // Tolerances of the rounds match the Newton solve's: a penetration, an adhesive normal
        // force or a change of kinetic friction smaller than what the solve resolves (its step
        // tolerance, and that step's inertial force) starts no new round.
        let pen_tol = self.config.newton_tolerance * self.model.length_scale;
        if penalty {
            self.build_penalties(dt, problem.c_mass);
            self.penalty_blocks(dt);
        }
        let max_rounds = 6;
        for round in 0..max_rounds + ACTIVATION_ROUNDS {
            // from the last round on, contacts are neither released nor change their friction
            let last = round + 1 >= max_rounds;
            // and after the activation rounds, nothing starts another round
            let activate = round + 1 < max_rounds + ACTIVATION_ROUNDS && !penalty;
            for i in 0..n {
                self.fric[i] = Vector3::zeros();
            }
            for c in &self.candidates {
                if c.active && !c.stick {
                    self.fric[c.node as usize] = c.friction_force;
                }
            }
            // initial guess x_n + dt v_n (exact for steady motion; gravity is left to Newton)
            for i in 0..n {
                self.pos[i] = self.xprev[i] + self.vprev[i] * dt;
            }
            self.build_active();
            stats.active_set_rounds += 1;
            self.newton(
                &problem,
                self.config.newton_max_iterations,
                true,
                &mut stats,
            )?;
            stats.inverted = self.gradient_after_solve(&problem);
            let mut changed = false;
            for ci in 0..self.candidates.len() {
                let c = self.candidates[ci];
                let i = c.node as usize;
                let nrm = c.contact.normal;
                let force_tol = self.model.mass[i] * problem.c_mass * pen_tol;
                if c.active {
                    let g = self.grad[i];
                    let lam = nrm.dot(&g);
                    self.candidates[ci].normal_force = lam;
                    if lam < -force_tol && !stuck {
                        if !last {
                            self.candidates[ci].active = false;
                            changed = true;
                        }
                        continue;
                    }
                    let mu = c.contact.friction;
                    if c.stick {
                        let ft = g - nrm * lam;
                        if ft.norm() > mu * lam * (1.0 + 1e-9) && !last && !stuck {
                            let cc = &mut self.candidates[ci];
                            cc.stick = false;
                            cc.slip_dir = ft / ft.norm();
                            cc.friction_force = cc.slip_dir * (mu * lam);
                            cc.secant = None;
                            changed = true;
                        }
                    } else {
                        let vt = {
                            let v = (self.pos[i] - self.xprev[i]) / dt - c.contact.velocity;
                            v - nrm * v.dot(&nrm)
                        };
                        let cc = &mut self.candidates[ci];
                        if vt.dot(&cc.slip_dir) > 0.0 && mu > 0.0 && !last {
                            // friction reversed the sliding: the node sticks
                            cc.stick = true;
                            changed = true;
                        } else {
                            // kinetic friction f must equal mu * normal force, itself a function
                            // of f: a secant step on f - mu * lam(f) once two rounds are known
                            let f = cc.friction_force.dot(&cc.slip_dir);
                            let target = mu * lam.max(0.0);
                            let off = (target - f).abs();
                            if off > (FRICTION_RTOL * target).max(force_tol) && !last {
                                let next = match cc.secant {
                                    Some((f0, t0)) if f != f0 => {
                                        let slope = ((target - t0) / (f - f0)).clamp(-10.0, 0.5);
                                        (f + (target - f) / (1.0 - slope)).max(0.0)
                                    }
                                    _ => target,
                                };
                                cc.secant = Some((f, target));
                                cc.friction_force = cc.slip_dir * next;
                                changed = true;
                            }
                        }
                    }
                } else {
                    let gap = (self.pos[i] - c.contact.point).dot(&nrm);
                    if gap < -pen_tol && activate {
                        let cc = &mut self.candidates[ci];
                        cc.active = true;
                        // from the last round on no contact can start sliding, so one joining
                        // then takes the normal only (what projecting it out used to do): stuck,
                        // it could hold more than its friction cone (a torus resting on the
                        // ground trembled and let a box on it creep)
                        cc.stick = cc.contact.friction > 0.0 && !last;
                        if last {
                            cc.slip_dir = Vector3::zeros();
                            cc.friction_force = Vector3::zeros();
                        }
                        cc.secant = None;
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
        }
        self.record_constraint_forces();
        self.contact_memory.clear();
        if penalty {
            self.remember_penalties();
        }
        for c in &self.candidates {
            if c.active {
                self.contact_memory.push(ContactMemory {
                    node: c.node,
                    body: c.contact.body,
                    stick: c.stick,
                    slip_dir: c.slip_dir,
                    normal_force: c.normal_force,
                });
            }
        }
        self.contact_memory.sort_by_key(|m| m.node);
        // reactions of kinematic attachments
        for c in &self.active {
            if let ConKind::Attachment(ai) = c.kind {
                let f = c.proj * self.grad[c.node as usize];
                reactions.push(Reaction {
                    body: self.attachments[ai as usize].body,
                    point: self.pos[c.node as usize],
                    impulse: -f * dt,
                });
            }
        }
        // contact reactions (normal + friction); remaining penetration of inactive candidates
        // (only possible when the rounds ran out) is projected out
        if penalty {
            stats.contacts = self.penalty_reactions(dt, reactions);
        }
        for c in self.candidates.iter().filter(|_| !penalty) {
            let i = c.node as usize;
            let nrm = c.contact.normal;
            if !c.active {
                let gap = (self.pos[i] - c.contact.point).dot(&nrm);
                if gap < 0.0 {
                    stats.projected += usize::from(gap < -pen_tol);
                    self.pos[i] -= nrm * gap;
                }
                continue;
            }
            stats.contacts += 1;
            // only what a contact can transmit goes to the body: a compressive normal force and
            // friction inside the cone (the active-set rounds can end with a contact outside)
            let g = self.grad[i];
            let lam = nrm.dot(&g);
            if lam <= 0.0 {
                continue;
            }
            let ft = if c.stick {
                g - nrm * lam
            } else {
                c.friction_force
            };
            let ft_max = c.contact.friction * lam;
            let ft = if ft.norm() > ft_max {
                ft * (ft_max / ft.norm())
            } else {
                ft
            };
            let force_on_node = nrm * lam + ft;
            reactions.push(Reaction {
                body: c.contact.body,
                point: c.contact.point,
                impulse: -force_on_node * dt,
            });
        }
        for f in self.fric.iter_mut() {
            *f = Vector3::zeros();
        }
        for i in 0..n {
            self.vel[i] = (self.pos[i] - self.xprev[i]) / dt;
        }
        stats.slipping_grasps = self.finish_grasps(dt, Some(reactions));
        Ok(stats)
    }

    /// Static equilibrium under `gravity` and the external loads from the current shape
    /// (nonlinear, Newton with line search), respecting world constraints, attachments (at their
    /// bodies' poses) and grasps; contacts are ignored. Velocities are set to zero.
    pub fn solve_static(
        &mut self,
        gravity: Vector3<f64>,
        max_iterations: usize,
    ) -> Result<StepStats, FemError> {
        if !finite3(&gravity) {
            return Err(FemError::NonFiniteInput("gravity"));
        }
        let p = Problem {
            c_mass: 0.0,
            c_damp: 0.0,
            c_kdamp: 0.0,
            gravity,
        };
        self.xprev.copy_from_slice(&self.pos);
        self.refresh_grasp_anchors();
        self.candidates.clear();
        self.build_active();
        let mut stats = StepStats::default();
        let r = self.newton(&p, max_iterations, true, &mut stats);
        if let Err(e) = r {
            self.pos.copy_from_slice(&self.xprev);
            return Err(e);
        }
        if !self.pos.iter().all(finite3) {
            self.pos.copy_from_slice(&self.xprev);
            return Err(FemError::Exploded {
                step: self.steps,
                max_speed: f64::INFINITY,
            });
        }
        stats.inverted = self.gradient_after_solve(&p);
        self.record_constraint_forces();
        self.finish_grasps(1.0, None);
        self.vel.iter_mut().for_each(|v| *v = Vector3::zeros());
        Ok(stats)
    }

    /// Linear static displacement from the rest shape (m per node): one Newton step from rest,
    /// i.e. `K_rest u = f` with the current constraints, gravity and external loads. Leaves the
    /// state unchanged.
    pub fn solve_linear_static(
        &mut self,
        gravity: Vector3<f64>,
    ) -> Result<Vec<Vector3<f64>>, FemError> {
        if !finite3(&gravity) {
            return Err(FemError::NonFiniteInput("gravity"));
        }
        let saved = self.pos.clone();
        self.pos.copy_from_slice(&self.model.mesh.rest);
        self.xprev.copy_from_slice(&self.pos);
        let p = Problem {
            c_mass: 0.0,
            c_damp: 0.0,
            c_kdamp: 0.0,
            gravity,
        };
        self.refresh_grasp_anchors();
        self.candidates.clear();
        self.build_active();
        let mut stats = StepStats::default();
        let r = self.newton(&p, 1, false, &mut stats);
        let u: Vec<Vector3<f64>> = self
            .pos
            .iter()
            .zip(&self.model.mesh.rest)
            .map(|(x, r)| x - r)
            .collect();
        self.pos = saved;
        r?;
        Ok(u)
    }
}
