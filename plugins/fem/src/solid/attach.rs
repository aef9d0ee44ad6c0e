//! Constraints and rigid frames: world constraints (fixed nodes, rollers), body poses,
//! kinematic attachments and grasps (the force-limited grasp spring, its energy, and its
//! forces and slip after a step), and the constraint forces of the last solve.

use super::{
    finite3, finite_pose, Attachment, ConKind, FemSolid, Grasp, GraspInfo, GraspParams,
    WorldConstraint,
};
use crate::coupling::Reaction;
use crate::error::FemError;
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

impl FemSolid {
    // ----------------------------------------------------------------- world constraints

    fn world_entry(&mut self, node: u32) -> &mut WorldConstraint {
        let k = match self.world.binary_search_by_key(&node, |w| w.node) {
            Ok(k) => k,
            Err(k) => {
                let target = self.pos[node as usize];
                self.world.insert(
                    k,
                    WorldConstraint {
                        node,
                        proj: Matrix3::zeros(),
                        target,
                    },
                );
                k
            }
        };
        &mut self.world[k]
    }

    /// Fixes nodes to the world at their current positions.
    pub fn fix_nodes(&mut self, nodes: &[u32]) -> Result<(), FemError> {
        self.check_nodes(nodes)?;
        for &n in nodes {
            let p = self.pos[n as usize];
            let w = self.world_entry(n);
            w.proj = Matrix3::identity();
            w.target = p;
        }
        self.constraint_version += 1;
        Ok(())
    }

    /// Constrains the motion of nodes along `direction` (world frame) to their current
    /// coordinate; they stay free in the plane normal to it (a roller). Repeated calls with other
    /// directions add constrained directions.
    pub fn constrain_nodes_along(
        &mut self,
        nodes: &[u32],
        direction: Vector3<f64>,
    ) -> Result<(), FemError> {
        self.check_nodes(nodes)?;
        let d = direction
            .try_normalize(1e-12)
            .ok_or(FemError::NonFiniteInput("roller direction"))?;
        for &n in nodes {
            let p = self.pos[n as usize];
            let w = self.world_entry(n);
            // component of d outside the already constrained subspace
            let r = d - w.proj * d;
            if let Some(r) = r.try_normalize(1e-9) {
                w.proj += r * r.transpose();
            }
            // keep the constrained components of the current position as target
            w.target = p;
        }
        self.constraint_version += 1;
        Ok(())
    }

    /// Moves the target of a world-constrained node (m); only its constrained components apply.
    pub fn set_constraint_target(
        &mut self,
        node: u32,
        target: Vector3<f64>,
    ) -> Result<(), FemError> {
        if !finite3(&target) {
            return Err(FemError::NonFiniteInput("constraint target"));
        }
        match self.world.binary_search_by_key(&node, |w| w.node) {
            Ok(k) => {
                self.world[k].target = target;
                Ok(())
            }
            Err(_) => Err(FemError::NodeOutOfRange {
                node,
                count: self.n_nodes(),
            }),
        }
    }

    /// Removes the world constraints of the given nodes.
    pub fn release_nodes(&mut self, nodes: &[u32]) {
        self.world.retain(|w| !nodes.contains(&w.node));
        self.constraint_version += 1;
    }

    /// Force each constrained node received from its constraint during the last solve (N, world
    /// frame), for world constraints, attachments and contacts (normal part), in node order of
    /// the active constraint list.
    pub fn constraint_forces(&self) -> &[(u32, Vector3<f64>)] {
        &self.con_forces
    }

    // ----------------------------------------------------------------- rigid frames

    /// Sets the pose of rigid body `body` used by attachments and grasps from the next step.
    pub fn set_body_pose(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
    ) -> Result<(), FemError> {
        if !finite_pose(&world_from_body) {
            return Err(FemError::NonFiniteInput("body pose"));
        }
        match self.poses.binary_search_by_key(&body, |p| p.0) {
            Ok(k) => self.poses[k].1 = world_from_body,
            Err(k) => self.poses.insert(k, (body, world_from_body)),
        }
        Ok(())
    }

    /// [`FemSolid::set_body_pose`] for a body that nodes are attached to or grasped by now: the
    /// nodes are at this pose, so it is also where the next step starts from.
    fn set_body_pose_now(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
    ) -> Result<(), FemError> {
        self.set_body_pose(body, world_from_body)?;
        match self.poses_start.binary_search_by_key(&body, |p| p.0) {
            Ok(k) => self.poses_start[k].1 = world_from_body,
            Err(k) => self.poses_start.insert(k, (body, world_from_body)),
        }
        Ok(())
    }

