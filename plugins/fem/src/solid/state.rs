//! Snapshots: the solid's full dynamic state as a flat vector ([`FemSolid::get_state`]) and
//! its restore ([`FemSolid::set_state`], also the previous format).

use super::{
    finite3, Attachment, ContactMemory, FemSolid, Grasp, GraspParams, WorldConstraint, STATE_MAGIC,
    STATE_MAGIC_V1, STATE_MAGIC_V2,
};
use crate::error::FemError;
use nalgebra::{Isometry3, Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};

impl FemSolid {
    // ----------------------------------------------------------------- state

    /// Full dynamic state as a flat vector: positions, velocities, step count, external loads,
    /// world constraints, body poses, attachments, grasps (with slip state), the
    /// preconditioner's reference shape, the Young's modulus scale, the contacts the last step
    /// ended with (the next step's first guess) and the contact penalties of the factor's anchor
    /// (the factor is rebuilt from them, so a restored solid solves bit for bit as the
    /// uninterrupted one). `set_state(get_state())` is a bit-exact round trip.
    /// [`FemSolid::set_state`] also reads the two previous formats (without the anchor, and
    /// without the contacts either).
    pub fn get_state(&self) -> Vec<f64> {
        let mut s = vec![
            STATE_MAGIC,
            self.n_nodes() as f64,
            self.steps as f64,
            self.next_id as f64,
        ];
        let push3 = |s: &mut Vec<f64>, v: &Vector3<f64>| s.extend_from_slice(&[v.x, v.y, v.z]);
        for v in self.pos.iter().chain(&self.vel).chain(&self.ext_force) {
            push3(&mut s, v);
        }
        s.push(self.world.len() as f64);
        for w in &self.world {
            s.push(w.node as f64);
            s.extend_from_slice(w.proj.as_slice());
            push3(&mut s, &w.target);
        }
        s.push(self.poses.len() as f64);
        for (b, p) in &self.poses {
            s.push(*b as f64);
            push3(&mut s, &p.translation.vector);
            s.extend_from_slice(p.rotation.coords.as_slice());
        }
        s.push(self.attachments.len() as f64);
        for a in &self.attachments {
            s.extend_from_slice(&[a.id as f64, a.body as f64, a.nodes.len() as f64]);
            for (n, l) in a.nodes.iter().zip(&a.local) {
                s.push(*n as f64);
                push3(&mut s, l);
            }
        }
        s.push(self.grasps.len() as f64);
        for g in &self.grasps {
            s.extend_from_slice(&[
                g.id as f64,
                g.body as f64,
                g.params.stiffness,
                g.params.force_limit,
                g.nodes.len() as f64,
            ]);
            for (n, l) in g.nodes.iter().zip(&g.local) {
                s.push(*n as f64);
                push3(&mut s, l);
            }
            push3(&mut s, &g.force);
            s.extend_from_slice(&[if g.slipping { 1.0 } else { 0.0 }, g.slip_distance]);
        }
        match &self.precond_at {
            None => s.push(0.0),
            Some(x) => {
                s.push(1.0);
                for v in x {
                    push3(&mut s, v);
                }
            }
        }
        s.push(self.stiffness_scale);
        s.push(self.contact_memory.len() as f64);
        for m in &self.contact_memory {
            s.extend_from_slice(&[
                m.node as f64,
                f64::from(m.body),
                f64::from(u8::from(m.stick)),
            ]);
            push3(&mut s, &m.slip_dir);
            s.push(m.normal_force);
        }
        s.push(self.factor_anchor.len() as f64);
        for (node, d, k) in &self.factor_anchor {
            s.push(f64::from(*node));
            push3(&mut s, d);
            s.push(*k);
        }
        s
    }

