//! Solids: closed triangle meshes, and the boxes found inside them.
//!
//! A triangle mesh blocks a node as a whole only through one of its
//! triangles (or quads), and a building made of triangles has none that
//! covers what the building hides. A *solid* is a closed mesh whose
//! enclosed region is opaque; [`solid_parts`] finds axis-aligned boxes
//! inside that region, which the occluders then hold as box occluders: a
//! box blocks every segment that passes through it, and the classifier
//! proves that for a whole node from its corners.
//!
//! # Closed
//!
//! A mesh is closed when, over its vertices identified by position, every
//! edge is traversed as often in one direction as in the other (a
//! consistently wound watertight surface traverses each edge once each way;
//! a face shared by two closed parts, twice). The *winding number* of the
//! surface about a point not on it, the sum of the triangles' signed solid
//! angles over `4 pi`, is then an integer, constant on every connected
//! region that meets no triangle; the solid is where it is not zero (so
//! either winding of the surface encloses the same solid).
//!
//! # The boxes
//!
//! Each connected part of the mesh (triangles sharing vertices; a part of
//! a closed mesh is closed) is searched on a grid over its bounding box,
//! against its own triangles and those of the parts whose bounding boxes
//! meet its own (a closed part's winding number is 0 outside its bounding
//! box). The grid's planes along each axis are those triangles' vertices'
//! coordinates, clamped to the box (a box-shaped building is one cell),
//! or, where there are more than [`GRID_CELLS`] of them, [`GRID_CELLS`]
//! equal cells (fewer on a mesh of many triangles or many parts: the work
//! over a whole solid is bounded). A cell, shrunk by the
//! inset, is inside when no triangle meets it (a separating-axis test, in
//! `f64`, that declares a separation only with room for its rounding) and
//! the winding number at its centre rounds, clearly, to a nonzero integer.
//! Neighbouring inside cells are merged greedily into larger boxes, each of
//! which is tested against the triangles again (it is kept whole only if
//! none meets it), and the [`BOXES_PER_PART`] largest of a part are kept,
//! rounded inwards to `f32`.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use manylights::Aabb;
use obvhs::aabb::Aabb as BvhAabb;

use crate::bvh::Bvh;

/// Cells along an axis of a part's grid at most (when its vertices have
/// more distinct coordinates along it than this plus one).
pub const GRID_CELLS: usize = 16;

/// Interior boxes kept per connected part of a solid, the largest first.
pub const BOXES_PER_PART: usize = 8;

/// The grid's cells times the triangles tested against them, at most, over
/// all parts of a solid (a part's share, but at least one cell): the
/// separating-axis and winding-number work.
const WORK: usize = 1 << 24;

/// A vertex's identity: its position's bits (with `-0` as `+0`).
fn key(p: Vec3) -> [u32; 3] {
    p.to_array().map(|x| (x + 0.0).to_bits())
}

/// The number of edges of a mesh, over vertices identified by position,
/// traversed more often in one direction than in the other: 0 for a closed
/// mesh, which [`OccludersBuilder::solid`](crate::OccludersBuilder::solid)
/// takes (see the rules there).
///
/// ```
/// use manylights::Aabb;
/// use manylights_mesh::{box_mesh, open_edges};
/// # use glam::Vec3;
/// let (corners, indices) = box_mesh(&Aabb { min: Vec3::ZERO, max: Vec3::ONE });
/// let triangles: Vec<[Vec3; 3]> = indices
///     .chunks_exact(3)
///     .map(|t| [0, 1, 2].map(|k| corners[t[k] as usize]))
///     .collect();
/// assert_eq!(open_edges(&triangles), 0);
/// assert_eq!(open_edges(&triangles[..10]), 4); // a face missing
/// ```
pub fn open_edges(triangles: &[[Vec3; 3]]) -> usize {
    let mut balance: HashMap<([u32; 3], [u32; 3]), i64> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (key(t[k]), key(t[(k + 1) % 3]));
            if a == b {
                continue;
            }
            let (edge, sign) = if a < b { ((a, b), 1) } else { ((b, a), -1) };
            *balance.entry(edge).or_insert(0) += sign;
        }
    }
    balance.values().filter(|&&b| b != 0).count()
}