    /// The poses a fraction `t` of the way from the start of the step to `poses` (translation
    /// interpolated linearly, rotation spherically); a body without a start pose is at its end.
    pub(super) fn poses_between(&self, t: f64) -> Vec<(u32, Isometry3<f64>)> {
        self.poses
            .iter()
            .map(|&(b, end)| {
                let p = match self.poses_start.binary_search_by_key(&b, |p| p.0) {
                    Ok(k) => self.poses_start[k].1.lerp_slerp(&end, t),
                    Err(_) => end,
                };
                (b, p)
            })
            .collect()
    }

    fn pose(&self, body: u32) -> Isometry3<f64> {
        match self.poses.binary_search_by_key(&body, |p| p.0) {
            Ok(k) => self.poses[k].1,
            Err(_) => Isometry3::identity(),
        }
    }

    /// Attaches nodes kinematically to rigid body `body` (currently at `world_from_body`): they
    /// follow the body frame exactly; the reaction impulses are reported by [`FemSolid::step`].
    /// Returns the attachment id.
    pub fn attach_to_body(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
        nodes: &[u32],
    ) -> Result<u32, FemError> {
        self.check_nodes(nodes)?;
        self.set_body_pose_now(body, world_from_body)?;
        let inv = world_from_body.inverse();
        let local = nodes
            .iter()
            .map(|&n| inv * Point3::from(self.pos[n as usize]))
            .map(|p| p.coords)
            .collect();
        let id = self.next_id;
        self.next_id += 1;
        self.attachments.push(Attachment {
            id,
            body,
            nodes: nodes.to_vec(),
            local,
        });
        self.constraint_version += 1;
        Ok(id)
    }

    /// Removes a kinematic attachment.
    pub fn detach(&mut self, id: u32) -> Result<(), FemError> {
        let k = self
            .attachments
            .iter()
            .position(|a| a.id == id)
            .ok_or(FemError::UnknownAttachment(id))?;
        self.attachments.remove(k);
        self.constraint_version += 1;
        Ok(())
    }

    /// Grasps nodes with rigid body `body` (currently at `world_from_body`): each node is held by
    /// a spring of `params.stiffness` to its current position in the body frame; the total force
    /// saturates at `params.force_limit`, past which the grasp slips. Returns the grasp id.
    pub fn grasp(
        &mut self,
        body: u32,
        world_from_body: Isometry3<f64>,
        nodes: &[u32],
        params: GraspParams,
    ) -> Result<u32, FemError> {
        self.check_nodes(nodes)?;
        if nodes.is_empty() {
            return Err(FemError::InvalidMesh(
                "a grasp needs at least one node".into(),
            ));
        }
        if !(params.stiffness.is_finite() && params.stiffness > 0.0) {
            return Err(FemError::InvalidParameter {
                name: "grasp.stiffness",
                value: params.stiffness,
                expected: "finite and > 0 (N/m)",
            });
        }
        if params.force_limit.is_nan() || params.force_limit <= 0.0 {
            return Err(FemError::InvalidParameter {
                name: "grasp.force_limit",
                value: params.force_limit,
                expected: "> 0 (N), may be infinite",
            });
        }
        self.set_body_pose_now(body, world_from_body)?;
        let inv = world_from_body.inverse();
        let local: Vec<Vector3<f64>> = nodes
            .iter()
            .map(|&n| (inv * Point3::from(self.pos[n as usize])).coords)
            .collect();
        let id = self.next_id;
        self.next_id += 1;
        self.grasps.push(Grasp {
            id,
            body,
            params,
            nodes: nodes.to_vec(),
            anchor: nodes.iter().map(|&n| self.pos[n as usize]).collect(),
            local,
            force: Vector3::zeros(),
            slipping: false,
            slip_distance: 0.0,
        });
        self.constraint_version += 1;
        Ok(id)
    }

    /// Releases a grasp.
    pub fn release_grasp(&mut self, id: u32) -> Result<(), FemError> {
        let k = self
            .grasps
            .iter()
            .position(|g| g.id == id)
            .ok_or(FemError::UnknownAttachment(id))?;
        self.grasps.remove(k);
        self.constraint_version += 1;
        Ok(())
    }

    /// Ids of the rigid bodies that attachments or grasps follow (sorted, unique).
    pub fn attached_bodies(&self) -> Vec<u32> {
        let mut b: Vec<u32> = self
            .attachments
            .iter()
            .map(|a| a.body)
            .chain(self.grasps.iter().map(|g| g.body))
            .collect();
        b.sort_unstable();
        b.dedup();
        b
    }

    /// Ids of the grasps held by rigid body `body`, in creation order.
    pub fn grasps_of(&self, body: u32) -> Vec<u32> {
        self.grasps
            .iter()
            .filter(|g| g.body == body)
            .map(|g| g.id)
            .collect()
    }

