//! The statistics pass: every node's statistics from the lights, bottom-up,
//! for a tree whose topology is set. Build and refit share it, and the
//! tree's planes and children's blocks, which follow from its results and
//! its [`Notes`].

use core::ops::Range;

use glam::DVec3;

use super::groups::leaf_ratios;
use super::layout::LightTree;
use super::leaf_moments::LeafScratch;
use super::moment_statistics::Statistics;
use super::moments::Moments;
use super::node::{MAX_CHILDREN, Node};
use super::notes::Notes;
use super::plane::{certainly_not_coplanar, record_planes};
use super::pool::Pool;
use super::prefetch::{as_bytes_range, prefetch};
use crate::PointLight;
use crate::geometry::Aabb;
use crate::numeric::{BUILD_LENGTH_SLACK, round_up_f32};

/// Every node's statistics ([`fill_statistics`]), then what follows from
/// them and from the pass's notes: the planes of the nodes whose lights
/// lie in one (see [`record_planes`]) and the blocks of every node's
/// children (see [`NodeGroups`](super::groups::NodeGroups)), on `pool`.
pub(super) fn fill_nodes(tree: &mut LightTree, pool: Pool) {
    let mut notes = fill_statistics(tree, pool);
    record_planes(tree, &notes, pool.cheap(tree.lights.len()));
    tree.groups.refill_from_notes(&tree.nodes, &mut notes, pool);
    super::slabs::fill_slabs(tree, pool);
}

/// Computes every node's statistics from the lights, in time linear in
/// their number (but for the radii's search through each node's subtree,
/// which reads a few leaves per node), for a tree whose topology is set:
/// children hold larger indices than their parent.
///
/// One depth-first pass, children before their parent, so that a
/// subtree's lights are read while they are in the cache:
///
/// 1. A leaf sums its lights' intensities, weights, weighted positions and
///    box; any other node its children's sums. Then the centroid.
/// 2. The radius: the largest distance from the centroid to a member (a
///    leaf's over its lights; any other node's found through its subtree,
///    see [`farthest_member`]).
/// 3. Moments up to degree 5 (see [`Moments`]): summed directly over each
///    leaf's lights, shifted from the children's centroids to the parent's
///    for every other node; a node's children's moments wait in one buffer
///    per level of the path until its centroid is known (eight moments of
///    about 2 KiB a level: some 350 KiB for a tree 20 levels deep, per
///    thread).
///
/// On a pool, disjoint subtrees are done side by side (each node by the
/// same operations in the same order as on one thread), then the few nodes
/// above them.
///
/// Returns every node's [`Notes`] for the planes and the blocks.
fn fill_statistics(tree: &mut LightTree, pool: Pool) -> Vec<Notes> {
    let (lights, nodes) = (&tree.lights, &mut tree.nodes);
    let mut notes = vec![Notes::NONE; nodes.len()];
    if nodes.is_empty() {
        return notes;
    }
    let mut scratch = StatisticsScratch::new();
    if !pool.parallel() {
        let mut levels = Levels::split(nodes, &mut notes, &[0])
            .pop()
            .expect("one subtree");
        fill_subtree(&mut levels, lights, &mut scratch);
        return notes;
    }
    let roots = subtrees(nodes, pool.parts());
    let subtrees = Levels::split(nodes, &mut notes, &roots);
    let done = pool.map_owned(subtrees, StatisticsScratch::new, |scratch, mut levels| {
        let (sums, moments) = fill_subtree(&mut levels, lights, scratch);
        Done {
            root: levels.root() as u32,
            sums,
            moments: *moments,
        }
    });
    let mut done = done;
    done.sort_unstable_by_key(|d| d.root);
    let mut levels = Levels::split(nodes, &mut notes, &[0])
        .pop()
        .expect("one subtree");
    levels.done = &done;
    fill_subtree(&mut levels, lights, &mut scratch);
    notes
}

/// A node's sums that its parent's are made of, in `f64`.
#[derive(Clone, Copy, Debug)]
struct Sums {
    /// The members' summed weight `W = sum_i w_i`.
    weight: f64,
    /// Their summed weighted position `sum_i w_i x_i`.
    weighted: DVec3,
    /// Their summed position, for the plain mean of a node without weight.
    plain: DVec3,
}

