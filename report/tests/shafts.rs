//! The shaft classifier of [`Shadows`] is conservative: on random scenes of
//! box occluders, a box it calls visible is reached by a shadow ray at every
//! one of many points, and a box it calls occluded by none; asked through
//! the crate's cut, the same holds for every node's lights, and the
//! certified bound holds against the exact shadowed sum, and every shadow
//! ray through a candidate list, alone or four at a time, answers as the
//! BVH does. The cut keeps classifying in the city and gives up under the
//! canopy.

use glam::Vec3;
use manylights::{
    Aabb, Coverage, Lambert, LightTree, NodeRegion, PointLight, Query, Threshold, Visibility,
};
use manylights_report::bvh::{Occluders, corners};
use manylights_report::scenes::{SceneRng, rng};
use manylights_report::shadows::{SHADOW_OFFSET, Shadows};
use rand::RngExt;

/// Random scenes per test.
const SCENES: u64 = 2_000;
/// Node boxes classified per scene.
const BOXES_PER_SCENE: usize = 12;
/// Grid points per axis of a box that the brute force casts rays to (its
/// corners, edges, faces and inside), besides random points.
const GRID: usize = 5;
const RANDOM_POINTS: usize = 64;

/// A box centred in the cube of half-size `reach`, with half-extents up to
/// `half`; each axis is flat (zero extent) with probability `flat`.
fn random_box(rng: &mut SceneRng, reach: f32, half: f32, flat: f64) -> Aabb {
    let centre = Vec3::from_array(std::array::from_fn(|_| rng.random_range(-reach..reach)));
    let extent = Vec3::from_array(std::array::from_fn(|_| {
        if rng.random_bool(flat) {
            0.0
        } else {
            rng.random_range(0.01..half)
        }
    }));
    Aabb {
        min: centre - extent,
        max: centre + extent,
    }
}

/// 1 to 12 occluders, half-extents up to 4, in the cube of half-size 10.
fn random_occluders(rng: &mut SceneRng) -> Vec<Aabb> {
    let count = rng.random_range(1..=12);
    (0..count)
        .map(|_| random_box(rng, 10.0, 4.0, 0.0))
        .collect()
}

fn random_unit(rng: &mut SceneRng) -> Vec3 {
    loop {
        let v = Vec3::from_array(std::array::from_fn(|_| rng.random_range(-1.0..1.0)));
        if v.length_squared() > 1e-2 && v.length_squared() <= 1.0 {
            return v.normalize();
        }
    }
}

/// The points of `b` the brute force tries: a grid and random points.
fn box_points(rng: &mut SceneRng, b: &Aabb) -> Vec<Vec3> {
    let at = |i: usize| i as f32 / (GRID - 1) as f32;
    let mut points = Vec::with_capacity(GRID * GRID * GRID + RANDOM_POINTS);
    for i in 0..GRID {
        for j in 0..GRID {
            for k in 0..GRID {
                points.push(b.min + (b.max - b.min) * Vec3::new(at(i), at(j), at(k)));
            }
        }
    }
    points.extend(corners(b));
    for _ in 0..RANDOM_POINTS {
        let u = Vec3::from_array(std::array::from_fn(|_| rng.random::<f32>()));
        points.push(b.min + (b.max - b.min) * u);
    }
    points
}

/// Whether `coverage` agrees with the host's shadow rays from `point` to
/// every one of `targets`.
fn agrees(host: &mut Shadows<'_>, point: Vec3, targets: &[Vec3], coverage: Coverage) -> bool {
    match coverage {
        Coverage::Visible => targets.iter().all(|&q| host.visible(point, q)),
        Coverage::Occluded => targets.iter().all(|&q| !host.visible(point, q)),
        Coverage::Partial => true,
    }
}

#[test]
fn shaft_answers_agree_with_rays_to_the_box() {
    let mut answers = [0usize; 3];
    for seed in 0..SCENES {
        let mut rng = rng(seed);
        let occluders = Occluders::new(&random_occluders(&mut rng));
        for _ in 0..BOXES_PER_SCENE {
            let target = random_box(&mut rng, 12.0, 6.0, 0.2);
            let point = Vec3::from_array(std::array::from_fn(|_| rng.random_range(-12.0..12.0)));
            let mut host = Shadows::new(&occluders, random_unit(&mut rng));
            let coverage = host.classify_box(point, &target);
            answers[coverage as usize] += 1;
            let targets = box_points(&mut rng, &target);
            assert!(
                agrees(&mut host, point, &targets, coverage),
                "seed {seed}: {coverage:?} for {target:?} from {point} is wrong"
            );
        }
    }
    // Every answer is exercised, each in at least one case in twenty.
    let total = answers.iter().sum::<usize>();
    assert!(
        answers.iter().all(|&a| 20 * a >= total),
        "answers (visible, occluded, partial) {answers:?}"
    );
}

/// A host that checks every classification against shadow rays to the
/// node's box and to each of its lights, and every shadow ray (through a
/// candidate list or not) against the BVH's any-hit traversal.
struct Checked<'a> {
    host: Shadows<'a>,
    tree: &'a LightTree,
    occluders: &'a Occluders,
    /// The host's offset of the shading point.
    lift: Vec3,
    rng: SceneRng,
    answers: [usize; 3],
    /// Lights asked about together ([`Visibility::visible_lights`]).
    batched: usize,
}

