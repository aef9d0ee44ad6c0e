//! Frames (rigid bodies the cloth is attached to) and attachments: pins, drives, frame
//! attachments and force-limited grasps.

use super::{
    finite3, iso_finite, Attachment, AttachmentId, Cloth, Drive, Frame, FrameId, OrientedBox,
};
use crate::error::PbdError;
use nalgebra::{Isometry3, Point3, Vector3};

impl Cloth {
    // ------------------------------------------------------------------ frames and attachments

    /// Adds a frame (e.g. a gripper link) at `pose`; `body` is the rigid body that receives the
    /// attachment reactions (`u32::MAX` for none).
    pub fn add_frame(&mut self, pose: Isometry3<f64>, body: u32) -> Result<FrameId, PbdError> {
        if !iso_finite(&pose) {
            return Err(PbdError::InvalidParameter {
                field: "frame pose",
                value: format!("{pose:?}"),
                expected: "a finite pose",
            });
        }
        self.frames.push(Frame {
            body,
            prev: pose,
            target: pose,
        });
        Ok(FrameId(self.frames.len() as u32 - 1))
    }

    /// Sets the pose the frame will have at the end of the next step; attachments follow the
    /// pose interpolated over the substeps (translation linear, rotation slerp).
    pub fn set_frame_pose(&mut self, frame: FrameId, pose: Isometry3<f64>) -> Result<(), PbdError> {
        if !iso_finite(&pose) {
            return Err(PbdError::InvalidParameter {
                field: "frame pose",
                value: format!("{pose:?}"),
                expected: "a finite pose",
            });
        }
        let f = self
            .frames
            .get_mut(frame.0 as usize)
            .ok_or_else(|| PbdError::Unknown(format!("frame {}", frame.0)))?;
        f.target = pose;
        Ok(())
    }

    /// Current (end of last step) pose of a frame.
    pub fn frame_pose(&self, frame: FrameId) -> Result<Isometry3<f64>, PbdError> {
        self.frames
            .get(frame.0 as usize)
            .map(|f| f.prev)
            .ok_or_else(|| PbdError::Unknown(format!("frame {}", frame.0)))
    }

    fn check_particles(&self, particles: &[u32]) -> Result<(), PbdError> {
        if particles.is_empty() {
            return Err(PbdError::InvalidParameter {
                field: "particles",
                value: "[]".into(),
                expected: "at least one particle",
            });
        }
        if let Some(&p) = particles.iter().find(|&&p| p as usize >= self.pos.len()) {
            return Err(PbdError::Unknown(format!("particle {p}")));
        }
        Ok(())
    }

    fn push_attachment(
        &mut self,
        frame: Option<u32>,
        kinematic: bool,
        max_force: f64,
        particles: &[u32],
    ) -> AttachmentId {
        let local: Vec<Vector3<f64>> = particles
            .iter()
            .map(|&p| {
                let x = self.pos[p as usize];
                match frame {
                    None => x,
                    Some(f) => {
                        self.frames[f as usize]
                            .prev
                            .inverse_transform_point(&Point3::from(x))
                            .coords
                    }
                }
            })
            .collect();
        let id = self.next_attachment;
        self.next_attachment += 1;
        let k = particles.len();
        self.attachments.push(Attachment {
            id,
            frame,
            kinematic,
            max_force,
            particles: particles.to_vec(),
            local,
            slipped: false,
            impulse: Vector3::zeros(),
            lambda: vec![Vector3::zeros(); k],
            cand: vec![Vector3::zeros(); k],
        });
        self.refresh_inv_mass();
        self.rebuild_tethers();
        AttachmentId(id)
    }

    /// Pins particles to their current world positions (kinematic: they never move).
    pub fn pin_to_world(&mut self, particles: &[u32]) -> Result<AttachmentId, PbdError> {
        self.check_particles(particles)?;
        Ok(self.push_attachment(None, true, f64::INFINITY, particles))
    }