impl Sums {
    /// The sums over no members.
    const ZERO: Self = Self {
        weight: 0.0,
        weighted: DVec3::ZERO,
        plain: DVec3::ZERO,
    };
}

/// A node's totals, summed from its lights (a leaf) or from its children:
/// its intensity, the [`Sums`] its parent takes, and its box.
#[derive(Clone, Copy, Debug)]
struct Totals {
    intensity: DVec3,
    sums: Sums,
    aabb: Aabb,
}

impl Totals {
    /// The totals over no members.
    const ZERO: Self = Self {
        intensity: DVec3::ZERO,
        sums: Sums::ZERO,
        aabb: Aabb::EMPTY,
    };
}

/// A subtree whose statistics are done: its root, the root's sums and its
/// moments about its centroid.
struct Done {
    root: u32,
    sums: Sums,
    moments: Moments,
}

/// One level's run of a subtree's nodes: the index of its first node, the
/// nodes and their notes.
struct Run<'a> {
    start: usize,
    nodes: &'a mut [Node],
    notes: &'a mut [Notes],
}

/// Where one level's run of a subtree lies in the node array (`start..end`)
/// and which of the subtrees it belongs to; ordered as the array.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Span {
    start: usize,
    end: usize,
    subtree: usize,
}

/// Mutable access to one subtree's nodes, level by level. In breadth-first
/// order a node's descendants at each depth are one contiguous run, so
/// disjoint subtrees own disjoint runs.
struct Levels<'a> {
    /// Per level below the subtree's root (the root's first), its run.
    runs: Vec<Run<'a>>,
    /// Subtrees below this one whose statistics are done, by root (the
    /// pass stops there); empty but for the nodes above a pool's subtrees.
    done: &'a [Done],
}

impl<'a> Levels<'a> {
    /// The subtrees of `roots` (disjoint: none holds another), each as its
    /// runs of `nodes`.
    fn split(nodes: &'a mut [Node], notes: &'a mut [Notes], roots: &[u32]) -> Vec<Self> {
        // Every subtree's runs, with the subtree they belong to: a run
        // below the last is from the first child of its first inner node
        // to the last child of its last.
        let mut spans = Vec::new();
        for (subtree, &root) in roots.iter().enumerate() {
            let mut run = root as usize..root as usize + 1;
            loop {
                spans.push(Span {
                    start: run.start,
                    end: run.end,
                    subtree,
                });
                let level = &nodes[run.clone()];
                let Some(first) = level.iter().find(|n| !n.is_leaf()) else {
                    break;
                };
                let last = level.iter().rev().find(|n| !n.is_leaf()).unwrap_or(first);
                run = first.children().start..last.children().end;
            }
        }
        spans.sort_unstable();
        let mut out: Vec<Self> = roots
            .iter()
            .map(|_| Self {
                runs: Vec::new(),
                done: &[],
            })
            .collect();
        // Runs in the order of the array: each subtree's come shallowest
        // first.
        let (mut rest, mut rest_notes, mut offset) = (nodes, notes, 0);
        for Span {
            start,
            end,
            subtree,
        } in spans
        {
            let (_, tail) = rest.split_at_mut(start - offset);
            let (run, tail) = tail.split_at_mut(end - start);
            let (_, tail_notes) = rest_notes.split_at_mut(start - offset);
            let (run_notes, tail_notes) = tail_notes.split_at_mut(end - start);
            out[subtree].runs.push(Run {
                start,
                nodes: run,
                notes: run_notes,
            });
            (rest, rest_notes, offset) = (tail, tail_notes, end);
        }
        out
    }

    /// Index of the subtree's root.
    fn root(&self) -> usize {
        self.runs[0].start
    }

    /// Node `index`, at `depth` levels below the subtree's root.
    #[inline(always)]
    fn node(&self, depth: usize, index: usize) -> &Node {
        let run = &self.runs[depth];
        &run.nodes[index - run.start]
    }

    /// See [`node`](Self::node).
    #[inline(always)]
    fn node_mut(&mut self, depth: usize, index: usize) -> &mut Node {
        let run = &mut self.runs[depth];
        &mut run.nodes[index - run.start]
    }

