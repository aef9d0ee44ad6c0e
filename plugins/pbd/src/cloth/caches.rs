//! Solver caches: the kernel choice, shared constraint rows, per-step caches, inverse masses
//! and the tethers derived from the attachments.

use super::Cloth;
#[cfg(test)]
use crate::lanes;
use crate::lanes::{BendRow, DistRow, OnceRows, RowCache, SolverRows};
use crate::material::TetherMetric;
use std::collections::BinaryHeap;
use std::sync::Arc;

impl Cloth {
    /// Chooses the AVX2 or the baseline kernels (tests: both give the same bits); AVX2 only
    /// where the machine has it. Returns whether AVX2 is used.
    #[cfg(test)]
    pub(crate) fn use_avx2(&mut self, on: bool) -> bool {
        self.avx2 = if on {
            lanes::Simd::detect()
        } else {
            lanes::Simd::baseline()
        };
        self.avx2.avx2()
    }

    /// Shares this cloth's solver rows with the other cloths that use `cache` (the envs of one
    /// compiled object): where their rows are bitwise equal they read one copy. Results do not
    /// change (the rows are a pure function of the cloth's data).
    pub(crate) fn share_rows(&mut self, cache: Arc<RowCache>) {
        self.row_cache = cache;
        self.cache_h = f64::NAN;
    }

    /// Whether this cloth reads the same solver rows as `other` (tests).
    #[cfg(test)]
    pub(crate) fn shares_rows_with(&self, other: &Cloth) -> bool {
        Arc::ptr_eq(&self.rows, &other.rows)
    }

    /// Recomputes the packed per-constraint rows for substep length `h` if stale.
    pub(super) fn refresh_caches(&mut self, h: f64) {
        if self.cache_h == h {
            return;
        }
        let inv_h2 = 1.0 / (h * h);
        let w = &self.inv_mass;
        let mut dist = Vec::with_capacity(self.dist_idx.len());
        for k in 0..self.dist_idx.len() {
            let [a, b] = self.dist_idx[k];
            let at = self.dist_alpha[k] * inv_h2;
            let (wa, wb) = (w[a as usize], w[b as usize]);
            let den = wa + wb + at;
            let inv_denom = if den > 0.0 { 1.0 / den } else { 0.0 };
            dist.push(DistRow {
                a,
                b,
                rest: self.dist_rest[k],
                at,
                inv_denom,
                ka: wa * inv_denom,
                kb: wb * inv_denom,
            });
        }
        let mut bend = Vec::with_capacity(self.bend_idx.len());
        for b in 0..self.bend_idx.len() {
            let ids = self.bend_idx[b];
            let k = self.bend_k[b];
            let at = self.bend_alpha[b] * inv_h2;
            let mut den = at;
            for j in 0..4 {
                den += w[ids[j] as usize] * k[j] * k[j];
            }
            let inv_denom = if den > 0.0 { 1.0 / den } else { 0.0 };
            let wk = [0, 1, 2, 3].map(|j| w[ids[j] as usize] * k[j] * inv_denom);
            bend.push(BendRow {
                ids,
                k,
                wk,
                at,
                inv_denom,
            });
        }
        let once = OnceRows::build(&dist, &self.dist_colour_end);
        self.rows = self.row_cache.share(SolverRows { dist, once, bend });
        self.cache_h = h;
    }

    pub(super) fn refresh_inv_mass(&mut self) {
        self.cache_h = f64::NAN;
        self.inv_mass.copy_from_slice(&self.inv_mass_free);
        for a in &self.attachments {
            if a.kinematic {
                for &p in &a.particles {
                    self.inv_mass[p as usize] = 0.0;
                }
            }
        }
    }

    /// Long-range attachments: each particle is tethered to its nearest anchor: a pinned
    /// (kinematic) particle, and with [`SolverSettings::grasp_tethers`] a grasped one too
    /// (multi-source Dijkstra over the edge graph, deterministic tie-breaking by index).
    ///
    /// [`SolverSettings::grasp_tethers`]: crate::material::SolverSettings::grasp_tethers
    pub(super) fn rebuild_tethers(&mut self) {
        let n = self.pos.len();
        self.tether_rows.clear();
        self.grasp_tether_rows.clear();
        if !self.settings.tethers {
            return;
        }
        #[derive(PartialEq)]
        struct Item(f64, u32, u32);
        impl Eq for Item {}
        impl PartialOrd for Item {
            fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
                Some(self.cmp(o))
            }
        }
        impl Ord for Item {
            fn cmp(&self, o: &Self) -> std::cmp::Ordering {
                // min-heap on distance, then particle, then anchor
                o.0.total_cmp(&self.0)
                    .then(o.1.cmp(&self.1))
                    .then(o.2.cmp(&self.2))
            }
        }
        let mut dist = vec![f64::INFINITY; n];
        let mut anchor = vec![u32::MAX; n];
        // predecessor on the shortest path and the rest length of that edge
        let mut parent = vec![(u32::MAX, 0.0); n];
        // Anchors that are grasped particles (a particle both pinned and grasped is a pin).
        let mut grasped = vec![false; n];
        let mut is_source = vec![false; n];
        let mut heap = BinaryHeap::new();
        for a in self.attachments.iter().filter(|a| a.kinematic) {
            for &p in &a.particles {
                is_source[p as usize] = true;
            }
        }
        if self.settings.grasp_tethers {
            for a in &self.attachments {
                if a.kinematic || a.frame.is_none() {
                    continue;
                }
                for &p in &a.particles {
                    if !is_source[p as usize] {
                        is_source[p as usize] = true;
                        grasped[p as usize] = true;
                    }
                }
            }
        }
        for s in 0..n {
            if is_source[s] {
                dist[s] = 0.0;
                anchor[s] = s as u32;
                heap.push(Item(0.0, s as u32, s as u32));
            }
        }
        while let Some(Item(d, p, a)) = heap.pop() {
            if d > dist[p as usize] || (d == dist[p as usize] && a != anchor[p as usize]) {
                continue;
            }
            // grasp-anchored particles in the order they are settled (parents first)
            let (par, len) = parent[p as usize];
            if par != u32::MAX && grasped[a as usize] {
                self.grasp_tether_rows.push((
                    p,
                    par,
                    len * (1.0 + self.settings.grasp_tether_slack),
                ));
            }
            let (s, e) = (
                self.adj_start[p as usize] as usize,
                self.adj_start[p as usize + 1] as usize,
            );
            for &(q, l) in &self.adj[s..e] {
                let nd = d + l;
                let qi = q as usize;
                if nd < dist[qi] || (nd == dist[qi] && a < anchor[qi]) {
                    dist[qi] = nd;
                    anchor[qi] = a;
                    parent[qi] = (p, l);
                    heap.push(Item(nd, q, a));
                }
            }
        }
        for i in 0..n {
            if anchor[i] == u32::MAX || anchor[i] as usize == i {
                continue;
            }
            let a = anchor[i] as usize;
            let len = match self.settings.tether_metric {
                TetherMetric::Graph => dist[i],
                TetherMetric::RestEuclidean => (self.rest[i] - self.rest[a]).norm(),
            };
            if !grasped[a] {
                self.tether_rows.push((i as u32, a as u32, len));
            }
        }
    }
}
