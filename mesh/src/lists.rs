//! Candidate lists: the occluders gathered for the shafts a host answered
//! [`Coverage::Partial`](manylights::Coverage::Partial), which later shafts
//! and shadow rays inside them test instead of the BVH (see "Candidate
//! lists" in [`Shadows`](crate::Shadows)).

use std::ops::Range;

use glam::{Vec3, Vec3A};
use manylights::Aabb;

use crate::occluders::{Occluders, Prim};
use crate::shaft::Shaft;

/// Most occluders a candidate list holds; a shaft that meets more keeps no
/// list. The shafts of the top levels of a light tree span much of a
/// scene and meet most of its occluders; the levels below them then gather
/// from the BVH until a shaft meets few enough.
pub const CANDIDATES_MAX: usize = 128;

/// Shafts of small nodes (at most [`SMALL_NODE_LIGHTS`] lights) that met
/// more than [`BATCH_CANDIDATES_MAX`](crate::BATCH_CANDIDATES_MAX)
/// occluders before a host stops gathering lists for the current apex, as
/// long as more than half of the small nodes' shafts did: under many small
/// occluders (foliage) every small shaft is crowded, its list serves no
/// batch of shadow rays, and gathering it costs a traversal of the BVH.
pub const GIVE_UP_CROWDED: u32 = 16;

/// Nodes of at most this many lights count towards giving up (see
/// [`GIVE_UP_CROWDED`]): near the root of a light tree every shaft is
/// crowded.
pub const SMALL_NODE_LIGHTS: u32 = 64;

/// No list: the end of a chain of lists.
const NO_LIST: u32 = u32::MAX;

/// A candidate list: the slots of the occluders that meet the shaft from
/// the apex to `target`, `Lists::slots[start..start + len]`.
#[derive(Clone, Copy, Debug)]
struct List {
    target: Aabb,
    start: u32,
    len: u32,
    /// The list this one is under (`NO_LIST` for a root), the first list
    /// under this one (listed inside its box), and the next list under the
    /// same parent.
    parent: u32,
    child: u32,
    sibling: u32,
}

/// The candidate lists of one apex (a shading point, or the box of a group
/// of points), and how gathering has gone.
#[derive(Clone, Debug)]
pub(crate) struct Lists {
    /// The apex the lists belong to.
    from: Option<Aabb>,
    /// The lists' occluder slots, back to back; a list being gathered is
    /// at the end.
    pub slots: Vec<u32>,
    lists: Vec<List>,
    /// The first list under no other, and the last one kept.
    root: u32,
    last: u32,
    /// Small nodes' shafts gathered, and those that met more than
    /// [`BATCH_CANDIDATES_MAX`](crate::BATCH_CANDIDATES_MAX) occluders.
    small_shafts: u32,
    small_crowded: u32,
    /// The lists of a group whose box holds the apex, kept while the
    /// group's points are asked about one by one: the first `outer.lists`
    /// lists and `outer.slots` slots, under the roots from `outer.root`.
    outer: Option<Outer>,
}

/// The lists of a group kept for the points inside its box (see
/// [`Lists::aim`]).
#[derive(Clone, Copy, Debug)]
struct Outer {
    from: Aabb,
    lists: usize,
    slots: usize,
    root: u32,
}

impl Default for Lists {
    fn default() -> Self {
        Self {
            from: None,
            slots: Vec::new(),
            lists: Vec::new(),
            root: NO_LIST,
            last: NO_LIST,
            small_shafts: 0,
            small_crowded: 0,
            outer: None,
        }
    }
}

/// Whether the closed box `outer` holds the box `inner`.
#[inline]
fn holds(outer: &Aabb, inner: &Aabb) -> bool {
    let (o_min, o_max) = (Vec3A::from(outer.min), Vec3A::from(outer.max));
    (o_min.cmple(Vec3A::from(inner.min)) & Vec3A::from(inner.max).cmple(o_max)).all()
}

impl Lists {
    /// Makes the lists those of the apex `from`, dropping any of another;
    /// but a group's lists are kept (as the *outer* lists) while the apex
    /// is a point inside the group's box. Every segment from such a point
    /// to a box is one from the group's box, so a group's list serves the
    /// point as its own would (the batch call asks about a group's nodes,
    /// then about the nodes below them for each of its points).
    pub fn aim(&mut self, from: &Aabb) {
        if self.from == Some(*from) {
            return;
        }
        let point = from.min == from.max;
        let outer = match (self.outer, self.from) {
            (Some(outer), _) if point && holds(&outer.from, from) => Some(outer),
            (_, Some(group)) if point && group.min != group.max && holds(&group, from) => {
                Some(Outer {
                    from: group,
                    lists: self.lists.len(),
                    slots: self.slots.len(),
                    root: self.root,
                })
            }
            _ => None,
        };
        let (lists, slots) = outer.map_or((0, 0), |o| (o.lists, o.slots));
        self.lists.truncate(lists);
        self.slots.truncate(slots);
        *self = Self {
            from: Some(*from),
            slots: std::mem::take(&mut self.slots),
            lists: std::mem::take(&mut self.lists),
            outer,
            ..Self::default()
        };
    }

    /// Whether lists are still worth gathering for this apex (see
    /// [`GIVE_UP_CROWDED`]).
    pub fn gathering(&self) -> bool {
        self.small_crowded < GIVE_UP_CROWDED || 2 * self.small_crowded <= self.small_shafts
    }

    /// The smallest list whose box holds `target` among `at`, its siblings
    /// and their descendants, else `found`.
    fn descend(&self, mut found: u32, mut at: u32, target: &Aabb) -> u32 {
        while at != NO_LIST {
            let list = &self.lists[at as usize];
            let held = holds(&list.target, target);
            found = if held { at } else { found };
            at = if held { list.child } else { list.sibling };
        }
        found
    }