    /// Appends the nodes held by grasps (grasp order).
    pub fn grasped_nodes(&self, out: &mut Vec<u32>) {
        out.extend(self.grasps.iter().flat_map(|g| g.nodes.iter().copied()));
    }

    /// Appends the nodes whose contact constraint was active at the end of the last step
    /// (ascending).
    pub fn contact_nodes(&self, out: &mut Vec<u32>) {
        out.extend(
            self.active
                .iter()
                .filter(|c| matches!(c.kind, ConKind::Contact))
                .map(|c| c.node),
        );
    }

    /// State of a grasp after the last step.
    pub fn grasp_info(&self, id: u32) -> Result<GraspInfo, FemError> {
        let g = self
            .grasps
            .iter()
            .find(|g| g.id == id)
            .ok_or(FemError::UnknownAttachment(id))?;
        Ok(GraspInfo {
            body: g.body,
            force: g.force,
            slipping: g.slipping,
            slip_distance: g.slip_distance,
        })
    }

    pub(super) fn grasp_energy_grad(
        &self,
        x: &[Vector3<f64>],
        grad: Option<&mut [Vector3<f64>]>,
    ) -> f64 {
        let mut e = 0.0;
        let mut grad = grad;
        for g in &self.grasps {
            let n = g.nodes.len() as f64;
            let k = g.params.stiffness;
            let kk = n * k;
            let dbar: Vector3<f64> = g
                .nodes
                .iter()
                .zip(&g.anchor)
                .map(|(&i, a)| x[i as usize] - a)
                .sum::<Vector3<f64>>()
                / n;
            for (&i, a) in g.nodes.iter().zip(&g.anchor) {
                let d = x[i as usize] - a - dbar;
                e += 0.5 * k * d.norm_squared();
            }
            let r = dbar.norm();
            let flim = g.params.force_limit;
            let (eh, gh) = if kk * r <= flim {
                (0.5 * kk * r * r, dbar * kk)
            } else {
                (flim * r - 0.5 * flim * flim / kk, dbar * (flim / r))
            };
            e += eh;
            if let Some(gr) = grad.as_deref_mut() {
                for (&i, a) in g.nodes.iter().zip(&g.anchor) {
                    gr[i as usize] += (x[i as usize] - a - dbar) * k + gh / n;
                }
            }
        }
        e
    }

    pub(super) fn refresh_grasp_anchors(&mut self) {
        for gi in 0..self.grasps.len() {
            let pose = self.pose(self.grasps[gi].body);
            let g = &mut self.grasps[gi];
            for (a, l) in g.anchor.iter_mut().zip(&g.local) {
                *a = (pose * Point3::from(*l)).coords;
            }
        }
    }

    /// Updates grasp forces and slips saturated grasps; returns the number that slipped.
    pub(super) fn finish_grasps(
        &mut self,
        dt: f64,
        reactions: Option<&mut Vec<Reaction>>,
    ) -> usize {
        let mut slipped = 0;
        let mut reactions = reactions;
        for gi in 0..self.grasps.len() {
            let pose = self.pose(self.grasps[gi].body);
            let inv = pose.inverse();
            let g = &mut self.grasps[gi];
            let n = g.nodes.len() as f64;
            let k = g.params.stiffness;
            let kk = n * k;
            let dbar: Vector3<f64> = g
                .nodes
                .iter()
                .zip(&g.anchor)
                .map(|(&i, a)| self.pos[i as usize] - a)
                .sum::<Vector3<f64>>()
                / n;
            let r = dbar.norm();
            let flim = g.params.force_limit;
            let gh = if kk * r <= flim {
                dbar * kk
            } else {
                dbar * (flim / r)
            };
            g.force = -gh;
            if let Some(re) = reactions.as_deref_mut() {
                for (&i, a) in g.nodes.iter().zip(&g.anchor) {
                    let f_on_node = -((self.pos[i as usize] - a - dbar) * k + gh / n);
                    re.push(Reaction {
                        body: g.body,
                        point: *a,
                        impulse: -f_on_node * dt,
                    });
                }
            }
            g.slipping = kk * r > flim;
            if g.slipping {
                slipped += 1;
                let s = dbar * (1.0 - flim / (kk * r));
                g.slip_distance += s.norm();
                for (a, l) in g.anchor.iter_mut().zip(g.local.iter_mut()) {
                    *a += s;
                    *l = (inv * Point3::from(*a)).coords;
                }
            }
        }
        slipped
    }

    pub(super) fn record_constraint_forces(&mut self) {
        self.con_forces.clear();
        for c in &self.active {
            let f = c.proj * self.grad[c.node as usize];
            self.con_forces.push((c.node, f));
        }
    }
}
