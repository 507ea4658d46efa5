//! [`Shadows`]: one thread's host over shared [`Occluders`].

use glam::{DVec3, Vec3};
use manylights::{Aabb, Coverage, NodeRegion, PointGroup, Visibility};
use obvhs::aabb::Aabb as BvhAabb;

use crate::bvh::{Segment, distinct_corners};
use crate::lists::{Lists, SMALL_NODE_LIGHTS};
use crate::occluders::{BLOCKER_REACH, MARGIN_ULPS, NO_PARTNER, Occluders, Prim};
use crate::shaft::{Fan, Shaft};
use crate::triangle::{blocks, clears};

/// Occluders tried as the single blocker of a node: the first few boxes,
/// and the first few triangles (a quad counted once), that the shadow ray
/// between the centres of the apex's box and the node's box hits (one that
/// does not cannot block every segment), in the order of the BVH's
/// traversal or of the candidate list the node lies in (boxes first). The
/// triangles are tried only when the ray hits no box: where it crosses a
/// solid ([`OccludersBuilder::solid`](crate::OccludersBuilder::solid)) the
/// box inside it blocks whatever the solid's walls block, less a sliver
/// at the walls (in a city of solids, under 2% of the tries of a triangle
/// after a box succeeded, at a tenth of the host's work). A blocker of a
/// whole node is nearly always among them, and a long segment through
/// foliage meets many occluders that cannot be one.
pub const BLOCKER_CANDIDATES: usize = 4;

/// Occluders a batch of shadow rays from one point
/// ([`visible_lights`](Visibility::visible_lights)) gathers at most: past
/// this many in the shaft from the point to the lights' box, the rays
/// traverse the BVH one by one instead. A leaf's lights lie close
/// together, so their shaft is narrow and usually meets a few occluders,
/// which each ray then tests directly (a slab test and, for a triangle,
/// the segment test) instead of descending the BVH again; a wide shaft
/// through many occluders would make every ray test all of them.
pub const BATCH_CANDIDATES_MAX: usize = 64;

