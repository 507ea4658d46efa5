//! Baseline (d): a Lightcuts-style cut (Walter et al. 2005) built from the
//! crate's public API only (`Node`, `Cone::new`, `Shader::bound`).
//!
//! Same tree and node bounds as the crate's cut, different stopping rule:
//! refine the node of largest error (a max-heap keyed by the largest channel
//! of `Shader::bound(..).error()`) until that *single* largest node error is
//! at most `t` times the current estimate (largest channel), instead of the
//! paper's rule on the *sum* of node errors. Nodes whose ball reaches the
//! shading point (no `Cone`) have infinite error and are always refined.
//! The result is not certified: the summed error of the cut may exceed `t`
//! by the number of nodes in it. The report measures its actual error.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::DVec3;
use manylights::{Cone, LightTree, PointLight, Shader, Surface};

/// An unrefined node of the cut.
#[derive(Clone, Copy, Debug)]
struct Entry {
    /// Largest channel of the node's error bound.
    error: f64,
    node: u32,
    estimate: DVec3,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.error
            .total_cmp(&other.error)
            .then(other.node.cmp(&self.node))
    }
}

/// A Lightcuts session: tree, shader and reusable heap (no allocation once
/// warmed, like the crate's `Shading`).
pub struct Lightcuts<'t, S: Shader> {
    tree: &'t LightTree,
    shader: S,
    heap: BinaryHeap<Entry>,
}

/// Radiance and work of one Lightcuts evaluation.
#[derive(Clone, Copy, Debug)]
pub struct CutResult {
    /// Estimated radiance.
    pub radiance: DVec3,
    /// Node bounds plus single-light evaluations.
    pub cost: u32,
}

impl<'t, S: Shader> Lightcuts<'t, S> {
    /// A session over `tree` with `shader`.
    pub fn new(tree: &'t LightTree, shader: S) -> Self {
        Self {
            tree,
            shader,
            heap: BinaryHeap::new(),
        }
    }

    /// Shades `surface`, refining until the largest node error is at most
    /// `t` times the estimate.
    pub fn shade(&mut self, surface: &Surface, t: f64) -> CutResult {
        let frame = self.shader.frame(surface);
        self.heap.clear();
        let mut settled = DVec3::ZERO;
        let mut pending = DVec3::ZERO;
        let mut cost = 0;
        if !self.tree.is_empty() {
            self.enter(0, surface, &frame, &mut settled, &mut pending, &mut cost);
        }
        while let Some(&top) = self.heap.peek() {
            if top.error <= t * (settled + pending).max_element() {
                break;
            }
            self.heap.pop();
            pending -= top.estimate;
            let node = &self.tree.nodes()[top.node as usize];
            if node.is_leaf() {
                for light in &self.tree.lights()[node.lights()] {
                    settled += self.eval(surface, &frame, light);
                    cost += 1;
                }
            } else {
                for child in node.children() {
                    self.enter(
                        child,
                        surface,
                        &frame,
                        &mut settled,
                        &mut pending,
                        &mut cost,
                    );
                }
            }
        }
        // The running `pending` subtracts and may drift: sum the cut afresh.
        let radiance = settled + self.heap.iter().map(|e| e.estimate).sum::<DVec3>();
        CutResult { radiance, cost }
    }

    #[inline]
    fn eval(&self, surface: &Surface, frame: &S::Frame, light: &PointLight) -> DVec3 {
        self.shader.eval(
            frame,
            surface,
            light.position.as_dvec3(),
            light.intensity.as_dvec3(),
        )
    }

    /// Evaluates node `index`: a single light exactly, otherwise its bound,
    /// settled if it has no error and queued otherwise.
    fn enter(
        &mut self,
        index: usize,
        surface: &Surface,
        frame: &S::Frame,
        settled: &mut DVec3,
        pending: &mut DVec3,
        cost: &mut u32,
    ) {
        let node = &self.tree.nodes()[index];
        *cost += 1;
        if node.light_count() == 1 {
            let light = &self.tree.lights()[node.lights().start];
            *settled += self.eval(surface, frame, light);
            return;
        }
        let Some(cone) = Cone::new(surface.point, node) else {
            self.heap.push(Entry {
                error: f64::INFINITY,
                node: index as u32,
                estimate: DVec3::ZERO,
            });
            return;
        };
        let bound = self.shader.bound(frame, surface, node, &cone);
        let error = bound.error().max_element();
        if error <= 0.0 {
            *settled += bound.estimate;
            return;
        }
        *pending += bound.estimate;
        self.heap.push(Entry {
            error,
            node: index as u32,
            estimate: bound.estimate,
        });
    }
}