    /// The notes of node `index` (see [`node`](Self::node)).
    #[inline(always)]
    fn notes(&self, depth: usize, index: usize) -> &Notes {
        let run = &self.runs[depth];
        &run.notes[index - run.start]
    }

    /// See [`notes`](Self::notes).
    #[inline(always)]
    fn notes_mut(&mut self, depth: usize, index: usize) -> &mut Notes {
        let run = &mut self.runs[depth];
        &mut run.notes[index - run.start]
    }

    /// The statistics of the subtree of `index` if they are done.
    #[inline(always)]
    fn done(&self, index: usize) -> Option<&Done> {
        if self.done.is_empty() {
            return None;
        }
        let k = self
            .done
            .binary_search_by_key(&(index as u32), |d| d.root)
            .ok()?;
        Some(&self.done[k])
    }
}

/// What one thread's pass over subtrees reuses: the moments of the root,
/// the buffers of the children's moments (one per level of a path) and the
/// leaves' scratch.
struct StatisticsScratch {
    root: Moments,
    children: Vec<[Moments; MAX_CHILDREN]>,
    leaf: LeafScratch,
}

impl StatisticsScratch {
    /// Empty buffers, grown to the depth of the first subtree filled.
    fn new() -> Self {
        Self {
            root: Moments::ZERO,
            children: Vec::new(),
            leaf: LeafScratch::new(),
        }
    }
}

/// Fills the statistics of the subtree of `levels` (see
/// [`fill_statistics`]); returns its root's sums and moments.
fn fill_subtree<'s>(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    scratch: &'s mut StatisticsScratch,
) -> (Sums, &'s Moments) {
    let depth = levels.runs.len();
    if scratch.children.len() < depth {
        scratch
            .children
            .resize(depth, [Moments::ZERO; MAX_CHILDREN]);
    }
    let root = levels.root();
    let StatisticsScratch {
        root: out,
        children,
        leaf,
    } = scratch;
    // The pass recurses, so each copy is a function of its own that calls
    // itself (a closure, as `dispatch::with_avx2` takes, cannot).
    let sums = crate::dispatch::copy_or!(
        avx2_fma,
        fill_node_avx2,
        fill_node_baseline,
        levels,
        lights,
        0,
        root,
        out,
        children,
        leaf
    );
    (sums, out)
}

/// Statistics of node `index` (`depth` levels below the subtree's root)
/// and its descendants, children before parents; the node's moments about
/// its centroid into `out`, its children's into `below[0]` (their
/// children's one level down), and its sums returned. `$recurse` is the
/// function itself (one per compiled copy); the steps it takes are
/// `#[inline(always)]` functions, compiled into each copy.
macro_rules! fill_node_body {
    ($recurse:ident, $levels:ident, $lights:ident, $depth:ident, $index:ident, $out:ident, $below:ident, $scratch:ident) => {{
        if let Some(done) = $levels.done($index) {
            *$out = done.moments;
            return done.sums;
        }
        let node = $levels.node($depth, $index);
        let (members, children, count) = (node.lights(), node.children(), node.light_count);
        if children.is_empty() {
            let totals = leaf_totals($levels, $lights, $depth, $index, members.clone());
            let c = place($levels, $depth, $index, &totals, count);
            // The largest squared distance from the centroid to a member,
            // from the offsets the leaf's moments take.
            let radius_sq = $out.set_to_lights(&$lights[members], c, $scratch);
            finish(
                $levels,
                $depth,
                $index,
                radius_sq,
                $out,
                totals.intensity,
                count,
            );
            return totals.sums;
        }
        let (kids, below) = $below
            .split_first_mut()
            .expect("one buffer per level of the tree");
        let mut sums = [Sums::ZERO; MAX_CHILDREN];
        for ((k, kid), sum) in children.clone().zip(kids.iter_mut()).zip(&mut sums) {
            *sum = $recurse($levels, $lights, $depth + 1, k, kid, below, $scratch);
        }
        let totals = inner_totals($levels, $depth, $index, &sums);
        let c = place($levels, $depth, $index, &totals, count);
        shift_children($levels, $depth, children, kids, c, $out);
        // The largest squared distance from the centroid to a member,
        // found through the subtree.
        let radius_sq = farthest_member($levels, $lights, $depth, $index);
        finish(
            $levels,
            $depth,
            $index,
            radius_sq,
            $out,
            totals.intensity,
            count,
        );
        totals.sums
    }};
}

