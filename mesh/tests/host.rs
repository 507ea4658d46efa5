//! The mesh host is conservative and certifies: on random triangle soups,
//! closed meshes (boxes, spheres) and grids of buildings made of triangles
//! (with box occluders beside them), a node box it calls visible is reached
//! by the host's shadow ray at every one of many points, and one it calls
//! occluded by none, from a point and from a group of points; shading
//! through the tree, one point at a time and through the batch call,
//! certifies against the exact shadowed sum with the host's own rays; bad
//! input gets an error.

mod geometry;

use geometry::{Mesh, Rng, box_mesh, box_points, buildings, soup, sphere_mesh};
use glam::Vec3;
use manylights::{
    Aabb, Coverage, Lambert, LightTree, PointLight, Query, ShadeResult, Threshold, Visibility,
};
use manylights_mesh::{MeshError, Occluders, Shadows};
use proptest::prelude::*;

/// The kinds of occluder scene the tests draw from.
fn scene(rng: &mut Rng) -> Occluders {
    let builder = Occluders::builder();
    // Closed meshes are given as plain meshes or, half the time, as solids
    // (with boxes found inside them).
    let solid = rng.below(2) == 0;
    let closed =
        |builder: manylights_mesh::OccludersBuilder, positions: &[Vec3], indices: &[u32]| {
            if solid {
                builder.solid(positions, indices)
            } else {
                builder.mesh(positions, indices)
            }
        };
    let builder = match rng.below(4) {
        0 => {
            let count = 1 + rng.below(24);
            builder.triangles(&soup(rng, count, 10.0, 6.0))
        }
        1 => {
            let mut mesh = Mesh::default();
            for _ in 0..1 + rng.below(6) {
                mesh.append(&box_mesh(&rng.boxed(10.0, 4.0, 0.0)));
            }
            closed(builder, &mesh.positions, &mesh.indices)
        }
        2 => {
            let mut mesh = Mesh::default();
            for _ in 0..1 + rng.below(3) {
                let (centre, radius) = (rng.vec(-8.0, 8.0), rng.range(1.0, 5.0));
                mesh.append(&sphere_mesh(centre, radius, 6, 10));
            }
            closed(builder, &mesh.positions, &mesh.indices)
        }
        _ => {
            let (mesh, _) = buildings(rng, 3, 6.0);
            let shifted: Vec<Vec3> = mesh
                .positions
                .iter()
                .map(|p| *p - Vec3::new(9.0, 9.0, 0.0))
                .collect();
            closed(builder, &shifted, &mesh.indices)
        }
    }
    .unwrap();
    // Sometimes a few solid boxes too.
    let builder = if rng.below(3) == 0 {
        let boxes: Vec<Aabb> = (0..1 + rng.below(3))
            .map(|_| rng.boxed(10.0, 3.0, 0.0))
            .collect();
        builder.boxes(&boxes).unwrap()
    } else {
        builder
    };
    builder.build()
}