/// The visibility host of one thread over shared [`Occluders`]: a
/// conservative shaft classifier and any-hit shadow rays, with counters of
/// the work asked of it. Make one per thread (or per batch call) with
/// [`Occluders::host`]; it serves any shading point, with any normal.
///
/// # Shadow rays
///
/// [`visible`](Visibility::visible) is an any-hit query of the segment from
/// the shading point to the light through the BVH, which ignores what it
/// meets closer than the *offset* ([`Occluders::offset`]) to the shading
/// point, measured along the segment: the surface the point lies on, and
/// any other within the offset, as a renderer's `t_min` does. Triangles are
/// tested with the watertight `f64` test of the crate's triangle
/// predicates (see "Rounding" in the [crate documentation](crate)), boxes
/// (solid) with an `f32` slab test. This test *is* the visibility `V_i` of
/// the model: [`Shading::exact_query`](manylights::Shading::exact_query)
/// with this host sums it, and every classification is conservative with
/// respect to it.
///
/// # Classification
///
/// [`classify`](Visibility::classify) asks about every segment from the
/// shading point to the node's box; [`classify_group`](Visibility::classify_group)
/// about every segment from a point of the group's box to a point of the
/// node's box. Both go the same way, after Haines and Wallace 1994:
///
/// * [`Coverage::Occluded`] when one occluder blocks every such segment:
///   a box that, shrunk by the margin, meets the segments between the
///   corners of the two boxes (the points from which every segment to a
///   box meets a convex occluder form a convex set, and so do the targets
///   seen through it from one point, so the corners decide), at least twice
///   the offset plus the margin away from the apex's box; or a triangle,
///   or a quad of two, whose predicates clear their slack at every pair of
///   corners (see `triangle`'s rounding note in the crate documentation),
///   crossed at least the offset from the apex. Only the first
///   [`BLOCKER_CANDIDATES`] boxes and triangles that the shadow ray between
///   the two boxes' centres hits are tried, triangles only if it hits no
///   box.
/// * [`Coverage::Partial`] when a shadow ray between the two centres is
///   blocked.
/// * [`Coverage::Visible`] when no occluder's box (a triangle's grown by
///   [`RAY_BOX_ULPS`](crate::RAY_BOX_ULPS)) meets the shaft of the two
///   boxes grown by the margin, every segment's slab tests then missing
///   every occluder; or when each triangle whose box meets it is one that
///   every segment leaves behind within the offset (the surface the
///   shading point, or the group, lies on: the segments start on its plane
///   and the node lies clear of that plane on one side), so that no
///   segment's test can hit it past the offset. [`Coverage::Partial`]
///   otherwise.
///
/// The margin is [`MARGIN_ULPS`]` f32::EPSILON` times the largest
/// coordinate involved. A triangle is tried as a blocker only while the
/// apex and the node lie within [`BLOCKER_REACH`]
/// times the occluders' largest coordinate ([`Occluders::scale`]), where
/// the growth of its box covers the slab test's rounding.
///
/// # Batches of shadow rays
///
/// [`visible_lights`](Visibility::visible_lights) (the lights of a leaf
/// from one point) first gathers, into the host's own scratch list, the
/// occluders whose boxes meet the shaft from the point to the lights' box
/// grown by the margin: as for a [`Coverage::Visible`] answer, no other
/// occluder's slab test can meet any of the segments. Each segment then
/// runs the shadow ray's own tests against the gathered occluders only, so
/// every answer is the one [`visible`](Visibility::visible) gives. Past
/// [`BATCH_CANDIDATES_MAX`] occluders the rays are cast one by one.
///
/// # Candidate lists
///
/// The cut asks about a node only after its parent answered
/// [`Coverage::Partial`], and casts the rays to a leaf's lights right
/// after the leaf did. So for the current apex (a shading point, or a
/// group's box) the host keeps the occluders gathered for each partial
/// node's shaft, its *candidate list* (Haines and Wallace's term): every
/// occluder whose box meets the shaft grown by the margin (of a solid's
/// part that meets the apex's box, each member that does), less the
/// triangles that every segment leaves behind within the offset, up to
/// [`CANDIDATES_MAX`](crate::CANDIDATES_MAX) of them. If a node's box lies
/// inside a listed box, every segment from the apex to it is a segment to
/// the listed box, so no occluder off the list can meet one in its tests.
/// Hence:
///
/// * a node inside a listed box is classified from the smallest such list
///   (found down the tree the lists form by containment) rather than the
///   BVH: the single blocker is looked for along the list, and the node's
///   own list is the parent's filtered by its shaft;
/// * the lights of a leaf inside a listed box of at most
///   [`BATCH_CANDIDATES_MAX`] occluders are tested against that list, each
///   ray with its own tests, so every answer is the one
///   [`visible`](Visibility::visible) gives; the occluder that blocks a ray
///   moves to the front of the list, where the next light's ray tries it
///   first (neighbouring lights hide behind the same building).
///
/// The lists are dropped when the apex changes, except a group's while the
/// apex is a point inside the group's box: every segment from the point
/// is one from the group's box, so the group's lists serve the point too
/// (the batch call asks about a group's nodes, then about the nodes below
/// those for each of its points). Where the shafts of small nodes keep
/// meeting more occluders than a batch of rays tests (foliage:
/// [`GIVE_UP_CROWDED`](crate::GIVE_UP_CROWDED)), the host stops gathering
/// lists for the apex and classifies from the BVH, as without lists.
#[derive(Clone, Debug)]
pub struct Shadows<'o> {
    occluders: &'o Occluders,
    /// Classifications answered: visible, occluded, partial.
    pub answers: [u64; 3],
    /// Shadow rays cast (one per light asked about, batched or not).
    pub rays: u64,
    /// Of [`rays`](Self::rays), those answered in batches against gathered
    /// occluders (see "Batches of shadow rays").
    pub batched: u64,
    /// Classifications answered from a candidate list rather than the BVH
    /// (see "Candidate lists").
    pub listed: u64,
    /// The occluders' slots a batch of shadow rays tests: scratch space,
    /// kept between calls so that a warmed host allocates nothing.
    candidates: Vec<u32>,
    /// The candidate lists of the current apex.
    lists: Lists,
}