/// Lights past a leaf's whose loading [`leaf_totals`] starts as it reaches
/// the leaf (a leaf or two, in the build's default leaves).
const LIGHTS_AHEAD: usize = 32;

/// The totals of leaf `index` (`depth` levels below the subtree's root),
/// whose lights are `members`, summed light by light; its notes set from
/// its lights while they are in the cache.
#[inline(always)]
fn leaf_totals(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    depth: usize,
    index: usize,
    members: Range<usize>,
) -> Totals {
    // The lights of the leaves that follow, read next in this order, start
    // loading while this one is summed.
    let ahead = members.end..(members.end + LIGHTS_AHEAD).min(lights.len());
    prefetch(as_bytes_range(&lights[ahead]));
    let leaf = &lights[members];
    *levels.notes_mut(depth, index) = Notes {
        ratios: leaf_ratios(leaf),
        off_plane: leaf.len() >= 4
            && certainly_not_coplanar(
                leaf[0].position,
                leaf[1].position,
                leaf[2].position,
                leaf[leaf.len() - 1].position,
            ),
    };
    let mut totals = Totals::ZERO;
    for l in leaf {
        let w = f64::from(l.weight());
        let x = l.position.as_dvec3();
        totals.intensity += l.intensity.as_dvec3();
        totals.sums.weight += w;
        totals.sums.weighted += w * x;
        totals.sums.plain += x;
        totals.aabb = totals.aabb.union_point(l.position);
    }
    totals
}

/// The totals of node `index`, which has children, from its children's
/// nodes and their `sums` (one per child, in order); whether it holds four
/// lights off one plane noted from its children's notes.
#[inline(always)]
fn inner_totals(
    levels: &mut Levels<'_>,
    depth: usize,
    index: usize,
    sums: &[Sums; MAX_CHILDREN],
) -> Totals {
    let children = levels.node(depth, index).children();
    let off_plane = children
        .clone()
        .any(|k| levels.notes(depth + 1, k).off_plane);
    levels.notes_mut(depth, index).off_plane = off_plane;
    let mut totals = Totals::ZERO;
    for (k, sum) in children.zip(sums) {
        let child = levels.node(depth + 1, k);
        totals.intensity += child.intensity;
        totals.sums.weight += sum.weight;
        totals.sums.weighted += sum.weighted;
        totals.sums.plain += sum.plain;
        totals.aabb = totals.aabb.union(child.aabb);
    }
    totals
}

/// Stores the `totals` of node `index` (of `count` lights) and its
/// centroid; returns the centroid as stored, in `f64`.
#[inline(always)]
fn place(
    levels: &mut Levels<'_>,
    depth: usize,
    index: usize,
    totals: &Totals,
    count: u32,
) -> DVec3 {
    let Sums {
        weight,
        weighted,
        plain,
    } = totals.sums;
    // Zero total weight: every member is dark; use the plain mean so the
    // node still has a sensible position (its contribution is zero either
    // way).
    let centroid = if weight > 0.0 {
        weighted / weight
    } else {
        plain / f64::from(count)
    };
    let node = levels.node_mut(depth, index);
    node.intensity = totals.intensity;
    node.weight = (weight as f32).min(f32::MAX);
    // The average lies in the box in exact arithmetic; clamp away
    // rounding.
    node.centroid = centroid.as_vec3().clamp(totals.aabb.min, totals.aabb.max);
    node.aabb = totals.aabb;
    node.centroid.as_dvec3()
}