    /// Restores a state produced by [`FemSolid::get_state`] of a solid with the same model.
    pub fn set_state(&mut self, state: &[f64]) -> Result<(), FemError> {
        let mut r = Reader { s: state, i: 0 };
        let version = r.next()?;
        if ![STATE_MAGIC, STATE_MAGIC_V2, STATE_MAGIC_V1].contains(&version) {
            return Err(FemError::InvalidState(
                "not a modesuite-fem state vector (bad tag)".into(),
            ));
        }
        let n = r.next()? as usize;
        if n != self.n_nodes() {
            return Err(FemError::InvalidState(format!(
                "state has {n} nodes, solid has {}",
                self.n_nodes()
            )));
        }
        let steps = r.next()? as u64;
        let next_id = r.next()? as u32;
        let mut pos = Vec::with_capacity(n);
        let mut vel = Vec::with_capacity(n);
        let mut ext = Vec::with_capacity(n);
        for _ in 0..n {
            pos.push(r.v3()?);
        }
        for _ in 0..n {
            vel.push(r.v3()?);
        }
        for _ in 0..n {
            ext.push(r.v3()?);
        }
        let nw = r.count()?;
        let mut world = Vec::with_capacity(nw);
        for _ in 0..nw {
            let node = r.node(n)?;
            let mut proj = Matrix3::zeros();
            for k in 0..9 {
                proj.as_mut_slice()[k] = r.next()?;
            }
            world.push(WorldConstraint {
                node,
                proj,
                target: r.v3()?,
            });
        }
        let np = r.count()?;
        let mut poses = Vec::with_capacity(np);
        for _ in 0..np {
            let b = r.next()? as u32;
            let t = r.v3()?;
            let (qi, qj, qk, qw) = (r.next()?, r.next()?, r.next()?, r.next()?);
            let q = Quaternion::new(qw, qi, qj, qk);
            poses.push((
                b,
                Isometry3::from_parts(Translation3::from(t), UnitQuaternion::new_unchecked(q)),
            ));
        }
        let na = r.count()?;
        let mut attachments = Vec::with_capacity(na);
        for _ in 0..na {
            let id = r.next()? as u32;
            let body = r.next()? as u32;
            let k = r.count()?;
            let mut nodes = Vec::with_capacity(k);
            let mut local = Vec::with_capacity(k);
            for _ in 0..k {
                nodes.push(r.node(n)?);
                local.push(r.v3()?);
            }
            attachments.push(Attachment {
                id,
                body,
                nodes,
                local,
            });
        }
        let ng = r.count()?;
        let mut grasps = Vec::with_capacity(ng);
        for _ in 0..ng {
            let id = r.next()? as u32;
            let body = r.next()? as u32;
            let params = GraspParams {
                stiffness: r.next()?,
                force_limit: r.next()?,
            };
            let k = r.count()?;
            let mut nodes = Vec::with_capacity(k);
            let mut local = Vec::with_capacity(k);
            for _ in 0..k {
                nodes.push(r.node(n)?);
                local.push(r.v3()?);
            }
            let force = r.v3()?;
            let slipping = r.next()? != 0.0;
            let slip_distance = r.next()?;
            grasps.push(Grasp {
                id,
                body,
                params,
                anchor: local.clone(),
                nodes,
                local,
                force,
                slipping,
                slip_distance,
            });
        }
        let precond_at = if r.next()? != 0.0 {
            let mut x = Vec::with_capacity(n);
            for _ in 0..n {
                x.push(r.v3()?);
            }
            Some(x)
        } else {
            None
        };
        let stiffness_scale = r.next()?;
        if !(stiffness_scale.is_finite() && stiffness_scale > 0.0) {
            return Err(FemError::InvalidState(format!(
                "stiffness scale {stiffness_scale}: finite and > 0"
            )));
        }
        let mut contact_memory = Vec::new();
        if version != STATE_MAGIC_V1 {
            let count = r.count()?;
            for _ in 0..count {
                let node = r.node(n)?;
                let body = r.next()?;
                if !(body >= 0.0 && body <= f64::from(u32::MAX) && body.fract() == 0.0) {
                    return Err(FemError::InvalidState(format!("contact body id {body}")));
                }
                let stick = r.next()? != 0.0;
                let slip_dir = r.v3()?;
                let normal_force = r.next()?;
                if !(finite3(&slip_dir) && normal_force.is_finite()) {
                    return Err(FemError::NonFiniteInput("contact memory"));
                }
                contact_memory.push(ContactMemory {
                    node,
                    body: body as u32,
                    stick,
                    slip_dir,
                    normal_force,
                });
            }
            if !contact_memory.windows(2).all(|w| w[0].node < w[1].node) {
                return Err(FemError::InvalidState(
                    "contact memory: nodes not in increasing order".into(),
                ));
            }
        }
        let mut factor_anchor = Vec::new();
        if version == STATE_MAGIC {
            let count = r.count()?;
            for _ in 0..count {
                let node = r.node(n)?;
                let d = r.v3()?;
                let k = r.next()?;
                if !(finite3(&d) && (d.norm() - 1.0).abs() < 1e-9 && k > 0.0 && k < 1e300) {
                    return Err(FemError::InvalidState(format!(
                        "factor anchor: node {node} direction {d:?} stiffness {k}"
                    )));
                }
                factor_anchor.push((node, d, k));
            }
        }
        if r.i != state.len() {
            return Err(FemError::InvalidState(format!(
                "{} trailing values",
                state.len() - r.i
            )));
        }
        self.pos = pos;
        self.vel = vel;
        self.ext_force = ext;
        self.impulse.clear();
        self.steps = steps;
        self.next_id = next_id;
        self.world = world;
        self.poses_start.clone_from(&poses);
        self.poses = poses;
        self.attachments = attachments;
        self.grasps = grasps;
        self.precond_at = precond_at;
        self.precond_gen += 1;
        self.stiffness_scale = stiffness_scale;
        self.contact_memory = contact_memory;
        self.factor_anchor = factor_anchor;
        self.precond = None;
        self.constraint_version += 1;
        self.refresh_grasp_anchors();
        Ok(())
    }
}

struct Reader<'a> {
    s: &'a [f64],
    i: usize,
}

impl Reader<'_> {
    fn next(&mut self) -> Result<f64, FemError> {
        let v = *self
            .s
            .get(self.i)
            .ok_or_else(|| FemError::InvalidState("truncated".into()))?;
        self.i += 1;
        Ok(v)
    }
    fn v3(&mut self) -> Result<Vector3<f64>, FemError> {
        Ok(Vector3::new(self.next()?, self.next()?, self.next()?))
    }
    fn count(&mut self) -> Result<usize, FemError> {
        let v = self.next()?;
        if !(v >= 0.0 && v.fract() == 0.0 && v < 1e9) {
            return Err(FemError::InvalidState(format!("bad count {v}")));
        }
        Ok(v as usize)
    }
    fn node(&mut self, n: usize) -> Result<u32, FemError> {
        let v = self.count()?;
        if v >= n {
            return Err(FemError::InvalidState(format!("node {v} out of range")));
        }
        Ok(v as u32)
    }
}