/// The connected parts of a mesh: triangles that share a vertex (by
/// position) lie in one part.
fn parts(triangles: &[[Vec3; 3]]) -> Vec<Vec<[Vec3; 3]>> {
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut parent: Vec<usize> = (0..triangles.len()).collect();
    let mut first: HashMap<[u32; 3], usize> = HashMap::new();
    for (i, t) in triangles.iter().enumerate() {
        for &p in t {
            let j = *first.entry(key(p)).or_insert(i);
            let (a, b) = (root(&mut parent, i), root(&mut parent, j));
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut index: HashMap<usize, usize> = HashMap::new();
    let mut out: Vec<Vec<[Vec3; 3]>> = Vec::new();
    for (i, t) in triangles.iter().enumerate() {
        let r = root(&mut parent, i);
        let n = out.len();
        let slot = *index.entry(r).or_insert(n);
        if slot == out.len() {
            out.push(Vec::new());
        }
        out[slot].push(*t);
    }
    out
}

/// A connected part of a solid: its triangles of nonzero area, the boxes
/// found inside the solid on its grid, and how many of its triangles had
/// zero area.
#[derive(Clone, Debug)]
pub(crate) struct SolidPart {
    pub triangles: Vec<[Vec3; 3]>,
    pub boxes: Vec<Aabb>,
    pub degenerate: usize,
}

/// The connected parts of the solid bounded by the closed mesh `triangles`,
/// each with boxes inside the solid at least `inset` from the surface (see
/// the module documentation).
pub(crate) fn solid_parts(triangles: &[[Vec3; 3]], inset: f64) -> Vec<SolidPart> {
    let parts = parts(triangles);
    let bounds: Vec<BvhAabb> = parts
        .iter()
        .map(|p| {
            p.iter().flatten().fold(BvhAabb::empty(), |b, &q| {
                BvhAabb::new(b.min.min(q.into()), b.max.max(q.into()))
            })
        })
        .collect();
    // The parts' boxes in a BVH, to find the parts whose boxes meet each
    // part's.
    let (bvh, order) = Bvh::new(&bounds);
    // The grid's work over all parts: a scene of many parts gets coarser
    // grids.
    let budget = (WORK / parts.len().max(1)).max(1);
    let mut near_parts = Vec::new();
    parts
        .iter()
        .zip(&bounds)
        .map(|(part, b)| {
            // The parts whose boxes meet this one's: a closed part's winding
            // number is 0 outside its box, and its triangles lie in it.
            near_parts.clear();
            bvh.any_in(
                |n| n.intersect_aabb(b),
                |slot| {
                    let other = order[slot] as usize;
                    if bounds[other].intersect_aabb(b) {
                        near_parts.push(other);
                    }
                    false
                },
            );
            near_parts.sort_unstable();
            let near: Vec<[Vec3; 3]> = near_parts
                .iter()
                .flat_map(|&k| parts[k].iter().copied())
                .collect();
            let kept: Vec<[Vec3; 3]> = part
                .iter()
                .copied()
                .filter(|t| {
                    let [a, b, c] = t.map(Vec3::as_dvec3);
                    (b - a).cross(c - a) != DVec3::ZERO
                })
                .collect();
            SolidPart {
                degenerate: part.len() - kept.len(),
                triangles: kept,
                boxes: part_boxes(part, &near, inset, budget),
            }
        })
        .collect()
}

/// A box in `f64`.
#[derive(Clone, Copy, Debug)]
struct Cell {
    min: DVec3,
    max: DVec3,
}

impl Cell {
    fn volume(&self) -> f64 {
        (self.max - self.min).max(DVec3::ZERO).element_product()
    }
}

/// The grid planes along one axis of a part: its vertices' distinct
/// coordinates, or `cells` equal cells between the extremes when there are
/// more.
fn planes(coords: &mut Vec<f64>, cells: usize) -> Vec<f64> {
    coords.sort_by(f64::total_cmp);
    coords.dedup();
    let (lo, hi) = (coords[0], coords[coords.len() - 1]);
    if coords.len() <= cells + 1 {
        coords.clone()
    } else {
        let step = (hi - lo) / cells as f64;
        (0..=cells)
            .map(|i| if i == cells { hi } else { lo + step * i as f64 })
            .collect()
    }
}

/// The boxes of one part, on its own grid, tested against the triangles
/// `near` (the part's and those of every part whose box meets its box).
fn part_boxes(part: &[[Vec3; 3]], near: &[[Vec3; 3]], inset: f64, budget: usize) -> Vec<Aabb> {
    // Grid resolution: the part's share of the work over the triangles.
    let cells = ((budget / near.len().max(1)) as f64)
        .cbrt()
        .floor()
        .clamp(1.0, GRID_CELLS as f64) as usize;
    let grid: [Vec<f64>; 3] = std::array::from_fn(|axis| {
        let (lo, hi) = part
            .iter()
            .flatten()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), p| {
                (l.min(p[axis]), h.max(p[axis]))
            });
        let mut coords: Vec<f64> = near
            .iter()
            .flatten()
            .map(|p| f64::from(p[axis].clamp(lo, hi)))
            .collect();
        planes(&mut coords, cells)
    });
    let n = grid.clone().map(|g| g.len().saturating_sub(1));
    if n.contains(&0) {
        return Vec::new();
    }
    let magnitude = near
        .iter()
        .flatten()
        .fold(0.0f32, |m, p| m.max(p.abs().max_element()));
    let tolerance = f64::from(magnitude) * (1.0 / (1u64 << 30) as f64);
    let cell = |i: [usize; 2], j: [usize; 2], k: [usize; 2]| Cell {
        min: DVec3::new(grid[0][i[0]], grid[1][j[0]], grid[2][k[0]]) + inset,
        max: DVec3::new(grid[0][i[1]], grid[1][j[1]], grid[2][k[1]]) - inset,
    };
    let free = |c: &Cell| c.min.cmplt(c.max).all() && !near.iter().any(|t| meets(t, c, tolerance));
    let index = |i: usize, j: usize, k: usize| (k * n[1] + j) * n[0] + i;
    let mut inside = vec![false; n[0] * n[1] * n[2]];
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let c = cell([i, i + 1], [j, j + 1], [k, k + 1]);
                inside[index(i, j, k)] = free(&c) && {
                    let w = winding(near, 0.5 * (c.min + c.max));
                    (w - w.round()).abs() < 0.25 && w.round() != 0.0
                };
            }
        }
    }
    // Greedy merging: along x, then whole rows along y, then whole slabs
    // along z.
    let mut used = vec![false; inside.len()];
    let mut boxes: Vec<Cell> = Vec::new();
    for k0 in 0..n[2] {
        for j0 in 0..n[1] {
            for i0 in 0..n[0] {
                let open = |i: usize, j: usize, k: usize, used: &[bool]| {
                    inside[index(i, j, k)] && !used[index(i, j, k)]
                };
                if !open(i0, j0, k0, &used) {
                    continue;
                }
                let mut i1 = i0 + 1;
                while i1 < n[0] && open(i1, j0, k0, &used) {
                    i1 += 1;
                }
                let mut j1 = j0 + 1;
                while j1 < n[1] && (i0..i1).all(|i| open(i, j1, k0, &used)) {
                    j1 += 1;
                }
                let mut k1 = k0 + 1;
                while k1 < n[2] && (j0..j1).all(|j| (i0..i1).all(|i| open(i, j, k1, &used))) {
                    k1 += 1;
                }
                for k in k0..k1 {
                    for j in j0..j1 {
                        for i in i0..i1 {
                            used[index(i, j, k)] = true;
                        }
                    }
                }
                let whole = cell([i0, i1], [j0, j1], [k0, k1]);
                let single = i1 - i0 == 1 && j1 - j0 == 1 && k1 - k0 == 1;
                if single || free(&whole) {
                    boxes.push(whole);
                } else {
                    for k in k0..k1 {
                        for j in j0..j1 {
                            for i in i0..i1 {
                                boxes.push(cell([i, i + 1], [j, j + 1], [k, k + 1]));
                            }
                        }
                    }
                }
            }
        }
    }
    boxes.sort_by(|a, b| b.volume().total_cmp(&a.volume()));
    boxes
        .iter()
        .filter_map(inward)
        .take(BOXES_PER_PART)
        .collect()
}