    /// A list that serves the apex `from` and whose box holds `target`:
    /// among the lists of the current apex (or of the current group, for
    /// a point inside its box), the smallest under the nearest list that
    /// holds the target on the way up from the last list kept (the cut
    /// asks about a node's children soon after the node answered
    /// partial), else the smallest from the roots; else the smallest of
    /// the outer lists (see [`aim`](Self::aim)) if they serve `from`.
    /// `None` if no list does. Any list whose box holds the target holds
    /// every occluder that meets the target's shaft from `from`.
    pub fn find(&self, from: &Aabb, target: &Aabb) -> Option<u32> {
        let point = from.min == from.max;
        let serves = |apex: &Aabb| *apex == *from || (point && holds(apex, from));
        let mut found = NO_LIST;
        if self.from.as_ref().is_some_and(serves) {
            let mut at = self.last;
            found = loop {
                match self.lists.get(at as usize) {
                    Some(list) if holds(&list.target, target) => {
                        break self.descend(at, list.child, target);
                    }
                    Some(list) => at = list.parent,
                    None => break self.descend(NO_LIST, self.root, target),
                }
            };
        }
        if found == NO_LIST
            && let Some(outer) = self.outer
            && serves(&outer.from)
        {
            found = self.descend(NO_LIST, outer.root, target);
        }
        (found != NO_LIST).then_some(found)
    }

    /// Where the slots of list `index` lie in `slots`.
    #[inline]
    pub fn range(&self, index: u32) -> Range<usize> {
        let list = &self.lists[index as usize];
        list.start as usize..(list.start + list.len) as usize
    }

    /// Gathers at the end of `slots` the occluders that meet `shaft` (from
    /// the apex `from`): from the list `parent` if there is one, else from
    /// the BVH, where a part of a solid that meets `from` is replaced by
    /// its members that meet the shaft (every segment starts inside the
    /// part's bounds), triangles for which `may_block` is `false` (those
    /// every segment leaves behind within the offset) are left out, and
    /// the slots are ordered boxes, parts, triangles (a
    /// shadow ray through a solid meets a box inside it, which answers with
    /// one slab test). Returns their range, or `None` (nothing gathered)
    /// when more than [`CANDIDATES_MAX`] meet it; `small` says whether the
    /// shaft's target is a small node's box.
    pub fn gather(
        &mut self,
        occ: &Occluders,
        parent: Option<u32>,
        from: &Aabb,
        shaft: &Shaft,
        small: bool,
        may_block: impl Fn(&[Vec3; 3]) -> bool,
    ) -> Option<Range<usize>> {
        self.small_shafts += u32::from(small);
        let start = self.slots.len();
        if let Some(parent) = parent {
            for at in self.range(parent) {
                let slot = self.slots[at];
                let listed = shaft.meets(&occ.bounds[slot as usize])
                    && match &occ.prims[slot as usize] {
                        Prim::Triangle { v, .. } => may_block(v),
                        _ => true,
                    };
                if listed {
                    self.slots.push(slot);
                }
            }
        } else {
            let slots = &mut self.slots;
            let (lo, hi) = (Vec3A::from(from.min), Vec3A::from(from.max));
            let overflow = occ.bvh.any_in(
                |b| shaft.meets(b),
                |slot| {
                    let b = &occ.bounds[slot];
                    let listed = |slot: u32| {
                        shaft.meets(&occ.bounds[slot as usize])
                            && match &occ.prims[slot as usize] {
                                Prim::Triangle { v, .. } => may_block(v),
                                _ => true,
                            }
                    };
                    match occ.prims[slot] {
                        Prim::Part { first, end }
                            if lo.cmple(b.max).all() && b.min.cmple(hi).all() =>
                        {
                            if shaft.meets(b) {
                                slots.extend((first..end).filter(|&m| listed(m)));
                            }
                        }
                        _ => {
                            if listed(slot as u32) {
                                slots.push(slot as u32);
                            }
                        }
                    }
                    slots.len() - start > CANDIDATES_MAX
                },
            );
            if overflow {
                self.slots.truncate(start);
                self.small_crowded += u32::from(small);
                return None;
            }
            self.slots[start..].sort_unstable_by_key(|&slot| match occ.prims[slot as usize] {
                Prim::Box => 0,
                Prim::Part { .. } => 1,
                Prim::Triangle { .. } => 2,
            });
        }
        let end = self.slots.len();
        self.small_crowded += u32::from(small && end - start > crate::BATCH_CANDIDATES_MAX);
        Some(start..end)
    }

    /// Keeps the slots `gathered` (the last gathered) as the list of
    /// `target`, under the list `parent` they came from.
    pub fn keep(&mut self, parent: Option<u32>, target: &Aabb, gathered: Range<usize>) {
        let index = self.lists.len() as u32;
        // A list gathered from an outer list is a root of the apex's own
        // lists: the outer lists stay as they are, for the group's next
        // point.
        let outer = self.outer.map_or(0, |o| o.lists as u32);
        let parent = parent.filter(|&p| p >= outer).unwrap_or(NO_LIST);
        let sibling = if parent == NO_LIST {
            std::mem::replace(&mut self.root, index)
        } else {
            std::mem::replace(&mut self.lists[parent as usize].child, index)
        };
        self.lists.push(List {
            target: *target,
            start: gathered.start as u32,
            len: gathered.len() as u32,
            parent,
            child: NO_LIST,
            sibling,
        });
        self.last = index;
    }

    /// Drops the slots gathered from `start` on (a list not kept).
    pub fn drop_from(&mut self, start: usize) {
        self.slots.truncate(start);
    }
}