/// Shifts the moments of the children of a node with centroid `c` (node
/// `first_child + j` has its moments in `kids[j]`, `depth + 1` levels
/// below the subtree's root) to `c`, summed into `out`. The first child's
/// shifted moments are written, the others' added: no clearing of `out`
/// (the same bits, see [`Moments::shift_to`]).
#[inline(always)]
fn shift_children(
    levels: &Levels<'_>,
    depth: usize,
    children: Range<usize>,
    kids: &mut [Moments; MAX_CHILDREN],
    c: DVec3,
    out: &mut Moments,
) {
    for (j, (k, kid)) in children.zip(kids.iter_mut()).enumerate() {
        let t = levels.node(depth + 1, k).centroid.as_dvec3() - c;
        if j == 0 {
            kid.shift_to(t, out);
        } else {
            kid.shift_into(t, out);
        }
    }
}

/// Stores the radius of node `index` (from the largest squared distance
/// `radius_sq` from its centroid to a member, rounded up) and the
/// statistics its moments `out` give, for `count` lights of summed
/// `intensity`.
#[inline(always)]
fn finish(
    levels: &mut Levels<'_>,
    depth: usize,
    index: usize,
    radius_sq: f64,
    out: &Moments,
    intensity: DVec3,
    count: u32,
) {
    let node = levels.node_mut(depth, index);
    node.radius = round_up_f32(radius_sq.sqrt() * (1.0 + BUILD_LENGTH_SLACK));
    let radius = node.radius;
    let stats = out.statistics(intensity, radius, count as usize);
    store(levels.node_mut(depth, index), stats);
}

/// See [`fill_node_body`]: the baseline copy.
fn fill_node_baseline(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    depth: usize,
    index: usize,
    out: &mut Moments,
    below: &mut [[Moments; MAX_CHILDREN]],
    scratch: &mut LeafScratch,
) -> Sums {
    fill_node_body!(
        fill_node_baseline,
        levels,
        lights,
        depth,
        index,
        out,
        below,
        scratch
    )
}

/// [`fill_node_baseline`] compiled for AVX2 and FMA (the same bits, see
/// [`dispatch`](crate::dispatch)).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fill_node_avx2(
    levels: &mut Levels<'_>,
    lights: &[PointLight],
    depth: usize,
    index: usize,
    out: &mut Moments,
    below: &mut [[Moments; MAX_CHILDREN]],
    scratch: &mut LeafScratch,
) -> Sums {
    fill_node_body!(
        fill_node_avx2,
        levels,
        lights,
        depth,
        index,
        out,
        below,
        scratch
    )
}

/// The largest squared distance, as computed in `f64`, from the centroid
/// of node `index` (`depth` levels below the subtree's root), which has
/// children, to a member light: the same value as over all its lights, but
/// subtrees that cannot hold a farther member are skipped. Its
/// descendants' statistics are set. (A leaf's comes with its moments, see
/// [`Moments::set_to_lights`]: the same value as over its lights here.)
///
/// A member `x` of a subtree with centroid `c'`, stored radius `r'` (at
/// least its members' exact distances) and box `B` lies within `|c' - c| +
/// r'` of `c`, and no farther than `B`'s farthest corner; both computed in
/// `f64` are within a few `2^-53` of their exact values, and so is the
/// computed squared distance of `x` of the exact one. So a subtree whose
/// `min((|c' - c| (1 + 2^-40) + r')^2, corner^2) (1 + 2^-40)` is below the
/// largest computed value so far holds no larger one. Subtrees are taken
/// farthest bound first, depth first.
#[inline(always)]
fn farthest_member(levels: &Levels<'_>, lights: &[PointLight], depth: usize, index: usize) -> f64 {
    const MARGIN: f64 = 1.0 + 1.0 / 1_099_511_627_776.0; // 1 + 2^-40
    let node = levels.node(depth, index);
    let c = node.centroid.as_dvec3();
    // The largest of 0 and the members' squared distances, four running
    // maxima side by side (a maximum is exact, so in any order the same
    // value; no distance is NaN or -0, so a comparison serves).
    let squared = |members: &[PointLight]| {
        let distance = |l: &PointLight| (l.position.as_dvec3() - c).length_squared();
        let larger = |a: f64, b: f64| if b > a { b } else { a };
        let mut best = [0.0f64; 4];
        let fours = members.chunks_exact(4);
        let rest = fours.remainder();
        for four in fours {
            for (best, l) in best.iter_mut().zip(four) {
                *best = larger(*best, distance(l));
            }
        }
        for (best, l) in best.iter_mut().zip(rest) {
            *best = larger(*best, distance(l));
        }
        larger(larger(best[0], best[1]), larger(best[2], best[3]))
    };
    debug_assert!(!node.is_leaf(), "a leaf's radius comes with its moments");
    let mut best = 0.0f64;
    // Subtrees still to search.
    type Stack = smallvec::SmallVec<[Pending; 64]>;
    let push_children = |stack: &mut Stack, n: &Node, depth: usize| {
        let start = stack.len();
        for k in n.children() {
            let child = levels.node(depth + 1, k);
            let reach = (child.centroid.as_dvec3() - c).length() * MARGIN + f64::from(child.radius);
            let (lo, hi) = (child.aabb.min.as_dvec3() - c, child.aabb.max.as_dvec3() - c);
            let corner = (lo * lo).max(hi * hi).element_sum();
            stack.push(Pending {
                index: k as u32,
                depth: (depth + 1) as u32,
                bound: (reach * reach).min(corner) * MARGIN,
            });
        }
        // The farthest bound on top.
        stack[start..].sort_unstable_by(|a, b| a.bound.total_cmp(&b.bound));
    };
    let mut stack = Stack::new();
    push_children(&mut stack, node, depth);
    while let Some(Pending {
        index,
        depth,
        bound,
    }) = stack.pop()
    {
        if bound < best {
            continue;
        }
        let n = levels.node(depth as usize, index as usize);
        if n.is_leaf() {
            best = best.max(squared(&lights[n.lights()]));
        } else {
            push_children(&mut stack, n, depth as usize);
        }
    }
    best
}

