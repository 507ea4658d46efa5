//! Where a certified cut's work goes: on the street city at fixed density
//! (the scaling part's scene and points), at a certified 1%, per size, the
//! nodes the cut refines and the children it bounds, by depth and by
//! distance, the entries left in the final cut and their share of the
//! error, and how loose their bounds are against their own lights summed
//! exactly.
//!
//! It watches the cut from outside, through a [`Shader`] that forwards
//! every call of the public trait to [`Lambert`] and records the children
//! it bounds ([`Shader::bound_nodes`]) and the lights it sums
//! ([`Shader::eval_lights`]). Such a shader gets the cut a custom shader
//! gets: `f64` bounds and sums, without `Lambert`'s coarse `f32` lanes, so
//! it refines a little more than `Lambert` itself. A bounded node stays in the final cut
//! unless the cut later bounds its children or sums lights of its own;
//! nodes left exactly 0 are not seen, so the entries' errors fall a little
//! short of the reported bound or, where a node's children were all
//! settled without a call, exceed it slightly (the table prints the
//! ratio).

use std::cell::RefCell;
use std::collections::{BTreeMap, HashSet};
use std::error::Error;

use glam::{DVec3, Vec3};
use manylights::shader::{Cone, Node, NodeEstimate, Shader, Surface};
use manylights::{BoundKind, Lambert, LightTree, PointLight, Threshold, Unoccluded};

use crate::config::{SCALING_RELATIVE, SEED};
use crate::scenes;
use crate::sweep::query;

/// Numbers of lights.
const SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];
/// Shading points per size (the scaling part's).
const POINTS: usize = 128;

/// What one shading point's cut did, as the recorder saw it.
#[derive(Default)]
struct Seen {
    /// Nodes whose children were bounded together.
    parents: Vec<usize>,
    /// Children bounded (with a finite bound or none).
    children: usize,
    /// Each child bounded finitely, with its estimate.
    bounded: Vec<(usize, NodeEstimate)>,
    /// Light ranges summed (indices into the tree's lights).
    summed: Vec<(usize, usize)>,
}

/// [`Lambert`], recording what the cut asks of it.
struct Recorder {
    inner: Lambert,
    /// Address of the tree's first light, to turn summed slices into
    /// ranges.
    base: usize,
    /// Address of the tree's first node, to turn bounded nodes into
    /// indices.
    nodes: usize,
    /// Each node's parent (the root's is 0).
    parent: Vec<usize>,
    seen: RefCell<Seen>,
}

impl Recorder {
    /// The index of `node` in the tree's nodes.
    fn index_of(&self, node: &Node) -> usize {
        (node as *const Node as usize - self.nodes) / size_of::<Node>()
    }

    fn range_of(&self, lights: &[PointLight]) -> (usize, usize) {
        let start = (lights.as_ptr() as usize - self.base) / size_of::<PointLight>();
        (start, start + lights.len())
    }
}

impl Shader for Recorder {
    type PerPoint = ();

    fn prepare(&self, surface: &Surface) {
        self.inner.prepare(surface)
    }
    fn eval(&self, p: &(), surface: &Surface, position: DVec3, intensity: DVec3) -> DVec3 {
        self.inner.eval(p, surface, position, intensity)
    }
    fn bound(&self, p: &(), surface: &Surface, node: &Node, cone: &Cone) -> NodeEstimate {
        self.inner.bound(p, surface, node, cone)
    }
    fn eval_lights(&self, p: &(), surface: &Surface, lights: &[PointLight], out: &mut [DVec3]) {
        self.seen.borrow_mut().summed.push(self.range_of(lights));
        self.inner.eval_lights(p, surface, lights, out)
    }
    fn bound_nodes(
        &self,
        p: &(),
        surface: &Surface,
        nodes: &[&Node],
        cones: &[Cone],
        out: &mut [NodeEstimate],
    ) {
        self.inner.bound_nodes(p, surface, nodes, cones, out);
        let mut seen = self.seen.borrow_mut();
        if let Some(first) = nodes.first() {
            seen.parents.push(self.parent[self.index_of(first)]);
        }
        seen.children += nodes.len();
        for (node, bound) in nodes.iter().zip(out.iter()) {
            seen.bounded.push((self.index_of(node), *bound));
        }
    }
    fn horizon(&self, surface: &Surface) -> Option<Vec3> {
        self.inner.horizon(surface)
    }
}