impl<'o> Shadows<'o> {
    /// A host over `occluders` (see [`Occluders::host`]).
    pub fn new(occluders: &'o Occluders) -> Self {
        Self {
            occluders,
            answers: [0; 3],
            rays: 0,
            batched: 0,
            listed: 0,
            candidates: Vec::new(),
            lists: Lists::default(),
        }
    }

    /// The occluders this host tests.
    pub fn occluders(&self) -> &'o Occluders {
        self.occluders
    }

    /// Classifications answered.
    pub fn classifications(&self) -> u64 {
        self.answers.iter().sum()
    }

    /// Classifies every segment from a point of `from` (a point, as a box of
    /// one point, or a group of points) to a point of `target`: see the
    /// type's documentation, "Classification".
    pub fn classify_boxes(&mut self, from: &Aabb, target: &Aabb) -> Coverage {
        self.classify_counted(from, target, true)
    }

    /// [`classify_boxes`](Self::classify_boxes), `small` saying whether
    /// `target` is a small node's box (see
    /// [`GIVE_UP_CROWDED`](crate::GIVE_UP_CROWDED)).
    fn classify_counted(&mut self, from: &Aabb, target: &Aabb, small: bool) -> Coverage {
        let coverage = self.classification(from, target, small);
        self.answers[coverage as usize] += 1;
        coverage
    }

    /// The classifier's margin for segments between `from` and `target`
    /// ([`MARGIN_ULPS`]` f32::EPSILON` of the largest coordinate involved,
    /// the occluders' included) and that coordinate; `None` when one is not
    /// finite.
    fn margin(&self, from: &Aabb, target: &Aabb) -> Option<(f32, f32)> {
        let magnitude = [from.min, from.max, target.min, target.max]
            .iter()
            .fold(self.occluders.scale, |m, p| m.max(p.abs().max_element()));
        magnitude
            .is_finite()
            .then_some((MARGIN_ULPS * f32::EPSILON * magnitude, magnitude))
    }

    /// Gathers into `self.candidates` the slots of the occluders whose boxes
    /// meet the shaft from `point` to `target` grown by the margin (every
    /// occluder a segment's slab test may meet); `false` if there are more
    /// than [`BATCH_CANDIDATES_MAX`] of them, or a coordinate is not finite.
    fn gather(&mut self, point: Vec3, target: &Aabb) -> bool {
        let occ = self.occluders;
        self.candidates.clear();
        let from = Aabb {
            min: point,
            max: point,
        };
        let Some((margin, _)) = self.margin(&from, target) else {
            return false;
        };
        let shaft = Shaft::new(point, target, margin);
        let candidates = &mut self.candidates;
        let crowded = occ.bvh.any_in(
            |b| shaft.meets(b),
            |slot| {
                let b = &occ.bounds[slot];
                if shaft.meets(b) {
                    match occ.prims[slot] {
                        // The part the point lies in (its own building):
                        // every ray starts inside its bounds, so its members
                        // that meet the shaft are tested instead.
                        Prim::Part { first, end } if b.contains_point(point.into()) => {
                            candidates.extend(
                                (first..end).filter(|&m| shaft.meets(&occ.bounds[m as usize])),
                            );
                        }
                        _ => candidates.push(slot as u32),
                    }
                }
                candidates.len() > BATCH_CANDIDATES_MAX
            },
        );
        // Boxes first, then the parts of solids (whose rays try the boxes
        // inside them first): a ray through a solid meets a box inside it,
        // which answers with one slab test.
        let occ = self.occluders;
        self.candidates
            .sort_unstable_by_key(|&slot| match occ.prims[slot as usize] {
                Prim::Box => 0,
                Prim::Part { .. } => 1,
                Prim::Triangle { .. } => 2,
            });
        !crowded
    }

    fn classification(&mut self, from: &Aabb, target: &Aabb, small: bool) -> Coverage {
        let occ = self.occluders;
        if occ.is_empty() {
            return Coverage::Visible;
        }
        let Some((margin, magnitude)) = self.margin(from, target) else {
            return Coverage::Partial;
        };
        self.lists.aim(from);
        let gathering = self.lists.gathering();
        let parent = if gathering {
            self.lists.find(from, target)
        } else {
            None
        };
        self.listed += u64::from(parent.is_some());
        let (centre, middle) = (centre(from), centre(target));
        let listed = parent.map(|list| &self.lists.slots[self.lists.range(list)]);
        let (occluded, centre_blocked) =
            self.single_blocker(from, target, (centre, middle), margin, magnitude, listed);
        if occluded {
            return Coverage::Occluded;
        }
        let shaft = if from.min == from.max {
            Shaft::new(from.min, target, margin)
        } else {
            Shaft::between(from, target, margin)
        };
        // Triangles that every segment leaves behind within the offset (the
        // surface the apex lies on) cannot block one.
        let t_min_bound = (f64::from(occ.offset) / box_reach(from, target)).min(1.0);
        let m = 2.0 * f64::from(magnitude);
        let member = |slot: usize| {
            shaft.meets(&occ.bounds[slot])
                && match &occ.prims[slot] {
                    Prim::Triangle { v, .. } => !clears(v, from, target, t_min_bound, m),
                    _ => true,
                }
        };
        let blocks_some = |slot: usize| match occ.prims[slot] {
            Prim::Part { first, end } => {
                shaft.meets(&occ.bounds[slot]) && (first as usize..end as usize).any(member)
            }
            _ => member(slot),
        };
        if gathering
            && let Some(gathered) = self.lists.gather(occ, parent, from, &shaft, small, |v| {
                !clears(v, from, target, t_min_bound, m)
            })
        {
            // Every occluder a segment's test may meet is gathered (see
            // "Candidate lists"): the node is visible unless one of them
            // may block a segment, and the list is kept for the node's
            // children and its lights' shadow rays if it is partial.
            // (Each gathered occluder meets the shaft.)
            let may_block = |slot: usize| match occ.prims[slot] {
                Prim::Part { first, end } => (first as usize..end as usize).any(member),
                Prim::Triangle { ref v, .. } => !clears(v, from, target, t_min_bound, m),
                Prim::Box => true,
            };
            let slots = &self.lists.slots;
            if centre_blocked || gathered.clone().any(|at| may_block(slots[at] as usize)) {
                self.lists.keep(parent, target, gathered);
                return Coverage::Partial;
            }
            self.lists.drop_from(gathered.start);
            return Coverage::Visible;
        }
        if centre_blocked || occ.bvh.any_in(|b| shaft.meets(b), blocks_some) {
            Coverage::Partial
        } else {
            Coverage::Visible
        }
    }

    /// Whether one of the first [`BLOCKER_CANDIDATES`] triangles or boxes along the
    /// segment from `centre` to `middle` blocks every segment from `from`
    /// to `target`, and whether the shadow ray from `centre` to `middle` is
    /// blocked.
    fn single_blocker(
        &self,
        from: &Aabb,
        target: &Aabb,
        (centre, middle): (Vec3, Vec3),
        margin: f32,
        magnitude: f32,
        listed: Option<&[u32]>,
    ) -> (bool, bool) {
        let occ = self.occluders;
        let between = Segment::new(centre, middle);
        let length = (middle.as_dvec3() - centre.as_dvec3()).length();
        let t_min = if length > 0.0 {
            f64::from(occ.offset) / length
        } else {
            f64::INFINITY
        };
        let gap = box_distance(from, target);
        // Triangles block only within the occluders' range (see the type's
        // documentation); and never a node the apex's box touches.
        let within = magnitude <= BLOCKER_REACH * occ.scale;
        let m = 2.0 * f64::from(magnitude);
        let (mut tried, mut boxes_tried, mut occluded, mut centre_blocked) = (0, 0, false, false);
        // Triangles (or quads) to try once the traversal is over: a box is
        // tried at once (its test is cheap, and in a solid it is the
        // likely blocker), a triangle's test only if no box blocks.
        let mut triangles = [0u32; BLOCKER_CANDIDATES];
        // The segments from a point apex to the target's corners, set up
        // once for the boxes tried.
        let mut fan = None;
        let mut visit = |slot: usize| {
            // Triangles are tried only while no box is hit (below).
            if boxes_tried > 0 && matches!(occ.prims[slot], Prim::Triangle { .. }) {
                return false;
            }
            // An occluder that blocks every segment blocks the one between
            // the centres: only those are tried, and a quad once.
            if !occ.hits_one(slot, &between, centre, middle, t_min) {
                return false;
            }
            centre_blocked = true;
            match occ.prims[slot] {
                Prim::Triangle { partner, .. } => {
                    if partner != NO_PARTNER && triangles[..tried].contains(&partner) {
                        return false;
                    }
                    if tried < BLOCKER_CANDIDATES {
                        triangles[tried] = slot as u32;
                        tried += 1;
                    }
                }
                _ => {
                    boxes_tried += 1;
                    occluded = box_blocks(
                        &occ.bounds[slot],
                        (from, target),
                        margin,
                        occ.offset,
                        &mut fan,
                    );
                }
            }
            occluded
                || (tried == BLOCKER_CANDIDATES
                    && (boxes_tried >= BLOCKER_CANDIDATES || occ.boxes() == 0))
        };
        let mut along = |slot: usize| match occ.prims[slot] {
            // A part's members, its boxes first.
            Prim::Part { first, end } => {
                between.hits(&occ.bounds[slot]) && (first as usize..end as usize).any(&mut visit)
            }
            _ => visit(slot),
        };
        match listed {
            // Every occluder the segment may meet is on the list.
            Some(slots) => {
                slots.iter().any(|&slot| along(slot as usize));
            }
            None => {
                occ.bvh.any_along(&between, along);
            }
        }
        if occluded || boxes_tried > 0 || !(within && gap > 0.0) {
            return (occluded, centre_blocked);
        }
        let t_min_bound = f64::from(occ.offset) / gap;
        occluded = triangles[..tried].iter().any(|&slot| {
            let Prim::Triangle { v, partner, shared } = occ.prims[slot as usize] else {
                unreachable!("only triangles are kept")
            };
            if partner == NO_PARTNER {
                blocks(&[v], &[[true; 3]], from, target, t_min_bound, m)
            } else {
                let Prim::Triangle {
                    v: w,
                    shared: other,
                    ..
                } = occ.prims[partner as usize]
                else {
                    unreachable!("a partner is a triangle")
                };
                blocks(
                    &[v, w],
                    &[shared.map(|s| !s), other.map(|s| !s)],
                    from,
                    target,
                    t_min_bound,
                    m,
                )
            }
        });
        (occluded, centre_blocked)
    }
}