impl Visibility for Checked<'_> {
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        let coverage = self.host.classify(point, node);
        self.answers[coverage as usize] += 1;
        let members = &self.tree.nodes()[node.index as usize];
        let mut targets = box_points(&mut self.rng, &node.aabb);
        targets.extend(
            self.tree.lights()[members.lights()]
                .iter()
                .map(|l| l.position),
        );
        assert!(
            agrees(&mut self.host, point, &targets, coverage),
            "{coverage:?} for node {} from {point} is wrong",
            node.index
        );
        coverage
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        let seen = self.host.visible(point, light);
        assert_eq!(
            seen,
            !self.occluders.blocked(point + self.lift, light),
            "the shadow ray from {point} to {light} differs from the BVH's"
        );
        seen
    }

    fn visible_lights(&mut self, point: Vec3, lights: &[Vec3], seen: &mut [bool]) {
        self.host.visible_lights(point, lights, seen);
        for (&light, &seen) in lights.iter().zip(seen.iter()) {
            assert_eq!(
                seen,
                !self.occluders.blocked(point + self.lift, light),
                "the shadow ray from {point} to {light} (asked with others) differs from the \
                 BVH's"
            );
        }
        self.batched += lights.len();
    }

    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        self.host.visible_fraction(point, node)
    }
}

#[test]
fn node_answers_agree_with_rays_and_keep_the_bound() {
    let (mut answers, mut listed_rays, mut batched) = ([0usize; 3], 0, 0);
    for seed in 0..SCENES / 4 {
        let mut rng = rng(1_000 + seed);
        let boxes = random_occluders(&mut rng);
        let occluders = Occluders::new(&boxes);
        // Lights in a few clusters, so that nodes of every size occur.
        let clusters: Vec<Aabb> = (0..4)
            .map(|_| random_box(&mut rng, 12.0, 5.0, 0.2))
            .collect();
        let lights: Vec<PointLight> = (0..300)
            .map(|i| {
                let c = &clusters[i % clusters.len()];
                let u = Vec3::from_array(std::array::from_fn(|_| rng.random::<f32>()));
                PointLight::new(c.min + (c.max - c.min) * u, Vec3::new(1.0, 0.8, 0.6))
            })
            .collect();
        let tree = LightTree::build(&lights).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::splat(0.7)));
        for _ in 0..4 {
            let point = Vec3::from_array(std::array::from_fn(|_| rng.random_range(-12.0..12.0)));
            let normal = random_unit(&mut rng);
            let query = Query::new(point, normal).unwrap();
            let exact = shading.exact_query(&query, Shadows::new(&occluders, normal));
            for t in [Threshold::relative(0.01), Threshold::relative(0.2)] {
                let mut checked = Checked {
                    host: Shadows::new(&occluders, normal),
                    tree: &tree,
                    occluders: &occluders,
                    lift: normal * SHADOW_OFFSET,
                    rng: manylights_report::scenes::rng(rng.random()),
                    answers: [0; 3],
                    batched: 0,
                };
                let r = shading.shade_query(&query, t, &mut checked).unwrap();
                assert!(r.certifies(exact), "seed {seed}: {r:?} against {exact}");
                for (total, a) in answers.iter_mut().zip(checked.answers) {
                    *total += a;
                }
                listed_rays += checked.host.listed_rays;
                batched += checked.batched;
            }
        }
    }
    assert!(
        answers.iter().all(|&a| a > 0),
        "answers (visible, occluded, partial) {answers:?}"
    );
    // Rays through candidate lists were checked too.
    assert!(listed_rays > 0, "no shadow ray used a candidate list");
    // So were lights asked about together.
    assert!(batched > 0, "no lights were asked about together");
}

/// Mean shadow rays and classifications per point of the tree at a certified
/// 1% over `points`, with the shaft host against `occluders`. Leaves of at
/// most 4 lights, the size these counts were first measured with: larger
/// leaves (the default 16) trade classifications for rays, about 230 rays
/// per point becoming about 700 in the city below.
fn mean_work(scene: &manylights_report::scenes::Scene, occluders: &Occluders) -> (f64, f64) {
    let tree = LightTree::builder()
        .max_leaf_lights(4)
        .build(&scene.lights)
        .unwrap();
    let mut shading = tree.shading(Lambert::new(scene.material.kd));
    let (mut rays, mut classified) = (0.0, 0.0);
    for pt in &scene.points {
        let mut host = Shadows::new(occluders, pt.normal);
        let query = Query::new(pt.point, pt.normal).unwrap();
        shading
            .shade_query(&query, Threshold::relative(0.01), &mut host)
            .unwrap();
        rays += f64::from(host.rays);
        classified += f64::from(host.classifications());
    }
    let n = scene.points.len() as f64;
    (rays / n, classified / n)
}

#[test]
fn city_keeps_classifying_past_partial_answers_near_the_root() {
    // The nodes near the root are partial from anywhere in a city; counting
    // those answers against the host made the cut give up and cast a ray per
    // light at most points (about 2,200 rays per point here).
    let (scene, city) = manylights_report::scenes::city_shadows(20_000, 32, 7);
    let (rays, _) = mean_work(&scene, &city.occluders);
    assert!(rays < 500.0, "{rays} shadow rays per point");
}

#[test]
fn canopy_gives_up_classifying() {
    // Under many small leaves every node is partial: the cut stops asking
    // after a few small nodes' answers instead of classifying the whole tree
    // (about 800 classifications per point here).
    let (scene, leaves) = manylights_report::scenes::canopy(2_000, 8, 7);
    let (_, classified) = mean_work(&scene, &leaves);
    assert!(classified < 300.0, "{classified} classifications per point");
}