    /// Pins particles rigidly (kinematically) to a frame at their current offsets; they follow
    /// the frame exactly, and no reaction is reported (use [`Cloth::attach_to_frame`] with an
    /// infinite limit for a measured force).
    pub fn pin_to_frame(
        &mut self,
        frame: FrameId,
        particles: &[u32],
    ) -> Result<AttachmentId, PbdError> {
        self.check_particles(particles)?;
        if frame.0 as usize >= self.frames.len() {
            return Err(PbdError::Unknown(format!("frame {}", frame.0)));
        }
        Ok(self.push_attachment(Some(frame.0), true, f64::INFINITY, particles))
    }

    /// Pins particles kinematically to a new frame that the cloth itself moves at constant
    /// `velocity` (m/s, world frame) during the simulated-time window `[start, stop]` (s) and holds
    /// still before and after (a scripted handle: a group dragged along the ground, a corner
    /// lifted). The frame's pose follows from the cloth's time, so snapshots need nothing extra;
    /// [`Cloth::set_frame_pose`] on this frame is overridden at every step.
    pub fn drive_particles(
        &mut self,
        particles: &[u32],
        velocity: Vector3<f64>,
        start: f64,
        stop: f64,
    ) -> Result<(FrameId, AttachmentId), PbdError> {
        self.check_particles(particles)?;
        if !finite3(&velocity) {
            return Err(PbdError::InvalidParameter {
                field: "drive velocity",
                value: format!("{velocity:?}"),
                expected: "a finite vector (m/s)",
            });
        }
        if !(start.is_finite() && stop.is_finite() && start >= 0.0 && stop >= start) {
            return Err(PbdError::InvalidParameter {
                field: "drive window",
                value: format!("[{start}, {stop}]"),
                expected: "finite times with 0 <= start <= stop (s)",
            });
        }
        let frame = self.add_frame(Isometry3::identity(), u32::MAX)?;
        let id = self.pin_to_frame(frame, particles)?;
        self.drives.push(Drive {
            frame: frame.0,
            origin: Isometry3::identity(),
            velocity,
            start,
            stop,
        });
        Ok((frame, id))
    }

    /// Attaches particles to a frame at their current offsets with a total force limit `max_force`
    /// (N, may be `f64::INFINITY`). Above the limit the particles slip (they are re-anchored
    /// where the limited force leaves them, like kinetic friction). Reactions go to the frame's
    /// body.
    pub fn attach_to_frame(
        &mut self,
        frame: FrameId,
        particles: &[u32],
        max_force: f64,
    ) -> Result<AttachmentId, PbdError> {
        self.check_particles(particles)?;
        if frame.0 as usize >= self.frames.len() {
            return Err(PbdError::Unknown(format!("frame {}", frame.0)));
        }
        if max_force.is_nan() || max_force <= 0.0 {
            return Err(PbdError::InvalidParameter {
                field: "max_force",
                value: format!("{max_force}"),
                expected: "a force > 0 N (or infinity)",
            });
        }
        Ok(self.push_attachment(Some(frame.0), false, max_force, particles))
    }

    /// A gripper closes: attaches every particle inside the finger volume `volume` (world frame,
    /// current positions) to `frame` with force limit `max_force` (N). Returns `None` when no
    /// particle is inside.
    pub fn grasp(
        &mut self,
        frame: FrameId,
        volume: &OrientedBox,
        max_force: f64,
    ) -> Result<Option<AttachmentId>, PbdError> {
        if !iso_finite(&volume.pose) || !finite3(&volume.half_extents) {
            return Err(PbdError::InvalidParameter {
                field: "grasp volume",
                value: format!("{volume:?}"),
                expected: "a finite pose and half extents",
            });
        }
        let inside: Vec<u32> = (0..self.pos.len() as u32)
            .filter(|&p| volume.contains(&self.pos[p as usize]))
            .collect();
        if inside.is_empty() {
            return Ok(None);
        }
        self.attach_to_frame(frame, &inside, max_force).map(Some)
    }