/// Whether `coverage` agrees with the host's shadow rays between every pair
/// of `starts` and `ends`.
fn agrees(host: &mut Shadows<'_>, starts: &[Vec3], ends: &[Vec3], coverage: Coverage) -> bool {
    let mut all = starts
        .iter()
        .flat_map(|&p| ends.iter().map(move |&q| (p, q)));
    match coverage {
        Coverage::Visible => all.all(|(p, q)| host.visible(p, q)),
        Coverage::Occluded => all.all(|(p, q)| !host.visible(p, q)),
        Coverage::Partial => true,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// From a point: never visible when a sampled segment is blocked, never
    /// occluded when one is free.
    #[test]
    fn point_answers_agree_with_rays(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let occluders = scene(&mut rng);
        let mut host = occluders.host();
        for _ in 0..16 {
            let target = rng.boxed(12.0, 5.0, 0.2);
            let point = rng.vec(-12.0, 12.0);
            let coverage = host.classify_boxes(&Aabb { min: point, max: point }, &target);
            let ends = box_points(&mut rng, &target, 4, 32);
            prop_assert!(
                agrees(&mut host, &[point], &ends, coverage),
                "{coverage:?} for {target:?} from {point}"
            );
        }
    }

    /// From a group of points: the same for sampled segments between the two
    /// boxes.
    #[test]
    fn group_answers_agree_with_rays(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let occluders = scene(&mut rng);
        let mut host = occluders.host();
        for _ in 0..8 {
            let target = rng.boxed(12.0, 4.0, 0.2);
            let group = rng.boxed(12.0, 1.0, 0.3);
            let coverage = host.classify_boxes(&group, &target);
            let starts = box_points(&mut rng, &group, 2, 8);
            let ends = box_points(&mut rng, &target, 3, 16);
            prop_assert!(
                agrees(&mut host, &starts, &ends, coverage),
                "{coverage:?} for {target:?} from {group:?}"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// A batch of shadow rays from one point (the lights of a leaf, close
    /// together or spread out) answers each light as one ray does.
    #[test]
    fn batched_rays_answer_as_single_rays(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let occluders = scene(&mut rng);
        let mut host = occluders.host();
        for _ in 0..8 {
            let point = rng.vec(-12.0, 12.0);
            let spread = [0.05, 0.5, 3.0, 12.0][rng.below(4)];
            let cluster = rng.boxed(12.0, spread, 0.2);
            let lights: Vec<Vec3> = (0..1 + rng.below(32)).map(|_| rng.in_box(&cluster)).collect();
            let mut seen = vec![false; lights.len()];
            host.visible_lights(point, &lights, &mut seen);
            for (&light, &seen) in lights.iter().zip(&seen) {
                prop_assert_eq!(seen, !occluders.blocked(point, light), "{} to {}", point, light);
            }
        }
    }
}

/// Batches of shadow rays are answered from gathered occluders (not only
/// one ray at a time), and some of their rays are blocked.
#[test]
fn batches_use_gathered_occluders() {
    let (mut batched, mut rays, mut blocked) = (0, 0, 0);
    for seed in 0..100 {
        let mut rng = Rng::new(seed);
        let occluders = scene(&mut rng);
        let mut host = occluders.host();
        for _ in 0..8 {
            let point = rng.vec(-12.0, 12.0);
            let cluster = rng.boxed(12.0, 0.5, 0.2);
            let lights: Vec<Vec3> = (0..16).map(|_| rng.in_box(&cluster)).collect();
            let mut seen = [false; 16];
            host.visible_lights(point, &lights, &mut seen);
            blocked += seen.iter().filter(|&&s| !s).count();
        }
        (batched, rays) = (batched + host.batched, rays + host.rays);
    }
    assert!(batched > rays / 2, "{batched} of {rays} rays batched");
    assert!(blocked > 0);
}

/// A point on a triangle of the scene (or just off it, within the
/// offset), as a renderer's shading points lie on its surfaces, and the
/// triangle's normal.
fn on_surface(rng: &mut Rng, occluders: &Occluders, triangles: &[[Vec3; 3]]) -> (Vec3, Vec3) {
    let t = triangles[rng.below(triangles.len())];
    let (a, b) = (rng.unit(), rng.unit());
    let (a, b) = if a + b > 1.0 {
        (1.0 - a, 1.0 - b)
    } else {
        (a, b)
    };
    let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
    let lift = occluders.offset() * rng.range(-0.5, 0.5) * f32::from(rng.below(2) as u8);
    (
        t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b + normal * lift,
        normal,
    )
}

/// A grid of buildings (a closed mesh), and its triangles.
fn city(rng: &mut Rng) -> (Mesh, Vec<[Vec3; 3]>) {
    let (mesh, _) = buildings(rng, 3, 6.0);
    let triangles = mesh
        .indices
        .chunks_exact(3)
        .map(|t| [0, 1, 2].map(|k| mesh.positions[t[k] as usize]))
        .collect();
    (mesh, triangles)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// From points on the occluders' own surfaces (the shadow rays skip the
    /// surface within the offset): never visible when a sampled segment is
    /// blocked, never occluded when one is free.
    #[test]
    fn answers_from_surfaces_agree_with_rays(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let (mesh, triangles) = city(&mut rng);
        let occluders = if rng.below(2) == 0 {
            Occluders::builder().triangles(&triangles).unwrap().build()
        } else {
            Occluders::builder().solid(&mesh.positions, &mesh.indices).unwrap().build()
        };
        let mut host = occluders.host();
        for _ in 0..16 {
            let (point, normal) = on_surface(&mut rng, &occluders, &triangles);
            // Nodes in front of the surface, mostly.
            let centre = point + normal * rng.range(-2.0, 12.0) + rng.vec(-8.0, 8.0);
            let half = rng.vec(0.01, 3.0);
            let target = Aabb { min: centre - half, max: centre + half };
            let coverage = host.classify_boxes(&Aabb { min: point, max: point }, &target);
            let ends = box_points(&mut rng, &target, 3, 24);
            prop_assert!(
                agrees(&mut host, &[point], &ends, coverage),
                "{coverage:?} for {target:?} from {point}"
            );
            // A patch of the same triangle's surface as a group.
            let (other, _) = on_surface(&mut rng, &occluders, &triangles);
            let group = Aabb { min: point.min(point + (other - point) * 0.05), max: point.max(point + (other - point) * 0.05) };
            let coverage = host.classify_boxes(&group, &target);
            let starts = box_points(&mut rng, &group, 2, 4);
            prop_assert!(
                agrees(&mut host, &starts, &ends, coverage),
                "{coverage:?} for {target:?} from {group:?}"
            );
        }
    }
}

/// A box inside `outer`, of a random fraction of its size per axis.
fn inside(rng: &mut Rng, outer: &Aabb) -> Aabb {
    let size = outer.max - outer.min;
    let part = Vec3::new(
        rng.range(0.2, 0.7),
        rng.range(0.2, 0.7),
        rng.range(0.2, 0.7),
    ) * size;
    let min = outer.min + (size - part) * Vec3::new(rng.unit(), rng.unit(), rng.unit());
    Aabb {
        min,
        max: (min + part).min(outer.max),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// As the cut asks: from one point (in free space or on a surface),
    /// boxes inside boxes that answered partial, down to a leaf whose
    /// lights then get their shadow rays in a batch; half the time after a
    /// group around the point did the same. The host answers the
    /// inner boxes and the rays from the occluders it listed for the outer
    /// ones; every answer agrees with the shadow rays, and every batched
    /// ray with a single ray through the BVH.
    #[test]
    fn nested_answers_agree_with_rays(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let (mesh, triangles) = city(&mut rng);
        let occluders = match rng.below(3) {
            0 => Occluders::builder().triangles(&triangles).unwrap().build(),
            1 => Occluders::builder().solid(&mesh.positions, &mesh.indices).unwrap().build(),
            _ => scene(&mut rng),
        };
        let mut host = occluders.host();
        for _ in 0..8 {
            let point = if rng.below(2) == 0 {
                on_surface(&mut rng, &occluders, &triangles).0
            } else {
                rng.vec(-12.0, 12.0)
            };
            let from = Aabb { min: point, max: point };
            let mut target = rng.boxed(12.0, 8.0, 0.5);
            if rng.below(2) == 0 {
                // First a group around the point, as the batch call asks,
                // down a few boxes while it answers partial: its lists
                // then serve the point.
                let group = Aabb { min: point - rng.vec(0.0, 1.0), max: point + rng.vec(0.0, 1.0) };
                for _ in 0..3 {
                    let coverage = host.classify_boxes(&group, &target);
                    let starts = box_points(&mut rng, &group, 2, 4);
                    let ends = box_points(&mut rng, &target, 3, 8);
                    prop_assert!(
                        agrees(&mut host, &starts, &ends, coverage),
                        "{coverage:?} for {target:?} from {group:?}"
                    );
                    if coverage != Coverage::Partial {
                        break;
                    }
                    target = inside(&mut rng, &target);
                }
            }
            for _ in 0..6 {
                let coverage = host.classify_boxes(&from, &target);
                let ends = box_points(&mut rng, &target, 3, 16);
                prop_assert!(
                    agrees(&mut host, &[point], &ends, coverage),
                    "{coverage:?} for {target:?} from {point}"
                );
                if coverage != Coverage::Partial {
                    break;
                }
                if rng.below(3) == 0 {
                    // A leaf: its lights' rays, batched.
                    let lights: Vec<Vec3> = (0..2 + rng.below(31)).map(|_| rng.in_box(&target)).collect();
                    let mut seen = vec![false; lights.len()];
                    host.visible_lights(point, &lights, &mut seen);
                    for (&light, &seen) in lights.iter().zip(&seen) {
                        prop_assert_eq!(seen, !occluders.blocked(point, light), "{} to {}", point, light);
                    }
                    break;
                }
                target = inside(&mut rng, &target);
            }
        }
    }
}

/// From a point the host answers boxes inside a partial box from the
/// occluders it listed for it, and the nested descents see all three
/// answers.
#[test]
fn nested_descents_use_candidate_lists() {
    let (mut answers, mut listed) = ([0u64; 3], 0);
    for seed in 0..200 {
        let mut rng = Rng::new(seed);
        let (mesh, _) = buildings(&mut rng, 3, 6.0);
        let occluders = Occluders::builder()
            .solid(&mesh.positions, &mesh.indices)
            .unwrap()
            .build();
        let mut host = occluders.host();
        let point = rng.vec(-12.0, 12.0) * Vec3::new(1.0, 1.0, 0.0);
        let from = Aabb {
            min: point,
            max: point,
        };
        let mut target = rng.boxed(12.0, 8.0, 0.5);
        for _ in 0..12 {
            if host.classify_boxes(&from, &target) != Coverage::Partial {
                break;
            }
            target = inside(&mut rng, &target);
        }
        for (total, answered) in answers.iter_mut().zip(host.answers) {
            *total += answered;
        }
        listed += host.listed;
    }
    assert!(answers.iter().all(|&a| a > 0), "{answers:?}");
    let asked: u64 = answers.iter().sum();
    assert!(
        listed > asked / 4,
        "{listed} of {asked} answered from lists"
    );
}

/// A point on a wall sees a node in front of the wall as visible (the
/// wall, its own surface, cannot block a ray past the offset), from a
/// point and from a patch of the wall; a node in the wall's plane is not
/// visible.
#[test]
fn the_points_own_surface_does_not_hide_what_it_faces() {
    let wall = [
        Vec3::new(5.0, -4.0, -4.0),
        Vec3::new(5.0, 4.0, -4.0),
        Vec3::new(5.0, 4.0, 4.0),
        Vec3::new(5.0, -4.0, 4.0),
    ];
    let occluders = Occluders::from_mesh(&wall, &[0, 1, 2, 0, 2, 3]).unwrap();
    let mut host = occluders.host();
    let point = Aabb {
        min: Vec3::new(5.0, 0.5, 0.25),
        max: Vec3::new(5.0, 0.5, 0.25),
    };
    let front = Aabb {
        min: Vec3::new(1.0, -1.0, -1.0),
        max: Vec3::new(2.0, 1.0, 1.0),
    };
    assert_eq!(host.classify_boxes(&point, &front), Coverage::Visible);
    // Grazing: a node in the wall's own plane is not claimed visible.
    let along = Aabb {
        min: Vec3::new(4.5, 6.0, -1.0),
        max: Vec3::new(5.5, 7.0, 1.0),
    };
    assert_ne!(host.classify_boxes(&point, &along), Coverage::Visible);
    // A patch of the wall as a group.
    let patch = Aabb {
        min: Vec3::new(5.0, 0.0, 0.0),
        max: Vec3::new(5.0, 1.0, 1.0),
    };
    assert_eq!(host.classify_boxes(&patch, &front), Coverage::Visible);
}

/// Every answer occurs on the scenes above, from points and from groups,
/// so the tests above check something.
#[test]
fn every_answer_occurs() {
    let (mut points, mut groups) = ([0usize; 3], [0usize; 3]);
    for seed in 0..200 {
        let mut rng = Rng::new(seed);
        let occluders = scene(&mut rng);
        let mut host = occluders.host();
        for _ in 0..16 {
            let target = rng.boxed(12.0, 5.0, 0.2);
            let point = rng.vec(-12.0, 12.0);
            points[host.classify_boxes(
                &Aabb {
                    min: point,
                    max: point,
                },
                &target,
            ) as usize] += 1;
            let group = rng.boxed(12.0, 1.0, 0.3);
            groups[host.classify_boxes(&group, &target) as usize] += 1;
        }
    }
    assert!(points.iter().all(|&a| a > 0), "from points {points:?}");
    assert!(groups.iter().all(|&a| a > 0), "from groups {groups:?}");
}

/// Lights in a few clusters, so that nodes of every size occur.
fn clustered_lights(rng: &mut Rng, count: usize) -> Vec<PointLight> {
    let clusters: Vec<Aabb> = (0..4).map(|_| rng.boxed(12.0, 5.0, 0.2)).collect();
    (0..count)
        .map(|i| {
            let c = &clusters[i % clusters.len()];
            PointLight::new(
                rng.in_box(c),
                Vec3::new(1.0, 0.8, 0.6) * rng.range(0.2, 2.0),
            )
        })
        .collect()
}

fn unit(rng: &mut Rng) -> Vec3 {
    loop {
        let v = rng.vec(-1.0, 1.0);
        if v.length_squared() > 1e-2 && v.length_squared() <= 1.0 {
            return v.normalize();
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// One point at a time and through the batch call, the result certifies
    /// against the exact shadowed sum with the host's own rays.
    #[test]
    fn shading_certifies_against_the_exact_shadowed_sum(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let occluders = scene(&mut rng);
        let tree = LightTree::build(&clustered_lights(&mut rng, 400)).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::splat(0.7)));
        // A patch of neighbouring points sharing a normal, as a renderer's
        // tile of one surface, and a few scattered points.
        let (corner, normal) = (rng.vec(-10.0, 10.0), unit(&mut rng));
        let (u, v) = normal.any_orthonormal_pair();
        let mut queries: Vec<Query> = (0..32)
            .map(|k| {
                let p = corner + u * (k % 8) as f32 * 0.2 + v * (k / 8) as f32 * 0.2;
                Query::new(p, normal).unwrap()
            })
            .collect();
        queries.extend((0..4).map(|_| Query::new(rng.vec(-12.0, 12.0), unit(&mut rng)).unwrap()));
        let exact: Vec<_> = queries
            .iter()
            .map(|q| shading.exact_query(q, &mut occluders.host()))
            .collect();
        for t in [Threshold::relative(0.01), Threshold::relative(0.2)] {
            let mut host = occluders.host();
            for (q, e) in queries.iter().zip(&exact) {
                let r = shading.shade_query(q, t, &mut host).unwrap();
                prop_assert!(r.certifies(*e), "{r:?} against {e}");
            }
            let mut results = vec![ShadeResult::default(); queries.len()];
            shading.shade_batch(&queries, t, occluders.host(), &mut results).unwrap();
            for (r, e) in results.iter().zip(&exact) {
                prop_assert!(r.certifies(*e), "batch: {r:?} against {e}");
            }
        }
    }
}

/// A closed sphere does not leak: every segment from outside to its
/// centre is blocked, however it meets the edges and vertices between the
/// triangles.
#[test]
fn closed_meshes_do_not_leak() {
    let mut rng = Rng::new(7);
    let sphere = sphere_mesh(Vec3::new(0.5, -0.25, 0.125), 3.0, 12, 24);
    let occluders = Occluders::from_mesh(&sphere.positions, &sphere.indices).unwrap();
    for k in 0..20_000 {
        let dir = unit(&mut rng);
        // Aimed at a vertex now and then.
        let from = if k % 10 == 0 {
            let v = sphere.positions[rng.below(sphere.positions.len())];
            Vec3::new(0.5, -0.25, 0.125) + (v - Vec3::new(0.5, -0.25, 0.125)) * 3.0
        } else {
            dir * rng.range(4.0, 20.0)
        };
        assert!(
            occluders.blocked(from, Vec3::new(0.5, -0.25, 0.125)),
            "from {from} into the sphere"
        );
    }
}

/// A shadow ray ignores the surface its shading point lies on (the
/// offset), and nothing farther.
#[test]
fn the_offset_skips_the_shading_points_own_surface() {
    let floor = [
        Vec3::new(-5.0, -5.0, 0.0),
        Vec3::new(5.0, -5.0, 0.0),
        Vec3::new(5.0, 5.0, 0.0),
        Vec3::new(-5.0, 5.0, 0.0),
    ];
    let occluders = Occluders::builder()
        .mesh(&floor, &[0, 1, 2, 0, 2, 3])
        .unwrap()
        .offset(0.01)
        .unwrap()
        .build();
    assert_eq!(occluders.quads(), 1);
    let mut host = occluders.host();
    // On the floor, to a light above and to one below: both unblocked (the
    // floor is the point's own surface).
    assert!(host.visible(Vec3::new(1.0, 2.0, 0.0), Vec3::new(3.0, 1.0, 4.0)));
    assert!(host.visible(Vec3::new(1.0, 2.0, 0.0), Vec3::new(3.0, 1.0, -4.0)));
    // Just past the offset, the floor blocks.
    assert!(!host.visible(Vec3::new(1.0, 2.0, 0.02), Vec3::new(1.0, 2.0, -4.0)));
}

#[test]
fn bad_input_gets_an_error() {
    let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let nan = [Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Y];
    assert_eq!(
        Occluders::from_mesh(&nan, &[0, 1, 2]).unwrap_err(),
        MeshError::NonFinite { mesh: 0, vertex: 1 }
    );
    let inf = [[Vec3::ZERO, Vec3::X, Vec3::splat(f32::INFINITY)]];
    assert!(matches!(
        Occluders::builder().triangles(&inf),
        Err(MeshError::NonFinite { .. })
    ));
    assert!(matches!(
        Occluders::from_mesh(&p, &[0, 1, 3]),
        Err(MeshError::IndexOutOfRange { index: 3, .. })
    ));
    assert!(matches!(
        Occluders::from_mesh(&p, &[0, 1]),
        Err(MeshError::IndicesNotTriangles { len: 2, .. })
    ));
    assert!(matches!(
        Occluders::from_mesh(&p, &[]),
        Err(MeshError::EmptyMesh { mesh: 0 })
    ));
    let upside_down = Aabb {
        min: Vec3::ONE,
        max: Vec3::ZERO,
    };
    assert!(matches!(
        Occluders::builder().boxes(&[upside_down]),
        Err(MeshError::BadBox { index: 0 })
    ));
    assert!(matches!(
        Occluders::builder().offset(-1.0),
        Err(MeshError::BadOffset(_))
    ));
    // Degenerate triangles are dropped and counted; a mesh of nothing else
    // blocks nothing.
    let line = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
    let degenerate = Occluders::from_mesh(&line, &[0, 1, 2, 0, 0, 1]).unwrap();
    assert_eq!((degenerate.triangles(), degenerate.degenerate()), (0, 2));
    let mut host = degenerate.host();
    assert!(host.visible(Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0)));
    // No occluders at all: everything visible, no panic.
    let empty = Occluders::builder().build();
    let mut host = empty.host();
    let node = Aabb {
        min: Vec3::ONE,
        max: Vec3::splat(2.0),
    };
    let from = Aabb {
        min: Vec3::ZERO,
        max: Vec3::ZERO,
    };
    assert_eq!(host.classify_boxes(&from, &node), Coverage::Visible);
    // Non-finite queries: no panic, a conservative answer.
    let far = Aabb {
        min: Vec3::splat(f32::NEG_INFINITY),
        max: Vec3::splat(f32::INFINITY),
    };
    let occluders = Occluders::from_mesh(&p, &[0, 1, 2]).unwrap();
    assert_eq!(
        occluders.host().classify_boxes(&from, &far),
        Coverage::Partial
    );
    assert!(occluders.host().visible(Vec3::ZERO, Vec3::splat(f32::NAN)));
}

/// `Occluders` is shared between threads; hosts are made per thread.
#[test]
fn occluders_are_shared_between_threads() {
    fn shared<T: Send + Sync>() {}
    fn sent<T: Send>() {}
    shared::<Occluders>();
    sent::<Shadows<'static>>();
    let mut rng = Rng::new(3);
    let (mesh, _) = buildings(&mut rng, 4, 5.0);
    let occluders = Occluders::from_mesh(&mesh.positions, &mesh.indices).unwrap();
    let answers: Vec<bool> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..2)
            .map(|_| {
                let occluders = &occluders;
                s.spawn(move || {
                    let mut host = occluders.host();
                    host.visible(Vec3::new(-1.0, -1.0, 1.0), Vec3::new(30.0, 30.0, 1.0))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(answers[0], answers[1]);
}

/// A wall of two triangles hides a node behind it as a whole (a quad
/// blocker), where neither triangle alone does; and triangle meshes alone
/// (no box occluders) give every answer.
#[test]
fn triangles_block_whole_nodes() {
    let wall = [
        Vec3::new(5.0, -4.0, -4.0),
        Vec3::new(5.0, 4.0, -4.0),
        Vec3::new(5.0, 4.0, 4.0),
        Vec3::new(5.0, -4.0, 4.0),
    ];
    let occluders = Occluders::from_mesh(&wall, &[0, 1, 2, 0, 2, 3]).unwrap();
    assert_eq!(occluders.quads(), 1);
    let mut host = occluders.host();
    let from = Aabb {
        min: Vec3::ZERO,
        max: Vec3::ZERO,
    };
    // Across the diagonal, behind the wall.
    let node = Aabb {
        min: Vec3::new(8.0, -1.0, -1.0),
        max: Vec3::new(9.0, 1.0, 1.0),
    };
    assert_eq!(host.classify_boxes(&from, &node), Coverage::Occluded);
    let group = Aabb {
        min: Vec3::splat(-0.5),
        max: Vec3::splat(0.5),
    };
    assert_eq!(host.classify_boxes(&group, &node), Coverage::Occluded);
    // Half behind the wall: partial; beside it: visible.
    let half = Aabb {
        min: Vec3::new(8.0, 5.0, -1.0),
        max: Vec3::new(9.0, 9.0, 1.0),
    };
    assert_eq!(host.classify_boxes(&from, &half), Coverage::Partial);
    let beside = Aabb {
        min: Vec3::new(-3.0, 5.0, -1.0),
        max: Vec3::new(-2.0, 9.0, 1.0),
    };
    assert_eq!(host.classify_boxes(&from, &beside), Coverage::Visible);

    let mut answers = [0usize; 3];
    for seed in 0..100 {
        let mut rng = Rng::new(seed);
        let (mesh, _) = buildings(&mut rng, 3, 6.0);
        let occluders = Occluders::from_mesh(&mesh.positions, &mesh.indices).unwrap();
        let mut host = occluders.host();
        for _ in 0..16 {
            let target = rng.boxed(20.0, 2.0, 0.2);
            let point = rng.vec(-2.0, 20.0) * Vec3::new(1.0, 1.0, 0.2);
            answers[host.classify_boxes(
                &Aabb {
                    min: point,
                    max: point,
                },
                &target,
            ) as usize] += 1;
        }
    }
    assert!(answers.iter().all(|&a| a > 0), "{answers:?}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The boxes found inside a solid lie inside it: every segment from a
    /// point outside the solid's bounding box to a point of one of its
    /// boxes crosses the surface (the triangles alone block it), and every
    /// box keeps the inset from the surface.
    #[test]
    fn solid_boxes_lie_inside_their_solids(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let mut mesh = Mesh::default();
        match rng.below(3) {
            0 => {
                for _ in 0..1 + rng.below(6) {
                    mesh.append(&box_mesh(&rng.boxed(10.0, 4.0, 0.0)));
                }
            }
            1 => {
                for _ in 0..1 + rng.below(3) {
                    let (centre, radius) = (rng.vec(-8.0, 8.0), rng.range(1.0, 5.0));
                    let rings = 3 + rng.below(10) as u32;
                    mesh.append(&sphere_mesh(centre, radius, rings, 2 * rings));
                }
            }
            _ => mesh = buildings(&mut rng, 3, 6.0).0,
        }
        let solid = Occluders::builder().solid(&mesh.positions, &mesh.indices).unwrap().build();
        let surface = Occluders::builder().mesh(&mesh.positions, &mesh.indices).unwrap().offset(0.0).unwrap().build();
        prop_assert!(!solid.solid_boxes().is_empty());
        let (lo, hi) = mesh.positions.iter().fold(
            (Vec3::INFINITY, Vec3::NEG_INFINITY),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        for b in solid.solid_boxes() {
            for q in box_points(&mut rng, b, 2, 16) {
                for _ in 0..8 {
                    // A point outside the bounding box.
                    let dir = unit(&mut rng);
                    let far = 0.5 * (lo + hi) + dir * (hi - lo).length() * rng.range(0.6, 2.0);
                    prop_assert!(surface.blocked(far, q), "{} to {} in {:?}", far, q, b);
                }
            }
        }
    }
}

/// A building made of triangles has no triangle that hides a node behind
/// it, but as a solid it does, from a point and from a group; the rays
/// agree.
#[test]
fn a_solid_hides_what_its_triangles_cannot() {
    let building = Aabb {
        min: Vec3::new(0.0, 0.0, 0.0),
        max: Vec3::new(10.0, 10.0, 30.0),
    };
    let mesh = box_mesh(&building);
    // Behind the building's vertical edge at the origin, as seen from the
    // point: the segments enter through two different walls.
    let behind = Aabb {
        min: Vec3::new(14.0, 14.0, 4.0),
        max: Vec3::new(16.0, 16.0, 6.0),
    };
    let point = Vec3::new(-5.0, -5.0, 5.0);
    let from = Aabb {
        min: point,
        max: point,
    };
    let group = Aabb {
        min: Vec3::new(-6.0, -6.0, 4.5),
        max: Vec3::new(-5.0, -5.0, 5.5),
    };
    let surface = Occluders::from_mesh(&mesh.positions, &mesh.indices).unwrap();
    let solid = Occluders::builder()
        .solid(&mesh.positions, &mesh.indices)
        .unwrap()
        .build();
    assert_eq!(solid.solid_boxes().len(), 1);
    assert_eq!(solid.triangles(), surface.triangles());
    // No one wall (a quad) blocks every segment.
    assert_eq!(
        surface.host().classify_boxes(&from, &behind),
        Coverage::Partial
    );
    assert_eq!(
        solid.host().classify_boxes(&from, &behind),
        Coverage::Occluded
    );
    assert_eq!(
        solid.host().classify_boxes(&group, &behind),
        Coverage::Occluded
    );
    let mut rng = Rng::new(7);
    let ends = box_points(&mut rng, &behind, 3, 32);
    let starts = box_points(&mut rng, &group, 2, 8);
    for occluders in [&surface, &solid] {
        assert!(agrees(
            &mut occluders.host(),
            &starts,
            &ends,
            Coverage::Occluded
        ));
    }
}

/// A solid must be closed: an open box is an error, and a hollow shell (an
/// outer surface wound outwards, an inner one inwards) has no box in its
/// cavity.
#[test]
fn solids_are_closed_and_keep_their_cavities() {
    let mesh = box_mesh(&Aabb {
        min: Vec3::ZERO,
        max: Vec3::ONE,
    });
    let err = Occluders::builder()
        .solid(&mesh.positions, &mesh.indices[..30])
        .unwrap_err();
    assert_eq!(
        err,
        MeshError::NotClosed {
            mesh: 0,
            open_edges: 4
        }
    );
    let mut shell = box_mesh(&Aabb {
        min: Vec3::splat(-3.0),
        max: Vec3::splat(3.0),
    });
    let mut cavity = box_mesh(&Aabb {
        min: Vec3::splat(-1.0),
        max: Vec3::splat(1.0),
    });
    for t in cavity.indices.chunks_exact_mut(3) {
        t.swap(1, 2);
    }
    shell.append(&cavity);
    let occluders = Occluders::builder()
        .solid(&shell.positions, &shell.indices)
        .unwrap()
        .build();
    assert!(!occluders.solid_boxes().is_empty());
    for b in occluders.solid_boxes() {
        let inside_cavity = b.min.cmplt(Vec3::ONE).all() && b.max.cmpgt(Vec3::NEG_ONE).all();
        assert!(!inside_cavity, "{b:?}");
    }
    // From inside the cavity, a node in it is visible.
    let mut host = occluders.host();
    let from = Aabb {
        min: Vec3::splat(-0.5),
        max: Vec3::splat(-0.5),
    };
    let node = Aabb {
        min: Vec3::splat(0.2),
        max: Vec3::splat(0.6),
    };
    assert_eq!(host.classify_boxes(&from, &node), Coverage::Visible);
}
