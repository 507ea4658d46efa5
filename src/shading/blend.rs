//! Interpolation across levels (see [`Threshold::with_interpolation`]): the
//! cut's last nodes blended with their children so the estimate is
//! continuous in the shading point.

use glam::DVec3;

use super::error_list::{Class, Entry, ErrorList, Seen};
use super::refine::{Cut, reported_bound};
#[cfg(doc)]
use super::threshold::Threshold;
use crate::numeric::CompensatedSum;
use crate::shader::Shader;
use crate::visibility::Visibility;

/// A node waiting to be blended with its children.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pending {
    node: u32,
    /// Product of its ancestors' refinement weights.
    weight: f64,
    visible: bool,
}

/// The level at which the error list stopped, for the blend: between the
/// key of the last refinement (where the list would have stopped one step
/// earlier) and the largest key left, in proportion to where the excess
/// over the target crossed zero, so that it is continuous where the
/// stopping step changes.
pub(crate) fn level(last_step: Option<(f64, f64)>, after: f64, top: f64) -> f64 {
    match last_step {
        Some((before, key)) if before > 0.0 && before.is_finite() => {
            let beta = (before / (before - after)).clamp(0.0, 1.0);
            key + beta * (top - key)
        }
        _ => top,
    }
}

/// Blends every unrefined node of `list` whose error lies within `band` of
/// `level` with its children, recursively. Returns the blended radiance and
/// certified bound, or `None` when there is nothing to blend or blending
/// would exceed the budget. Consumes the error list.
pub(crate) fn blend<S: Shader, V: Visibility>(
    cut: &mut Cut<'_, S, V>,
    list: &mut ErrorList,
    stack: &mut Vec<Pending>,
    level: f64,
    band: f64,
) -> Option<(DVec3, DVec3)> {
    if list.peek().is_none() || !(level > 0.0 && level.is_finite()) {
        return None;
    }
    let floor = level / band;
    let ramp = |key: f64| ((key - floor) / (level - floor)).clamp(0.0, 1.0);
    let mut estimate = CompensatedSum::default();
    let mut error = CompensatedSum::default();
    stack.clear();
    // Each pending node carries the product of the refinement weights of its
    // ancestors; its own share (1 - alpha) keeps its virtual-light estimate
    // and the rest (alpha) goes to its children.
    let mut settle = |e: Entry, weight: f64, stack: &mut Vec<Pending>| {
        let alpha = if e.class == Class::Unbounded {
            1.0
        } else {
            ramp(e.key)
        };
        let (e_estimate, e_error) = e.counted();
        estimate.add(e_estimate * (weight * (1.0 - alpha)));
        error.add(e_error * (weight * (1.0 - alpha)));
        if alpha > 0.0 {
            stack.push(Pending {
                node: e.node,
                weight: weight * alpha,
                visible: e.seen == Seen::Visible,
            });
        }
    };
    for e in list.drain() {
        settle(e, 1.0, stack);
    }
    while let Some(p) = stack.pop() {
        let node = cut.tree.nodes[p.node as usize];
        if !cut.can_refine(&node, p.visible) {
            return None;
        }
        cut.refine(&node, p.visible, p.weight, |e| settle(e, p.weight, stack));
    }
    Some((
        cut.settled.value() + estimate.value(),
        reported_bound(error.value()),
    ))
}