/// Whether the box occluder `b`, shrunk by `margin`, meets every segment
/// between the corners of `from` and of `target`, and lies at least twice
/// `offset` plus `margin` away from `from` (so that every segment meets it
/// past the offset).
fn box_blocks(
    b: &BvhAabb,
    (from, target): (&Aabb, &Aabb),
    margin: f32,
    offset: f32,
    fan: &mut Option<Fan>,
) -> bool {
    let core = BvhAabb::new(b.min + margin, b.max - margin);
    if !core.valid() {
        return false;
    }
    let clear = 2.0 * offset + margin;
    let away = Aabb {
        min: from.min - clear,
        max: from.max + clear,
    };
    let touching = away.min.cmple(b.max.into()).all() && Vec3::from(b.min).cmple(away.max).all();
    if touching {
        return false;
    }
    if from.min == from.max {
        return fan
            .get_or_insert_with(|| Fan::new(from.min, target))
            .all_meet(&core);
    }
    let ends = distinct_corners(target);
    distinct_corners(from).all(|p| ends.clone().all(|q| Segment::new(p, q).hits(&core)))
}

/// The centre of a box.
fn centre(b: &Aabb) -> Vec3 {
    0.5 * (b.min + b.max)
}

/// An upper bound on the length of a segment between two boxes (the
/// distance between farthest corners), in `f64`, grown by a relative
/// `2^-40` for its rounding.
fn box_reach(a: &Aabb, b: &Aabb) -> f64 {
    let (lo, hi) = (a.min.min(b.min).as_dvec3(), a.max.max(b.max).as_dvec3());
    (hi - lo).length() * (1.0 + 1.0 / (1u64 << 40) as f64)
}