/// Per depth: children bounded, final entries, and the entries' errors
/// over the point's radiance (sums over the points).
#[derive(Default, Clone, Copy)]
struct Depth {
    bounded: f64,
    entries: f64,
    error: f64,
}

/// What the recorder saw over every point of one size, summed over the
/// points (divide by `points`).
pub struct Anatomy {
    /// Depth of the tree.
    pub depth: usize,
    /// Points with a positive radiance, over which the sums are taken.
    pub points: usize,
    /// Refinements that bounded children.
    pub refinements: usize,
    /// Children bounded (finitely or not).
    pub bounded: usize,
    /// Entries left in the final cut.
    pub entries: usize,
    /// Per point, the entries' summed error bounds (largest channel) over
    /// the reported bound (largest channel), summed over the points.
    pub share_of_reported: f64,
    /// Per depth: children bounded finitely, final entries, and their
    /// errors over the point's radiance.
    by_depth: BTreeMap<usize, Depth>,
    /// Children bounded finitely, by `floor(log2(D / R))`.
    by_distance: BTreeMap<i32, usize>,
    /// The final entries' error bounds, summed (per entry the channel of
    /// the larger estimate).
    pub bounds: f64,
    /// Their actual errors against their own lights summed exactly,
    /// summed as magnitudes.
    pub actual: f64,
    /// The same, summed with their signs.
    pub signed: f64,
    /// Each entry's bound over its actual error (entries with an error),
    /// sorted.
    pub looseness: Vec<f64>,
}

/// Watches the cut at a certified [`SCALING_RELATIVE`] on the street city
/// of `n` lights at `points` ground points; an error if a result breaks
/// its certified bound.
pub fn anatomy(n: usize, points: usize) -> Result<Anatomy, Box<dyn Error>> {
    let scene = scenes::city(n, points, SEED);
    let tree = LightTree::build(&scene.lights)?;
    let shader = Lambert::new(scene.material.kd).with_bound(BoundKind::Series);
    let mut parent = vec![0usize; tree.nodes().len()];
    for (i, node) in tree.nodes().iter().enumerate() {
        for child in node.children() {
            parent[child] = i;
        }
    }
    let recorder = Recorder {
        inner: shader,
        base: tree.lights().as_ptr() as usize,
        nodes: tree.nodes().as_ptr() as usize,
        parent,
        seen: RefCell::new(Seen::default()),
    };
    let mut shading = tree.shading(recorder);
    let threshold = Threshold::relative(SCALING_RELATIVE);
    let nodes = tree.nodes();
    let mut depth = vec![0usize; nodes.len()];
    for (i, node) in nodes.iter().enumerate() {
        for child in node.children() {
            depth[child] = depth[i] + 1;
        }
    }
    let (mut refinements, mut bounded, mut entries) = (0usize, 0usize, 0usize);
    let mut share_of_reported = 0.0;
    let mut by_depth = BTreeMap::<usize, Depth>::new();
    let mut by_distance = BTreeMap::<i32, usize>::new();
    let (mut bounds, mut actuals, mut signed) = (0.0, 0.0, 0.0);
    let mut looseness = Vec::new();
    let mut lit = 0usize;
    for pt in &scene.points {
        *shading.shader().seen.borrow_mut() = Seen::default();
        let q = query(pt);
        let r = shading.shade_query(&q, threshold, Unoccluded)?;
        let exact = shading.exact_query(&q, Unoccluded);
        if !r.certifies(exact) {
            return Err(format!("{n} lights: a point breaks its certified bound").into());
        }
        let radiance = r.radiance.max_element();
        if radiance <= 0.0 {
            continue;
        }
        lit += 1;
        let seen = shading.shader().seen.borrow();
        refinements += seen.parents.len();
        bounded += seen.children;
        let parents: HashSet<usize> = seen.parents.iter().copied().collect();
        let surface = q.surface();
        let mut cut_error = 0.0;
        for &(index, bound) in &seen.bounded {
            let node = &nodes[index];
            let at = depth[index];
            by_depth.entry(at).or_default().bounded += 1.0;
            let distance = (node.centroid() - pt.point).length() / node.radius();
            *by_distance
                .entry(distance.log2().floor() as i32)
                .or_default() += 1;
            let own = node.lights();
            let refined = parents.contains(&index)
                || seen
                    .summed
                    .iter()
                    .any(|&(s, e)| s >= own.start && e <= own.end);
            if refined {
                continue;
            }
            entries += 1;
            let k = if bound.estimate.x >= bound.estimate.y.max(bound.estimate.z) {
                0
            } else if bound.estimate.y >= bound.estimate.z {
                1
            } else {
                2
            };
            let error = bound.error()[k];
            cut_error += bound.error().max_element();
            let slot = by_depth.entry(at).or_default();
            slot.entries += 1.0;
            slot.error += bound.error().max_element() / radiance;
            let mut sum = 0.0;
            for light in &tree.lights()[own] {
                let value = shading.shader().inner.eval(
                    &(),
                    surface,
                    light.position.as_dvec3(),
                    light.intensity.as_dvec3(),
                );
                sum += value[k];
            }
            let actual = bound.estimate[k] - sum;
            bounds += error;
            actuals += actual.abs();
            signed += actual;
            if actual != 0.0 {
                looseness.push(error / actual.abs());
            }
        }
        share_of_reported += cut_error / r.error_bound.max_element();
    }
    looseness.sort_by(f64::total_cmp);
    Ok(Anatomy {
        depth: tree.depth() as usize,
        points: lit,
        refinements,
        bounded,
        entries,
        share_of_reported,
        by_depth,
        by_distance,
        bounds,
        actual: actuals,
        signed,
        looseness,
    })
}

