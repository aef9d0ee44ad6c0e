//! Snapshots: the cloth's full dynamic state as a flat vector ([`Cloth::get_state`]) and its
//! restore ([`Cloth::set_state`]).

use super::{finite3, iso_finite, Attachment, Cloth, Frame, STATE_MAGIC};
use crate::error::PbdError;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

impl Cloth {
    // ------------------------------------------------------------------ state

    /// The full dynamic state as a flat vector: time, step count, positions, velocities, frames
    /// (previous and target poses) and attachments (particles, offsets, limits). Multipliers are
    /// not kept between substeps, so they are not part of it. Bit-exact with
    /// [`Cloth::set_state`].
    pub fn get_state(&self) -> Vec<f64> {
        let n = self.pos.len();
        let mut s = Vec::with_capacity(6 * n + 16);
        s.push(STATE_MAGIC);
        s.push(n as f64);
        s.push(self.time);
        s.push(self.steps as f64);
        for v in self.pos.iter().chain(&self.vel) {
            s.extend_from_slice(&[v.x, v.y, v.z]);
        }
        s.push(self.frames.len() as f64);
        for f in &self.frames {
            s.push(f.body as f64);
            for p in [&f.prev, &f.target] {
                let t = p.translation.vector;
                let q = p.rotation.coords;
                s.extend_from_slice(&[t.x, t.y, t.z, q.x, q.y, q.z, q.w]);
            }
        }
        s.push(self.next_attachment as f64);
        s.push(self.attachments.len() as f64);
        for a in &self.attachments {
            s.push(a.id as f64);
            s.push(a.frame.map(|f| f as f64).unwrap_or(-1.0));
            s.push(if a.kinematic { 1.0 } else { 0.0 });
            s.push(a.max_force);
            s.push(if a.slipped { 1.0 } else { 0.0 });
            s.extend_from_slice(&[a.impulse.x, a.impulse.y, a.impulse.z]);
            s.push(a.particles.len() as f64);
            for (p, l) in a.particles.iter().zip(&a.local) {
                s.extend_from_slice(&[*p as f64, l.x, l.y, l.z]);
            }
        }
        s
    }

    /// Restores a state produced by [`Cloth::get_state`] of a cloth with the same mesh. The vector
    /// is validated completely before anything is changed.
    pub fn set_state(&mut self, state: &[f64]) -> Result<(), PbdError> {
        let mut r = Reader { s: state, k: 0 };
        let bad = |m: &str| PbdError::BadState(m.to_string());
        if r.next()? != STATE_MAGIC {
            return Err(bad("not a modesuite-pbd cloth state (wrong magic number)"));
        }
        let n = self.pos.len();
        if r.next()? != n as f64 {
            return Err(bad("particle count differs from this cloth"));
        }
        let time = r.next()?;
        let steps = r.next()?;
        let mut pos = Vec::with_capacity(n);
        let mut vel = Vec::with_capacity(n);
        for k in 0..2 * n {
            let v = r.vec3()?;
            if !finite3(&v) {
                return Err(bad("non-finite position or velocity"));
            }
            if k < n {
                pos.push(v)
            } else {
                vel.push(v)
            }
        }
        let nf = r.count()?;
        let mut frames = Vec::with_capacity(nf);
        for _ in 0..nf {
            let body = r.next()?;
            let prev = r.iso()?;
            let target = r.iso()?;
            frames.push(Frame {
                body: body as u32,
                prev,
                target,
            });
        }
        if self.drives.iter().any(|d| d.frame as usize >= nf) {
            return Err(bad("a driven frame of this cloth is missing"));
        }
        let next_attachment = r.count()? as u32;
        let na = r.count()?;
        let mut atts = Vec::with_capacity(na);
        for _ in 0..na {
            let id = r.count()? as u32;
            let frame = r.next()?;
            let frame = if frame < 0.0 {
                None
            } else {
                Some(frame as u32)
            };
            if let Some(f) = frame {
                if f as usize >= nf {
                    return Err(bad("attachment refers to a missing frame"));
                }
            }
            let kinematic = r.next()? != 0.0;
            let max_force = r.next()?;
            let slipped = r.next()? != 0.0;
            let impulse = r.vec3()?;
            let k = r.count()?;
            let mut particles = Vec::with_capacity(k);
            let mut local = Vec::with_capacity(k);
            for _ in 0..k {
                let p = r.count()?;
                if p >= n {
                    return Err(bad("attachment refers to a missing particle"));
                }
                particles.push(p as u32);
                local.push(r.vec3()?);
            }
            atts.push(Attachment {
                id,
                frame,
                kinematic,
                max_force,
                particles,
                local,
                slipped,
                impulse,
                lambda: vec![Vector3::zeros(); k],
                cand: vec![Vector3::zeros(); k],
            });
        }
        if r.k != state.len() {
            return Err(bad("trailing values"));
        }
        self.time = time;
        self.steps = steps as u64;
        self.pos = pos;
        self.vel = vel;
        self.frames = frames;
        self.next_attachment = next_attachment;
        self.attachments = atts;
        self.refresh_inv_mass();
        self.rebuild_tethers();
        Ok(())
    }
}

struct Reader<'a> {
    s: &'a [f64],
    k: usize,
}

impl Reader<'_> {
    fn next(&mut self) -> Result<f64, PbdError> {
        let v = self
            .s
            .get(self.k)
            .copied()
            .ok_or_else(|| PbdError::BadState("too short".into()))?;
        self.k += 1;
        Ok(v)
    }
    fn count(&mut self) -> Result<usize, PbdError> {
        let v = self.next()?;
        if v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v < 4.0e9 {
            Ok(v as usize)
        } else {
            Err(PbdError::BadState(format!("expected a count, found {v}")))
        }
    }
    fn vec3(&mut self) -> Result<Vector3<f64>, PbdError> {
        Ok(Vector3::new(self.next()?, self.next()?, self.next()?))
    }
    fn iso(&mut self) -> Result<Isometry3<f64>, PbdError> {
        let t = self.vec3()?;
        let (i, j, k, w) = (self.next()?, self.next()?, self.next()?, self.next()?);
        let q = Quaternion::from(nalgebra::Vector4::new(i, j, k, w));
        let p = Isometry3::from_parts(Translation3::from(t), UnitQuaternion::new_unchecked(q));
        if !iso_finite(&p) {
            return Err(PbdError::BadState("non-finite frame pose".into()));
        }
        Ok(p)
    }
}