/// A subtree [`farthest_member`] has still to search: its root `index`,
/// `depth` levels below the subtree's root of the pass, and an upper
/// `bound` on its members' squared distances.
#[derive(Clone, Copy, Debug)]
struct Pending {
    index: u32,
    depth: u32,
    bound: f64,
}

/// Roots of about `parts` disjoint subtrees that hold every leaf: from the
/// root, the subtree of most lights is replaced by its children's while
/// there are fewer than `parts` and it has children.
fn subtrees(nodes: &[Node], parts: usize) -> Vec<u32> {
    let mut roots = vec![0u32];
    while roots.len() < parts {
        let Some((k, &largest)) = roots
            .iter()
            .enumerate()
            .max_by_key(|(_, r)| nodes[**r as usize].light_count)
        else {
            break;
        };
        let node = &nodes[largest as usize];
        if node.is_leaf() {
            break;
        }
        roots.swap_remove(k);
        roots.extend(node.children().map(|c| c as u32));
    }
    roots
}

/// `stats` into `node`.
#[inline(always)]
fn store(node: &mut Node, stats: Statistics) {
    node.channel_offsets = stats.offsets;
    node.channel_covariances = stats.covariances;
    node.harmonic_norms = stats.harmonic_norms;
    node.moment_error = stats.moment_error;
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use crate::dispatch::baseline;
    use crate::{LightTree, PointLight};

    /// The build's copy compiled for AVX2 and FMA (where the processor has
    /// them) and the baseline give the same nodes, also after a refit.
    #[test]
    fn both_copies_of_the_build_give_the_same_nodes() {
        let mut state = 3u64;
        let mut uniform = move || crate::testing::uniform(&mut state);
        let lights: Vec<PointLight> = (0..5000)
            .map(|_| {
                let p = Vec3::new(uniform() * 100.0, uniform() * 100.0, uniform() * 3.0);
                PointLight::new(p, Vec3::new(uniform(), uniform() * 5.0, uniform() * 0.01))
            })
            .collect();
        let a = LightTree::build(&lights).unwrap();
        let b = baseline(|| LightTree::build(&lights).unwrap());
        assert_eq!(a.nodes(), b.nodes());
        let moved: Vec<PointLight> = lights
            .iter()
            .map(|l| PointLight::new(l.position * 1.5 + Vec3::ONE, l.intensity))
            .collect();
        let (mut a, mut b) = (a, b);
        a.refit(&moved).unwrap();
        baseline(|| b.refit(&moved).unwrap());
        assert_eq!(a.nodes(), b.nodes());
    }
}