/// A lower bound on the distance between two boxes, in `f64` (0 when they
/// touch), shrunk by a relative `2^-40` for its rounding.
fn box_distance(a: &Aabb, b: &Aabb) -> f64 {
    let gap = (b.min.as_dvec3() - a.max.as_dvec3())
        .max(a.min.as_dvec3() - b.max.as_dvec3())
        .max(DVec3::ZERO);
    gap.length() * (1.0 - 1.0 / (1u64 << 40) as f64)
}

impl Visibility for Shadows<'_> {
    const CLASSIFIES_GROUPS: bool = true;

    /// [`Shadows::classify_boxes`] from the point.
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        let from = Aabb {
            min: point,
            max: point,
        };
        self.classify_counted(&from, &node.aabb, node.light_count <= SMALL_NODE_LIGHTS)
    }

    /// [`Shadows::classify_boxes`] from the group's box.
    fn classify_group(&mut self, group: &PointGroup, node: &NodeRegion) -> Coverage {
        self.classify_counted(
            &group.aabb,
            &node.aabb,
            node.light_count <= SMALL_NODE_LIGHTS,
        )
    }

    /// One any-hit shadow ray ([`Occluders::blocked`]).
    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        self.rays += 1;
        !self.occluders.blocked(point, light)
    }

    /// The shadow rays of [`visible`](Visibility::visible) against the
    /// occluders gathered once for all of them (see the type's
    /// documentation, "Batches of shadow rays"): the same answers.
    fn visible_lights(&mut self, point: Vec3, lights: &[Vec3], seen: &mut [bool]) {
        let occ = self.occluders;
        let target = lights.iter().fold(
            Aabb {
                min: Vec3::INFINITY,
                max: Vec3::NEG_INFINITY,
            },
            |b, &l| Aabb {
                min: b.min.min(l),
                max: b.max.max(l),
            },
        );
        let from = Aabb {
            min: point,
            max: point,
        };
        if let Some(list) = self.lists.find(&from, &target) {
            let range = self.lists.range(list);
            if range.len() <= BATCH_CANDIDATES_MAX {
                // The list of a box that holds every light (the leaf's
                // own, just kept) holds every occluder their rays may meet.
                self.rays += lights.len() as u64;
                self.batched += lights.len() as u64;
                let slots = &mut self.lists.slots[range];
                for (&light, seen) in lights.iter().zip(seen) {
                    *seen = match occ.blocker_in(slots, point, light) {
                        None => true,
                        Some(k) => {
                            // The next light's ray tries this occluder
                            // first: neighbouring lights hide behind the
                            // same building.
                            slots.swap(0, k);
                            false
                        }
                    };
                }
                return;
            }
        }
        if occ.is_empty() || lights.len() < 2 || !self.gather(point, &target) {
            for (&light, seen) in lights.iter().zip(seen) {
                *seen = self.visible(point, light);
            }
            return;
        }
        self.rays += lights.len() as u64;
        self.batched += lights.len() as u64;
        for (&light, seen) in lights.iter().zip(seen) {
            *seen = !occ.blocked_by(&self.candidates, point, light);
        }
    }
}