/// Prints the part; an error if a result breaks its certified bound.
pub fn print_anatomy() -> Result<(), Box<dyn Error>> {
    println!(
        "## Anatomy of a certified cut: street city at fixed density, {POINTS} ground points, \
         certified {SCALING_RELATIVE} relative\n"
    );
    println!(
        "Per point: refinements that bounded children, children bounded, entries left in the \
         final cut, and the entries' summed error bounds over the reported bound; the distances \
         of the children bounded finitely in their radii (D / R); by depth, children bounded \
         finitely / final entries / the entries' error as a share of the radiance; and against each final \
         entry's lights summed exactly (the channel of the larger estimate), the entries' \
         summed bounds over their summed actual errors and over the cut's actual error, and the \
         median entry's bound over its error.\n"
    );
    for n in SIZES {
        let a = anatomy(n, POINTS)?;
        let per_point = |v: f64| v / a.points.max(1) as f64;
        let median = a
            .looseness
            .get(a.looseness.len() / 2)
            .copied()
            .unwrap_or(0.0);
        println!(
            "{n} lights (depth {}): {:.1} refinements, {:.1} children bounded, {:.1} final \
             entries per point; their error bounds {:.2}x the reported bound",
            a.depth,
            per_point(a.refinements as f64),
            per_point(a.bounded as f64),
            per_point(a.entries as f64),
            per_point(a.share_of_reported),
        );
        let distances: Vec<String> = a
            .by_distance
            .iter()
            .filter(|(_, c)| per_point(**c as f64) >= 0.05)
            .map(|(k, c)| {
                format!(
                    "[{}, {}): {:.1}",
                    2f64.powi(*k),
                    2f64.powi(k + 1),
                    per_point(*c as f64)
                )
            })
            .collect();
        println!("  D / R of the bounded children: {}", distances.join(", "));
        let depths: Vec<String> = a
            .by_depth
            .iter()
            .map(|(d, s)| {
                format!(
                    "{d}: {:.1} / {:.1} / {:.2}%",
                    per_point(s.bounded),
                    per_point(s.entries),
                    100.0 * per_point(s.error)
                )
            })
            .collect();
        println!("  by depth: {}", depths.join(", "));
        println!(
            "  looseness: summed bounds {:.2}x the summed actual errors, {:.2}x the cut's actual \
             error; median entry {:.1}x\n",
            a.bounds / a.actual,
            a.bounds / a.signed.abs(),
            median
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorded_cut_accounts_for_the_reported_bound() {
        let a = anatomy(3_000, 12).expect("the cut keeps its certificate");
        assert!(a.points > 0);
        assert!(a.entries <= a.bounded && a.refinements > 0);
        // The final entries found carry the reported bound, up to the
        // rounding the cut adds and nodes settled without a call.
        let share = a.share_of_reported / a.points as f64;
        assert!((0.9..=1.1).contains(&share), "{share}");
        // Each entry's bound is certified against its own lights, so the
        // summed bounds cover the summed actual errors.
        assert!(a.bounds >= a.actual && a.actual > 0.0);
        assert!(a.looseness.first().is_some_and(|&l| l >= 1.0));
        let depths: f64 = a.by_depth.values().map(|d| d.entries).sum();
        assert_eq!(depths as usize, a.entries);
    }
}
