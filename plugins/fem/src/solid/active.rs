//! The active constraint set of a solve (world constraints, attachments, contacts; one per
//! node) and the filter that projects constrained components out of a vector.

use super::{ActiveCon, ConKind, FemSolid};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

impl FemSolid {
    // ----------------------------------------------------------------- solver internals

    pub(super) fn build_active(&mut self) {
        self.active.clear();
        for w in &self.world {
            self.active.push(ActiveCon {
                node: w.node,
                proj: w.proj,
                target: w.target,
                normal: Vector3::zeros(),
                kind: ConKind::World,
            });
        }
        for (ai, a) in self.attachments.iter().enumerate() {
            let pose = match self.poses.binary_search_by_key(&a.body, |p| p.0) {
                Ok(k) => self.poses[k].1,
                Err(_) => Isometry3::identity(),
            };
            for (&n, l) in a.nodes.iter().zip(&a.local) {
                let target = (pose * Point3::from(*l)).coords;
                self.active.push(ActiveCon {
                    node: n,
                    proj: Matrix3::identity(),
                    target,
                    normal: Vector3::zeros(),
                    kind: ConKind::Attachment(ai as u32),
                });
            }
        }
        for c in self.candidates.iter() {
            if c.active {
                let n = c.contact.normal;
                let (proj, target) = if c.stick {
                    (Matrix3::identity(), c.stick_target)
                } else {
                    (n * n.transpose(), c.contact.point)
                };
                self.active.push(ActiveCon {
                    node: c.node,
                    proj,
                    target,
                    normal: n,
                    kind: ConKind::Contact,
                });
            }
        }
        // one constraint per node, by priority: attachment > world > contact (a contact on a
        // node that is already constrained is dropped)
        let rank = |k: &ConKind| match k {
            ConKind::Attachment(..) => 0u8,
            ConKind::World => 1,
            ConKind::Contact => 2,
        };
        self.active.sort_by_key(|c| (c.node, rank(&c.kind)));
        let mut merged: Vec<ActiveCon> = Vec::with_capacity(self.active.len());
        for c in self.active.drain(..) {
            if merged.last().is_some_and(|l| l.node == c.node) {
                continue;
            }
            merged.push(c);
        }
        self.active = merged;
    }

    pub(super) fn apply_filter(active: &[ActiveCon], v: &mut [Vector3<f64>]) {
        for c in active {
            let x = &mut v[c.node as usize];
            *x -= c.proj * *x;
        }
    }

    pub(super) fn full_constrained(&self) -> Vec<bool> {
        let mut full = vec![false; self.n_nodes()];
        for w in &self.world {
            if (w.proj - Matrix3::identity()).norm() < 1e-12 {
                full[w.node as usize] = true;
            }
        }
        for a in &self.attachments {
            for &n in &a.nodes {
                full[n as usize] = true;
            }
        }
        full
    }
}
