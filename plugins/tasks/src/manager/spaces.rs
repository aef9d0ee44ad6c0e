//! Observation spaces of the task's groups: the `policy` group's space and the items of a
//! frame of a group with camera images.

use modesuite_engine::Space;

use super::model::Group;
use crate::terms::Dims;

/// The space of the `policy` group: one unbounded box of every run of state terms (its
/// `history` frames one after another) or, with camera terms, a `Dict` of the items of
/// [`frame_items`], each with a leading axis of `history` frames (oldest first) when the group
/// stacks more than one: `state` of shape (history, n), an image of shape (history, height,
/// width, channels), the layout of Gymnasium's frame stacking.
pub(super) fn policy_space(g: &Group, dims: &Dims) -> Space {
    if !has_images(g) {
        let dim: usize = g.terms.iter().map(|t| t.term.term.dim(dims)).sum();
        return Space::unbounded(g.history * dim);
    }
    let items = frame_items(g, dims);
    if g.history == 1 {
        return Space::Dict(items);
    }
    let stack = |s: Space| match s {
        Space::Box { low, high, shape } => Space::Box {
            low: low.repeat(g.history),
            high: high.repeat(g.history),
            shape: [&[g.history][..], &shape].concat(),
        },
        other => other,
    };
    Space::Dict(items.into_iter().map(|(n, s)| (n, stack(s))).collect())
}

/// Whether a group has camera images (its observation is then a `Dict`).
pub(super) fn has_images(g: &Group) -> bool {
    g.terms.iter().any(|t| t.term.term.image().is_some())
}

/// The items of one frame of a group with camera images, in buffer order: each run of state
/// terms (`state`, `state_1`, ...; an unbounded box) and each image (`<camera>_<channels>`, a box
/// of shape (height, width, channels)).
pub(super) fn frame_items(g: &Group, dims: &Dims) -> Vec<(String, Space)> {
    let mut items: Vec<(String, Space)> = Vec::new();
    let mut run = 0usize;
    let mut states = 0usize;
    let mut flush = |run: &mut usize, items: &mut Vec<(String, Space)>| {
        if *run > 0 {
            let name = if states == 0 {
                "state".to_string()
            } else {
                format!("state_{states}")
            };
            states += 1;
            items.push((name, Space::unbounded(*run)));
            *run = 0;
        }
    };
    for t in &g.terms {
        match t.term.term.image() {
            None => run += t.term.term.dim(dims),
            Some((camera, channels, shape)) => {
                flush(&mut run, &mut items);
                let n: usize = shape.iter().product();
                items.push((
                    format!("{camera}_{}", channels.name()),
                    Space::Box {
                        low: vec![0.0; n],
                        high: vec![f32::INFINITY; n],
                        shape: shape.to_vec(),
                    },
                ));
            }
        }
    }
    flush(&mut run, &mut items);
    items
}
