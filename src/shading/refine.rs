//! Refinement: evaluating nodes as they enter the cut, and the error list's
//! loop that replaces the worst node by its children until the threshold is
//! met.

use glam::{DVec3, Vec3};

use super::error_list::{Class, Entry, ErrorList};
use super::result::Stop;
use super::threshold::Threshold;
use crate::geometry::Surface;
use crate::numeric::{CompensatedSum, SUM_SLACK};
use crate::shader::{NodeEstimate, Shader};
use crate::tree::{LightTree, Node};
use crate::visibility::{Coverage, NodeRegion, Visibility};

/// One shading call's state: what it reads (tree, shader, the point), the
/// host it asks, and what it has settled and spent so far.
pub(crate) struct Cut<'a, S: Shader, V> {
    pub(crate) tree: &'a LightTree,
    pub(crate) shader: &'a S,
    pub(crate) surface: &'a Surface,
    pub(crate) per_point: S::PerPoint,
    /// The shading point as the host was given it.
    pub(crate) point: Vec3,
    pub(crate) max_contribution: Option<f64>,
    pub(crate) budget: u32,
    pub(crate) visibility: V,
    /// Exact leaves and nodes that need no refinement.
    pub(crate) settled: CompensatedSum,
    pub(crate) nodes: u32,
    pub(crate) lights: u32,
    pub(crate) classify_queries: u32,
    pub(crate) point_queries: u32,
}

/// How the error list's loop ended.
pub(crate) struct Outcome {
    pub(crate) stop: Stop,
    /// The excess over the target before, and the key of, the last
    /// refinement: they place the interpolation level between the last two
    /// steps.
    pub(crate) last_step: Option<(f64, f64)>,
}

impl<'a, S: Shader, V: Visibility> Cut<'a, S, V> {
    pub(crate) fn new(
        tree: &'a LightTree,
        shader: &'a S,
        surface: &'a Surface,
        point: Vec3,
        threshold: &Threshold,
        visibility: V,
    ) -> Self {
        Self {
            tree,
            shader,
            surface,
            per_point: shader.prepare(surface),
            point,
            max_contribution: threshold.max_contribution(),
            budget: threshold.budget().unwrap_or(u32::MAX).max(1),
            visibility,
            settled: CompensatedSum::default(),
            nodes: 0,
            lights: 0,
            classify_queries: 0,
            point_queries: 0,
        }
    }

    /// Evaluations so far, in the units of the budget.
    #[inline]
    pub(crate) fn cost(&self) -> u32 {
        self.nodes.saturating_add(self.lights)
    }

    /// Whether refining `node` (its children or its lights) fits in the
    /// budget.
    #[inline]
    pub(crate) fn can_refine(&self, node: &Node) -> bool {
        let cost = if node.is_leaf() {
            node.light_count
        } else {
            node.child_count
        };
        self.cost().saturating_add(cost) <= self.budget
    }

    /// The paper's error list: starting from the root, replaces the node of
    /// greatest (class, error) by its children while the threshold is not
    /// met and the budget allows.
    pub(crate) fn run(&mut self, list: &mut ErrorList, threshold: &Threshold) -> Outcome {
        list.clear();
        if !self.tree.nodes.is_empty()
            && let Some(root) = self.evaluate(0, false, 1.0)
        {
            list.push(root);
        }
        let mut outcome = Outcome {
            stop: Stop::ThresholdMet,
            last_step: None,
        };
        loop {
            let largest = list.largest();
            if list.may_stop() && self.met(list.sums(), largest, threshold) {
                // Confirm with exact sums: the running ones drift.
                let sums = list.resum();
                if self.met(sums, largest, threshold) {
                    break;
                }
            }
            let Some(top) = list.peek().copied() else {
                break;
            };
            let node = self.tree.nodes[top.node as usize];
            if !self.can_refine(&node) {
                outcome.stop = Stop::Budget;
                break;
            }
            let (estimate, error) = list.sums();
            let before = threshold.excess(
                self.settled.value() + estimate,
                reported_bound(error),
                largest,
            );
            outcome.last_step = Some((before, top.key));
            list.pop();
            self.refine(&node, top.visible, 1.0, |e| list.push(e));
        }
        outcome
    }

    /// Whether the cut with the error list's `(estimate, error)` sums meets
    /// the threshold, with the error bound exactly as it will be reported.
    #[inline]
    fn met(&self, (estimate, error): (DVec3, DVec3), largest: f64, threshold: &Threshold) -> bool {
        threshold.met(
            self.settled.value() + estimate,
            reported_bound(error),
            largest,
        )
    }