    /// Removes an attachment (opening the gripper releases the grasp).
    pub fn release(&mut self, id: AttachmentId) -> Result<(), PbdError> {
        let k = self
            .attachments
            .iter()
            .position(|a| a.id == id.0)
            .ok_or_else(|| PbdError::Unknown(format!("attachment {}", id.0)))?;
        self.attachments.remove(k);
        self.refresh_inv_mass();
        self.rebuild_tethers();
        Ok(())
    }

    /// Particles held by an attachment.
    pub fn attachment_particles(&self, id: AttachmentId) -> Result<&[u32], PbdError> {
        self.attachment(id).map(|a| a.particles.as_slice())
    }

    /// Mean force the attachment exerted on the cloth during the last step, world frame, N.
    pub fn attachment_force(&self, id: AttachmentId, dt: f64) -> Result<Vector3<f64>, PbdError> {
        self.attachment(id).map(|a| a.impulse / dt)
    }

    /// Changes the force limit of a frame attachment or grasp (N, > 0, may be infinite).
    pub fn set_attachment_force_limit(
        &mut self,
        id: AttachmentId,
        max_force: f64,
    ) -> Result<(), PbdError> {
        if max_force.is_nan() || max_force <= 0.0 {
            return Err(PbdError::InvalidParameter {
                field: "max_force",
                value: format!("{max_force}"),
                expected: "a force > 0 N (or infinity)",
            });
        }
        let a = self
            .attachments
            .iter_mut()
            .find(|a| a.id == id.0)
            .ok_or_else(|| PbdError::Unknown(format!("attachment {}", id.0)))?;
        if a.kinematic {
            return Err(PbdError::InvalidParameter {
                field: "attachment",
                value: format!("{}", id.0),
                expected: "a force-limited attachment (pins are kinematic)",
            });
        }
        a.max_force = max_force;
        Ok(())
    }

    /// Whether the attachment hit its force limit (slipped) during the last step.
    pub fn attachment_slipped(&self, id: AttachmentId) -> Result<bool, PbdError> {
        self.attachment(id).map(|a| a.slipped)
    }

    /// The first frame that follows rigid body `body`, if any.
    pub fn frame_of_body(&self, body: u32) -> Option<FrameId> {
        self.frames
            .iter()
            .position(|f| f.body == body)
            .map(|i| FrameId(i as u32))
    }

    /// Frames that follow a rigid body (body id other than `u32::MAX`), with their body ids.
    pub fn body_frames(&self) -> Vec<(FrameId, u32)> {
        self.frames
            .iter()
            .enumerate()
            .filter(|(_, f)| f.body != u32::MAX)
            .map(|(i, f)| (FrameId(i as u32), f.body))
            .collect()
    }

    /// The force-limited (grasp) attachments on `frame`, in creation order.
    pub fn grasps_on(&self, frame: FrameId) -> Vec<AttachmentId> {
        self.attachments
            .iter()
            .filter(|a| a.frame == Some(frame.0) && !a.kinematic)
            .map(|a| AttachmentId(a.id))
            .collect()
    }

    /// Appends the particles held by grasps (force-limited attachments on body frames).
    pub fn grasped_particles(&self, out: &mut Vec<u32>) {
        out.extend(
            self.attachments
                .iter()
                .filter(|a| a.frame.is_some() && !a.kinematic)
                .flat_map(|a| a.particles.iter().copied()),
        );
    }

    /// Appends the particles that a rigid contact pushed in the last substep of the last step
    /// (particle order).
    pub fn contact_particles(&self, out: &mut Vec<u32>) {
        out.extend(
            self.c_particle
                .iter()
                .zip(&self.c_dn)
                .filter(|(_, dn)| **dn > 0.0)
                .map(|(p, _)| *p),
        );
    }

    /// Ids of all attachments, in creation order.
    pub fn attachment_ids(&self) -> Vec<AttachmentId> {
        self.attachments
            .iter()
            .map(|a| AttachmentId(a.id))
            .collect()
    }

    fn attachment(&self, id: AttachmentId) -> Result<&Attachment, PbdError> {
        self.attachments
            .iter()
            .find(|a| a.id == id.0)
            .ok_or_else(|| PbdError::Unknown(format!("attachment {}", id.0)))
    }
}