/// The box rounded inwards to `f32` (`None` if nothing is left).
fn inward(c: &Cell) -> Option<Aabb> {
    let up = |x: f64| {
        let y = x as f32;
        if f64::from(y) < x { y.next_up() } else { y }
    };
    let down = |x: f64| {
        let y = x as f32;
        if f64::from(y) > x { y.next_down() } else { y }
    };
    let min = Vec3::new(up(c.min.x), up(c.min.y), up(c.min.z));
    let max = Vec3::new(down(c.max.x), down(c.max.y), down(c.max.z));
    min.cmplt(max).all().then_some(Aabb { min, max })
}

/// The winding number of the surface about `x`: the triangles' signed
/// solid angles (after van Oosterom and Strackee) over `4 pi`.
fn winding(part: &[[Vec3; 3]], x: DVec3) -> f64 {
    let total: f64 = part
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|p| p.as_dvec3() - x);
            let (la, lb, lc) = (a.length(), b.length(), c.length());
            let num = a.dot(b.cross(c));
            let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
            2.0 * num.atan2(den)
        })
        .sum();
    total / (4.0 * std::f64::consts::PI)
}

/// Whether the triangle `t` may meet the box `c` grown by `tolerance`: no
/// separating axis among the box's three, the triangle's normal and the
/// nine cross products of an edge with a box axis shows a gap (Akenine-
/// Moller 2001). Every projection is taken relative to the box's centre
/// and compared with the box's extent grown by `tolerance` times the
/// axis's 1-norm, far above the rounding of the projections (a few `f64`
/// ulps of the coordinates' magnitude times that norm): a gap is declared
/// only where one exists.
fn meets(t: &[Vec3; 3], c: &Cell, tolerance: f64) -> bool {
    let centre = 0.5 * (c.min + c.max);
    let half = 0.5 * (c.max - c.min);
    let v = t.map(|p| p.as_dvec3() - centre);
    let edges = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    let separated = |axis: DVec3| {
        if axis == DVec3::ZERO {
            return false;
        }
        let p = v.map(|q| q.dot(axis));
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        let r = half.dot(axis.abs()) + tolerance * axis.abs().element_sum();
        lo > r || hi < -r
    };
    let units = [DVec3::X, DVec3::Y, DVec3::Z];
    if units.iter().any(|&u| separated(u)) {
        return false;
    }
    if separated(edges[0].cross(edges[1])) {
        return false;
    }
    !units
        .iter()
        .any(|&u| edges.iter().any(|&e| separated(u.cross(e))))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::box_mesh;

    fn interior_boxes(triangles: &[[Vec3; 3]], inset: f64) -> Vec<Aabb> {
        solid_parts(triangles, inset)
            .into_iter()
            .flat_map(|p| p.boxes)
            .collect()
    }

    fn triangles(positions: &[Vec3], indices: &[u32]) -> Vec<[Vec3; 3]> {
        indices
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| positions[t[k] as usize]))
            .collect()
    }

    fn cube(min: Vec3, max: Vec3) -> Vec<[Vec3; 3]> {
        let (corners, indices) = box_mesh(&Aabb { min, max });
        triangles(&corners, &indices)
    }

    #[test]
    fn a_box_is_one_cell_inset() {
        let t = cube(Vec3::new(-1.0, 2.0, 0.0), Vec3::new(3.0, 5.0, 8.0));
        assert_eq!(open_edges(&t), 0);
        let boxes = interior_boxes(&t, 0.01);
        assert_eq!(boxes.len(), 1);
        let b = boxes[0];
        assert!(b.min.abs_diff_eq(Vec3::new(-0.99, 2.01, 0.01), 1e-6));
        assert!(b.max.abs_diff_eq(Vec3::new(2.99, 4.99, 7.99), 1e-6));
    }

    #[test]
    fn either_winding_encloses_the_same_solid() {
        let mut t = cube(Vec3::ZERO, Vec3::ONE);
        for tri in &mut t {
            tri.swap(1, 2);
        }
        assert_eq!(open_edges(&t), 0);
        assert_eq!(interior_boxes(&t, 0.01).len(), 1);
    }

    #[test]
    fn an_open_box_is_not_closed() {
        let mut t = cube(Vec3::ZERO, Vec3::ONE);
        t.truncate(10);
        assert_eq!(open_edges(&t), 4);
    }

    #[test]
    fn a_hollow_shell_has_no_box_in_its_cavity() {
        // An outer cube wound outwards and an inner one wound inwards: the
        // cavity has winding number 0.
        let mut t = cube(Vec3::splat(-2.0), Vec3::splat(2.0));
        let mut inner = cube(Vec3::splat(-1.0), Vec3::splat(1.0));
        for tri in &mut inner {
            tri.swap(1, 2);
        }
        t.extend(inner);
        assert_eq!(open_edges(&t), 0);
        let boxes = interior_boxes(&t, 0.01);
        assert!(!boxes.is_empty());
        for b in &boxes {
            let cavity =
                b.min.cmplt(Vec3::splat(1.0)).all() && b.max.cmpgt(Vec3::splat(-1.0)).all();
            assert!(!cavity, "{b:?} reaches into the cavity");
        }
    }

    #[test]
    fn separate_buildings_are_separate_parts() {
        let mut t = cube(Vec3::ZERO, Vec3::ONE);
        t.extend(cube(Vec3::new(3.0, 0.0, 0.0), Vec3::new(4.0, 1.0, 2.0)));
        assert_eq!(parts(&t).len(), 2);
        assert_eq!(interior_boxes(&t, 0.01).len(), 2);
    }

    #[test]
    fn a_city_of_many_buildings_gets_a_box_in_each() {
        let mut t = Vec::new();
        for i in 0..80 {
            for j in 0..50 {
                let min = Vec3::new(i as f32 * 3.0, j as f32 * 3.0, 0.0);
                t.extend(cube(
                    min,
                    min + Vec3::new(2.0, 2.0, 1.0 + (i + j) as f32 % 7.0),
                ));
            }
        }
        let parts = solid_parts(&t, 0.01);
        assert_eq!(parts.len(), 4000);
        assert!(
            parts
                .iter()
                .all(|p| p.boxes.len() == 1 && p.triangles.len() == 12)
        );
    }

    #[test]
    fn the_separating_axis_test_sees_a_triangle_through_a_box() {
        let c = Cell {
            min: DVec3::ZERO,
            max: DVec3::ONE,
        };
        let through = [
            Vec3::new(-1.0, 0.5, -1.0),
            Vec3::new(2.0, 0.5, -1.0),
            Vec3::new(0.5, 0.5, 3.0),
        ];
        assert!(meets(&through, &c, 1e-9));
        let beside = [
            Vec3::new(1.5, 2.0, 0.0),
            Vec3::new(3.0, -1.0, 0.0),
            Vec3::new(3.0, 2.0, 3.0),
        ];
        assert!(!meets(&beside, &c, 1e-9));
    }
}