    /// Evaluates node `index` entering the cut with blend weight `weight`:
    /// settles it (exact single lights, dark, occluded or error-free nodes),
    /// or returns it as an unrefined entry.
    #[inline]
    pub(crate) fn evaluate(
        &mut self,
        index: usize,
        mut visible: bool,
        weight: f64,
    ) -> Option<Entry> {
        let node: &Node = &self.tree.nodes[index];
        if node.intensity == DVec3::ZERO {
            // Dark node: exactly zero whatever its geometry, even when its
            // ball holds the shading point; no query is needed.
            return None;
        }
        if node.radius == 0.0 {
            // A single light, or coincident lights (the build makes them one
            // leaf): exactly one light of the summed intensity at the
            // centroid, whatever their number.
            self.exact_light(node.centroid, node.intensity, visible, weight);
            return None;
        }
        let mut partial = false;
        if !V::ALWAYS_VISIBLE && !visible {
            self.classify_queries += 1;
            match self.visibility.classify(self.point, &region(node, index)) {
                Coverage::Occluded => return None,
                Coverage::Visible => visible = true,
                Coverage::Partial => partial = true,
            }
        }
        self.nodes += 1;
        let Some(cone) = node.cone(self.surface.point) else {
            return Some(Entry {
                class: Class::Unbounded,
                key: f64::INFINITY,
                node: index as u32,
                visible,
                estimate: DVec3::ZERO,
                error: DVec3::ZERO,
            });
        };
        let mut bound = self
            .shader
            .bound(&self.per_point, self.surface, node, &cone);
        if partial {
            // Partially occluded: anything between 0 and the unoccluded upper
            // bound. The host's visible fraction only moves the estimate.
            let fraction = self
                .visibility
                .visible_fraction(self.point, &region(node, index));
            let estimate = match fraction {
                Some(f) if f.is_finite() => bound.estimate * f64::from(f.clamp(0.0, 1.0)),
                _ => 0.5 * bound.upper,
            };
            bound = NodeEstimate::new(estimate, DVec3::ZERO, bound.upper);
        }
        let error = bound.error();
        let key = error.max_element();
        let over = self
            .max_contribution
            .is_some_and(|m| bound.upper.max_element() > m);
        if key <= 0.0 && !over {
            // Nothing to gain by refining (e.g. below the horizon).
            self.settled.add(bound.estimate * weight);
            return None;
        }
        Some(Entry {
            class: if over {
                Class::OverContribution
            } else {
                Class::Error
            },
            key,
            node: index as u32,
            visible,
            estimate: bound.estimate,
            error,
        })
    }

    /// Adds one light's exact contribution, times `weight`, asking the host
    /// for point-to-point visibility unless the light is known visible.
    #[inline]
    fn exact_light(&mut self, position: Vec3, intensity: DVec3, visible: bool, weight: f64) {
        if !V::ALWAYS_VISIBLE && !visible {
            self.point_queries += 1;
            if !self.visibility.visible(self.point, position) {
                return;
            }
        }
        self.lights += 1;
        let value = self.shader.eval(
            &self.per_point,
            self.surface,
            position.as_dvec3(),
            intensity,
        );
        self.settled.add(value * weight);
    }

    /// Refines `node`: its lights exactly if it is a leaf, its children
    /// otherwise, each with blend weight `weight`; children that need
    /// refinement are passed to `pending`.
    #[inline]
    pub(crate) fn refine(
        &mut self,
        node: &Node,
        visible: bool,
        weight: f64,
        mut pending: impl FnMut(Entry),
    ) {
        if node.is_leaf() {
            for k in node.lights() {
                let l = self.tree.lights[k];
                self.exact_light(l.position, l.intensity.as_dvec3(), visible, weight);
            }
        } else {
            for child in node.children() {
                if let Some(entry) = self.evaluate(child, visible, weight) {
                    pending(entry);
                }
            }
        }
    }
}

/// The certified bound reported for a summed error: the compensated sums
/// are within a few ulps of the sums of magnitudes; what that leaves of the
/// estimate's rounding is within the rounding allowance of the exact value
/// (terms are non-negative), and the error sum's own rounding is folded in
/// here.
#[inline]
pub(crate) fn reported_bound(error: DVec3) -> DVec3 {
    error * (1.0 + SUM_SLACK)
}

/// What the host is told about node `index`.
fn region(node: &Node, index: usize) -> NodeRegion {
    NodeRegion {
        index: index as u32,
        aabb: node.aabb,
        centroid: node.centroid,
        radius: node.radius,
        light_count: node.light_count,
    }
}
