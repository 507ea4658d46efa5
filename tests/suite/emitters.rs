//! Oriented emitters (cosine lobes, glTF spots, one- and two-sided, mixed
//! with isotropic lights in one tree): the certified-bound contract against
//! the exact sum (`Shading::exact_query`) for every shader, single and
//! batch, with and without a host's visibility; the profiles against an
//! independent evaluation; the sampler's probabilities; stiff named cases.

use crate::common::*;
use glam::{DVec3, Vec3};
use manylights::{
    BuildError, Combined, Emission, Emitter, Ggx, Lambert, LightTree, Phong, PointLight, Query,
    ShadeResult, Threshold, Unoccluded, Visibility,
};
use proptest::prelude::*;

/// A profile's value from the formulas, in `f64` from the given angles
/// (not the stored cosines): an evaluation written apart from the crate's.
fn reference_factor(e: &Emission, light: Vec3, point: Vec3) -> f64 {
    let d = (point - light).as_dvec3();
    let cosine = |axis: Vec3, two: bool| {
        let c = axis.as_dvec3().normalize().dot(d.normalize());
        if two { c.abs() } else { c }
    };
    match *e {
        Emission::Isotropic => 1.0,
        Emission::Cosine {
            axis,
            exponent,
            two_sided,
        } => {
            let c = cosine(axis, two_sided);
            if c > 0.0 {
                c.powf(f64::from(exponent))
            } else {
                0.0
            }
        }
        Emission::Spot {
            axis,
            inner_angle,
            outer_angle,
            two_sided,
        } => {
            let c = cosine(axis, two_sided);
            let (co, ci) = (f64::from(outer_angle).cos(), f64::from(inner_angle).cos());
            if c >= ci {
                1.0
            } else if c <= co {
                0.0
            } else {
                ((c - co) / (ci - co)).powi(2)
            }
        }
        _ => unreachable!(),
    }
}

/// A profile of each kind: isotropic; a cosine lobe of exponent 0, 1, or
/// log-uniform in `[0.1, 1e4]`; a spot of outer angle 1 to 90 degrees
/// and inner angle from 0 to the outer (sometimes equal: a hard edge);
/// each oriented one two-sided with probability 1/4. The axis is `base`
/// turned by up to `spread` radians (any direction for a large spread).
fn emission(base: Vec3) -> impl Strategy<Value = Emission> {
    let axis = move || {
        (direction(), 0.0f32..=1.0).prop_map(move |(d, t)| {
            // Between the base and a random direction: axes that mostly agree,
            // as on one wall, and some that do not.
            let t = t * t;
            let a = base.normalize() * (1.0 - t) + d.normalize() * t;
            if a.length() > 1e-3 { a } else { d }
        })
    };
    let exponent = prop_oneof![
        Just(0.0f32),
        Just(1.0f32),
        (-1.0f32..=4.0).prop_map(|u| 10f32.powf(u).min(Emission::MAX_EXPONENT)),
    ];
    let angles = (1.0f32..=90.0, 0.0f32..=1.0, any::<bool>()).prop_map(|(outer, t, hard)| {
        let outer = outer.to_radians().min(std::f32::consts::FRAC_PI_2);
        (if hard { outer } else { outer * t }, outer)
    });
    let two = prop::bool::weighted(0.25);
    prop_oneof![
        1 => Just(Emission::Isotropic),
        2 => (axis(), exponent, two).prop_map(|(a, k, two)| {
            let e = Emission::cosine(a, k);
            if two { e.two_sided() } else { e }
        }),
        2 => (axis(), angles, two).prop_map(|(a, (inner, outer), two)| {
            let e = Emission::spot(a, inner, outer);
            if two { e.two_sided() } else { e }
        }),
    ]
}

/// Lights of [`lights`] with a profile each; the axes lean towards one
/// direction (or point anywhere).
fn emitters(max: usize) -> impl Strategy<Value = Vec<Emitter>> {
    (lights(max), direction()).prop_flat_map(|(lights, base)| {
        let n = lights.len();
        (Just(lights), prop::collection::vec(emission(base), n)).prop_map(|(lights, e)| {
            lights
                .into_iter()
                .zip(e)
                .map(|(l, e)| l.with_emission(e))
                .collect()
        })
    })
}

/// Virtual point lights as instant radiosity leaves them: diffuse lobes
/// (`k = 1`) on one to four axis-aligned walls, each light exactly on its
/// wall and aimed along the wall's normal, with a few primary spots and
/// isotropic lamps among them.
fn vpl_walls(max: usize) -> impl Strategy<Value = Vec<Emitter>> {
    let wall = (0usize..6, -8.0f32..=8.0);
    (
        prop::collection::vec(wall, 1..=4),
        prop::collection::vec(
            (
                any::<prop::sample::Index>(),
                -10.0f32..=10.0,
                -10.0f32..=10.0,
                intensity(),
            ),
            1..=max,
        ),
        prop::collection::vec((vec_in(10.0), intensity(), direction()), 0..=3),
    )
        .prop_map(|(walls, vpls, primaries)| {
            let mut out: Vec<Emitter> = vpls
                .into_iter()
                .map(|(which, u, v, i)| {
                    let (face, at) = walls[which.index(walls.len())];
                    let axis = [
                        Vec3::X,
                        Vec3::NEG_X,
                        Vec3::Y,
                        Vec3::NEG_Y,
                        Vec3::Z,
                        Vec3::NEG_Z,
                    ][face];
                    let p = match face / 2 {
                        0 => Vec3::new(at, u, v),
                        1 => Vec3::new(u, at, v),
                        _ => Vec3::new(u, v, at),
                    };
                    PointLight::new(p, i).with_emission(Emission::cosine(axis, 1.0))
                })
                .collect();
            for (k, (p, i, d)) in primaries.into_iter().enumerate() {
                let e = if k % 2 == 0 {
                    Emission::spot(d, 0.3, 0.8)
                } else {
                    Emission::Isotropic
                };
                out.push(PointLight::new(p, i * 10.0).with_emission(e));
            }
            out
        })
}

/// The wall of [`Wall`] at `x = 0`.
const WALL: Wall = Wall { x: 0.0 };

/// Shades `qs` with one batch call (the host `host`, which answers for
/// groups as for points) and checks every result against its exact sum.
fn check_batch<V: Visibility + Copy>(
    shading: &mut manylights::Shading<'_, Lambert>,
    qs: &[Query],
    t: Threshold,
    host: V,
) -> Result<(), TestCaseError> {
    let mut results = vec![placeholder(); qs.len()];
    let stats = shading.shade_batch(qs, t, host, &mut results).unwrap();
    if std::env::var("BATCH_DEBUG").is_ok() {
        eprintln!("STATS {} {}", stats.shared_points, stats.points_alone);
    }
    for (q, r) in qs.iter().zip(&results) {
        check_bound(r, shading.exact_query(q, host))?;
    }
    Ok(())
}

fn placeholder() -> ShadeResult {
    let mut r = ShadeResult::default();
    r.radiance = DVec3::NAN;
    r
}

proptest! {
    #![proptest_config(cases(96))]

    /// The stored profile against the formulas, anywhere around the
    /// light: within the rounding of the stored cosines and axis.
    #[test]
    fn profiles_match_their_formulas(
        e in emission(Vec3::Z),
        light in vec_in(10.0),
        point in vec_in(12.0),
    ) {
        let (got, want) = (e.factor(light, point), reference_factor(&e, light, point));
        prop_assert!((0.0..=1.0).contains(&got), "{got}");
        // The stored `f32` cosines and axis move a value by about 1e-7
        // relative, more where the spot's ramp is steep (a hard edge
        // decides on the stored cosine): checked away from the edges.
        let steep = match e {
            Emission::Spot { inner_angle, outer_angle, .. } => {
                let c = reference_factor(&Emission::cosine(match e {
                    Emission::Spot { axis, .. } => axis,
                    _ => unreachable!(),
                }, 1.0), light, point);
                let near = |a: f32| (c - f64::from(a).cos()).abs() < 1e-5;
                near(inner_angle) || near(outer_angle) || c < 0.0 && matches!(e, Emission::Spot { two_sided: true, .. })
            }
            _ => false,
        };
        if !steep {
            // The ramp's slope amplifies the cosines' rounding (`2^-24`
            // each) by `1 / (cos_inner - cos_outer)`.
            let tolerance = match e {
                Emission::Cosine { axis, exponent, two_sided } => {
                    // The stored axis moves the cosine by up to a few
                    // `2^-24`, which moves `c^k` by as much as it varies
                    // over that range: near `c = 0` more than any share of
                    // the value.
                    const COSINE_ROUNDING: f64 = 5e-7;
                    let d = (point - light).as_dvec3().normalize();
                    let c = axis.as_dvec3().normalize().dot(d);
                    let c = if two_sided { c.abs() } else { c };
                    let k = f64::from(exponent);
                    let profile = |c: f64| if c > 0.0 { c.min(1.0).powf(k) } else { 0.0 };
                    let spread = profile(c + COSINE_ROUNDING) - profile(c - COSINE_ROUNDING);
                    (1e-5 * k.max(1.0) * want.max(1e-3)).max(spread)
                }
                Emission::Spot { inner_angle, outer_angle, .. } => {
                    1e-6 / (f64::from(inner_angle).cos() - f64::from(outer_angle).cos())
                }
                _ => 0.0,
            };
            prop_assert!((got - want).abs() <= tolerance, "{got} against {want}");
        }
    }

    /// Every shader at one point, every kind of threshold: Lambert without
    /// a view, Lambert plus Phong and GGX with one.
    #[test]
    fn emitters_certify_at_a_point(
        emitters in emitters(400),
        point in vec_in(12.0),
        normal in direction(),
        view in direction(),
        t in threshold(),
        leaf in 1usize..=32,
    ) {
        let tree = LightTree::builder().max_leaf_lights(leaf).build_emitters(&emitters).unwrap();
        let q = Query::new(point, normal).unwrap();
        let mut lambert = tree.shading(Lambert::new(Vec3::new(0.8, 0.5, 0.2)));
        let r = lambert.shade_query(&q, t, Unoccluded).unwrap();
        check_bound(&r, lambert.exact_query(&q, Unoccluded))?;
        check_threshold(&r, &t)?;
        let qv = q.with_view(view).unwrap();
        let mut glossy = tree.shading(Combined::new(
            Lambert::new(Vec3::splat(0.3)),
            Phong::new(Vec3::splat(0.5), 40.0),
        ));
        let r = glossy.shade_query(&qv, t, Unoccluded).unwrap();
        check_bound(&r, glossy.exact_query(&qv, Unoccluded))?;
        check_threshold(&r, &t)?;
        let mut ggx = tree.shading(Ggx::new(Vec3::splat(0.04), 0.2));
        let r = ggx.shade_query(&qv, t, Unoccluded).unwrap();
        check_bound(&r, ggx.exact_query(&qv, Unoccluded))?;
    }

    /// Virtual point lights on walls (where the second-order bound of
    /// diffuse lobes about one axis applies), Lambert, one point and a
    /// batch of points on a patch.
    #[test]
    fn vpls_on_walls_certify(
        emitters in vpl_walls(600),
        point in vec_in(12.0),
        normal in direction(),
        patch in prop::collection::vec((vec_in(1.0), vec_in(0.2)), 1..=64),
        t in threshold(),
    ) {
        let tree = LightTree::builder().max_leaf_lights(4).build_emitters(&emitters).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::new(0.9, 0.6, 0.3)));
        let q = Query::new(point, normal).unwrap();
        let r = shading.shade_query(&q, t, Unoccluded).unwrap();
        check_bound(&r, shading.exact_query(&q, Unoccluded))?;
        check_threshold(&r, &t)?;
        let n = normal.normalize();
        let qs: Vec<Query> = patch
            .iter()
            .map(|&(o, tilt)| Query::new(point + (o - n * o.dot(n)), n + tilt).unwrap())
            .collect();
        check_batch(&mut shading, &qs, t, Unoccluded)?;
    }

    /// With a host's visibility: the wall at `x = 0`.
    #[test]
    fn emitters_certify_behind_a_wall(
        emitters in emitters(400),
        point in vec_in(12.0),
        normal in direction(),
        t in threshold(),
    ) {
        let tree = LightTree::builder().max_leaf_lights(8).build_emitters(&emitters).unwrap();
        let q = Query::new(point, normal).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::splat(0.7)));
        let r = shading.shade_query(&q, t, WALL).unwrap();
        check_bound(&r, shading.exact_query(&q, WALL))?;
        check_threshold(&r, &t)?;
    }

    /// The batch call, with and without the wall, over points spread
    /// across a patch and over the whole cube.
    #[test]
    fn emitters_certify_in_a_batch(
        emitters in emitters(300),
        points in prop_oneof![
            prop::collection::vec((vec_in(12.0), direction()), 1..=96),
            // A patch of a plane under the lights, where groups share cuts.
            (vec_in(12.0), direction(), prop::collection::vec((vec_in(1.0), vec_in(0.2)), 1..=200))
                .prop_map(|(c, n, offsets)| {
                    let n = n.normalize();
                    offsets
                        .into_iter()
                        .map(|(o, tilt)| (c + (o - n * o.dot(n)), n + tilt))
                        .collect()
                }),
        ],
        t in threshold(),
    ) {
        let tree = LightTree::build_emitters(&emitters).unwrap();
        let mut shading = tree.shading(Lambert::new(Vec3::new(0.6, 0.6, 0.9)));
        let qs: Vec<Query> = points.iter().map(|&(p, n)| Query::new(p, n).unwrap()).collect();
        check_batch(&mut shading, &qs, t, Unoccluded)?;
        check_batch(&mut shading, &qs, t, WALL)?;
    }

    /// The sampler over emitters: probabilities sum to 1, every light
    /// that contributes can be chosen, and `sample` and `pmf` agree.
    #[test]
    fn the_sampler_sees_the_profiles(
        emitters in emitters(200),
        point in vec_in(12.0),
        normal in direction(),
    ) {
        let tree = LightTree::builder().max_leaf_lights(4).build_emitters(&emitters).unwrap();
        let lambert = Lambert::new(Vec3::splat(0.8));
        let sampler = tree.sampler(lambert);
        let q = Query::new(point, normal).unwrap();
        let mut sum = 0.0;
        for (i, e) in emitters.iter().enumerate() {
            let p = sampler.pmf(&q, i);
            let lit = single_term(&lambert, &q, &e.light) * e.emission.factor(e.light.position, point);
            if lit > 0.0 {
                prop_assert!(p > 0.0, "light {i} lit ({lit}) with probability 0");
            }
            sum += p;
        }
        let mut visited = 0;
        let mut same = true;
        sampler.for_each_pmf(&q, |light, pmf| {
            visited += 1;
            same &= pmf.to_bits() == sampler.pmf(&q, light).to_bits();
        });
        prop_assert!(visited == emitters.len() && same, "for_each_pmf against pmf");
        match sampler.sample(&q, 0.5) {
            Some(s) => {
                prop_assert!((sum - 1.0).abs() <= 1e-12, "{sum}");
                prop_assert_eq!(s.pmf.to_bits(), sampler.pmf(&q, s.light).to_bits());
            }
            None => prop_assert_eq!(sum, 0.0),
        }
    }
}

/// Lambert's term of one light at `q` (largest channel), as the shader
/// evaluates it.
fn single_term(shader: &Lambert, q: &Query, light: &PointLight) -> f64 {
    use manylights::shader::Shader;
    shader
        .eval(
            &(),
            q.surface(),
            light.position.as_dvec3(),
            light.intensity.as_dvec3(),
        )
        .max_element()
}

/// One point shaded at a 1% target and exactly: the result certifies.
fn shade_once(tree: &LightTree, p: Vec3, n: Vec3) -> (ShadeResult, DVec3) {
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let r = s.shade(p, n, Threshold::relative(0.01)).unwrap();
    let exact = s.exact(p, n).unwrap();
    assert!(r.certifies(exact), "{r:?} against {exact}");
    (r, exact)
}

#[test]
fn a_vpl_in_the_points_tangent_plane_gives_exactly_nothing() {
    // VPLs on the floor, facing up, and a point on the floor facing up: each
    // lies in the other's plane.
    let vpls: Vec<Emitter> = (0..2000)
        .map(|i| {
            let at = Vec3::new((i % 50) as f32 * 0.37, (i / 50) as f32 * 0.41, 0.0);
            PointLight::new(at, Vec3::ONE).with_emission(Emission::cosine(Vec3::Z, 1.0))
        })
        .collect();
    let tree = LightTree::build_emitters(&vpls).unwrap();
    let (r, exact) = shade_once(&tree, Vec3::new(3.1, 4.2, 0.0), Vec3::Z);
    assert_eq!(exact, DVec3::ZERO);
    assert_eq!(r.radiance, DVec3::ZERO);
    // A point on a wall at x = 0 facing +x: in the VPLs' plane, so dark,
    // though it faces them.
    let (r, exact) = shade_once(&tree, Vec3::new(-0.5, 4.0, 0.0), Vec3::X);
    assert_eq!(exact, DVec3::ZERO);
    assert_eq!(r.radiance, DVec3::ZERO);
    // Just above the floor: lit, and certified.
    let (r, exact) = shade_once(&tree, Vec3::new(3.1, 4.2, 1e-3), Vec3::NEG_Z);
    assert!(exact.x > 0.0 && r.radiance.x > 0.0);
}

#[test]
fn points_on_a_spots_cone_border() {
    // Spots straight down from height 10, outer 45 degrees: points on the
    // ground exactly 10 away sideways lie on the cone's border (up to the
    // rounding of the stored cosine), with hard and soft edges.
    for inner in [0.0f32, 0.5, std::f32::consts::FRAC_PI_4] {
        let spots: Vec<Emitter> = (0..400)
            .map(|i| {
                let at = Vec3::new((i % 20) as f32 * 10.0, (i / 20) as f32 * 10.0, 10.0);
                let spot = Emission::spot(Vec3::NEG_Z, inner, std::f32::consts::FRAC_PI_4);
                PointLight::new(at, Vec3::splat(100.0)).with_emission(spot)
            })
            .collect();
        let tree = LightTree::build_emitters(&spots).unwrap();
        for k in 0..50 {
            let p = Vec3::new(10.0 * (k % 7) as f32 + 10.0, 10.0 * (k / 7) as f32, 0.0);
            for n in [Vec3::Z, Vec3::new(1.0, 0.0, 1.0), Vec3::new(-1.0, 0.3, 0.2)] {
                shade_once(&tree, p, n);
            }
        }
    }
}

#[test]
fn axes_exactly_perpendicular_to_the_direction() {
    // Lobes along x, lights and point on one line along y: c = 0 exactly
    // for every light, so each is exactly dark (also for exponent 0).
    for k in [0.0f32, 1.0, 50.0] {
        let lights: Vec<Emitter> = (1..=500)
            .map(|i| {
                PointLight::new(Vec3::new(0.0, i as f32 * 0.1, 0.0), Vec3::ONE)
                    .with_emission(Emission::cosine(Vec3::X, k))
            })
            .collect();
        let tree = LightTree::build_emitters(&lights).unwrap();
        let (r, exact) = shade_once(&tree, Vec3::ZERO, Vec3::Y);
        assert_eq!(exact, DVec3::ZERO, "exponent {k}");
        assert_eq!(r.radiance, DVec3::ZERO, "exponent {k}");
    }
}

#[test]
fn coincident_lights_with_opposite_axes() {
    // Many lights on one spot, half aimed up and half down: only those
    // aimed at the point count, each with its own profile.
    let mut lights = Vec::new();
    for i in 0..300 {
        let axis = if i % 2 == 0 { Vec3::Z } else { Vec3::NEG_Z };
        let e = if i % 3 == 0 {
            Emission::cosine(axis, 1.0)
        } else {
            Emission::spot(axis, 0.2, 0.7)
        };
        lights.push(
            PointLight::new(Vec3::new(1.0, 2.0, 3.0), Vec3::splat(1.0 + i as f32)).with_emission(e),
        );
    }
    let tree = LightTree::build_emitters(&lights).unwrap();
    let (below, exact_below) = shade_once(&tree, Vec3::new(1.0, 2.0, 0.0), Vec3::Z);
    let (above, exact_above) = shade_once(&tree, Vec3::new(1.0, 2.0, 6.0), Vec3::NEG_Z);
    // Straight below and above, each half at full intensity: the sums of
    // the odd and even lights' intensities over the squared distances.
    let odd: f64 = (0..300)
        .filter(|i| i % 2 == 1)
        .map(|i| 1.0 + f64::from(i))
        .sum();
    let even: f64 = (0..300)
        .filter(|i| i % 2 == 0)
        .map(|i| 1.0 + f64::from(i))
        .sum();
    assert!((exact_below.x - odd / 9.0).abs() <= 1e-12 * odd);
    assert!((exact_above.x - even / 9.0).abs() <= 1e-12 * even);
    assert!(below.radiance.x > 0.0 && above.radiance.x > 0.0);
    // Aside, at 60 degrees from both axes: only the lobes light it.
    let aside = Vec3::new(1.0 + 3.0 * 3f32.sqrt(), 2.0, 0.0);
    let (_, exact) = shade_once(&tree, aside, Vec3::new(-1.0, 0.0, 1.0));
    assert!(exact.x > 0.0);
}

#[test]
fn a_node_aimed_away_costs_one_evaluation() {
    // A thousand spots aimed up, high over a point (outside their ball):
    // the root is certified dark.
    let lights: Vec<Emitter> = (0..1000)
        .map(|i| {
            let at = Vec3::new((i % 40) as f32, (i / 40) as f32, 100.0);
            PointLight::new(at, Vec3::ONE).with_emission(Emission::spot(Vec3::Z, 0.3, 0.6))
        })
        .collect();
    let tree = LightTree::build_emitters(&lights).unwrap();
    let (r, exact) = shade_once(&tree, Vec3::new(20.0, 12.0, 0.0), Vec3::Z);
    assert_eq!(exact, DVec3::ZERO);
    assert_eq!(r.radiance, DVec3::ZERO);
    assert_eq!(r.error_bound, DVec3::ZERO);
    assert!(r.nodes_evaluated <= 1, "{r:?}");
    assert_eq!(r.lights_evaluated, 0);
}

#[test]
fn isotropic_emitters_build_the_isotropic_tree() {
    let lights: Vec<PointLight> = (0..5000)
        .map(|i| {
            PointLight::new(
                Vec3::new((i % 70) as f32, (i / 70) as f32 * 1.3, 4.0),
                Vec3::ONE,
            )
        })
        .collect();
    let emitters: Vec<Emitter> = lights.iter().map(|&l| l.into()).collect();
    let plain = LightTree::build(&lights).unwrap();
    let through = LightTree::build_emitters(&emitters).unwrap();
    assert_eq!(plain.memory_bytes(), through.memory_bytes());
    assert_eq!(plain.nodes(), through.nodes());
    let p = Vec3::new(30.0, 40.0, 0.0);
    let a = plain
        .shading(Lambert::new(Vec3::ONE))
        .shade(p, Vec3::Z, Threshold::relative(0.01))
        .unwrap();
    let b = through
        .shading(Lambert::new(Vec3::ONE))
        .shade(p, Vec3::Z, Threshold::relative(0.01))
        .unwrap();
    assert_eq!(a, b);
}

#[test]
fn an_oriented_tree_rebuilt_from_isotropic_lights_forgets_its_profiles() {
    let spots: Vec<Emitter> =
        (0..200)
            .map(|i| {
                PointLight::new(Vec3::new(i as f32, 0.0, 5.0), Vec3::ONE)
                    .with_emission(Emission::spot(Vec3::Z, 0.1, 0.2))
            })
            .collect();
    let mut tree = LightTree::build_emitters(&spots).unwrap();
    let (r, _) = shade_once(&tree, Vec3::new(50.0, 0.0, 0.0), Vec3::Z);
    assert_eq!(r.radiance, DVec3::ZERO);
    let lights: Vec<PointLight> = spots.iter().map(|e| e.light).collect();
    tree.rebuild(&lights).unwrap();
    let (r, _) = shade_once(&tree, Vec3::new(50.0, 0.0, 0.0), Vec3::Z);
    assert!(r.radiance.x > 0.0);
    // A refit keeps them.
    let mut tree = LightTree::build_emitters(&spots).unwrap();
    let moved: Vec<PointLight> = lights
        .iter()
        .map(|l| PointLight::new(l.position + Vec3::Y, l.intensity))
        .collect();
    tree.refit(&moved).unwrap();
    let (r, _) = shade_once(&tree, Vec3::new(50.0, 1.0, 0.0), Vec3::Z);
    assert_eq!(r.radiance, DVec3::ZERO);
}

#[test]
fn bad_emissions_are_refused_with_their_index() {
    let ok = PointLight::new(Vec3::ZERO, Vec3::ONE);
    let bad = [
        Emission::cosine(Vec3::ZERO, 1.0),
        Emission::cosine(Vec3::new(f32::INFINITY, 0.0, 0.0), 1.0),
        Emission::cosine(Vec3::Z, -0.5),
        Emission::cosine(Vec3::Z, 1e5),
        Emission::cosine(Vec3::Z, f32::NAN),
        Emission::spot(Vec3::Z, 0.8, 0.4),
        Emission::spot(Vec3::Z, 0.0, 0.0),
        Emission::spot(Vec3::Z, 0.1, 1.7),
        Emission::spot(Vec3::Z, f32::NAN, 0.4),
        Emission::spot(Vec3::Z, 0.1, f32::NAN),
    ];
    for e in bad {
        let lights = [ok.into(), ok.into(), ok.with_emission(e)];
        match LightTree::build_emitters(&lights) {
            Err(BuildError::InvalidEmission { index: 2, .. }) => {}
            other => panic!("{e:?}: {other:?}"),
        }
    }
    // A bad position is still named as such.
    let nan = PointLight::new(Vec3::NAN, Vec3::ONE).with_emission(Emission::cosine(Vec3::Z, 1.0));
    assert!(matches!(
        LightTree::build_emitters(&[nan]),
        Err(BuildError::NonFinitePosition { index: 0 })
    ));
}

#[test]
fn grouping_by_axis_splits_a_rooms_walls() {
    // VPLs on the six faces of a unit room: with grouping, the root's
    // children each hold one face's lights.
    let mut vpls = Vec::new();
    for face in 0..6 {
        let axis = [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ][face];
        for i in 0..400 {
            let (u, v) = ((i % 20) as f32 / 20.0, (i / 20) as f32 / 20.0);
            let p = match face {
                0 => Vec3::new(0.0, u, v),
                1 => Vec3::new(1.0, u, v),
                2 => Vec3::new(u, 0.0, v),
                3 => Vec3::new(u, 1.0, v),
                4 => Vec3::new(u, v, 0.0),
                _ => Vec3::new(u, v, 1.0),
            };
            vpls.push(PointLight::new(p, Vec3::ONE).with_emission(Emission::cosine(axis, 1.0)));
        }
    }
    let tree = LightTree::build_emitters(&vpls).unwrap();
    let root = tree.root().unwrap();
    assert_eq!(root.children().len(), 6);
    for child in root.children() {
        let lights = tree.nodes()[child].lights();
        let first = tree.original_index(lights.start) / 400;
        assert!(
            lights
                .clone()
                .all(|i| tree.original_index(i) / 400 == first)
        );
    }
    let plain = LightTree::builder()
        .group_by_axis(false)
        .build_emitters(&vpls)
        .unwrap();
    assert_ne!(plain.root().unwrap().children().len(), 6);
    for tree in [&tree, &plain] {
        for p in [
            Vec3::splat(0.5),
            Vec3::new(0.1, 0.2, 0.9),
            Vec3::new(0.95, 0.5, 0.05),
        ] {
            for n in [Vec3::X, Vec3::NEG_Z, Vec3::new(1.0, -1.0, 0.5)] {
                shade_once(tree, p, n);
            }
        }
    }
}

#[test]
fn a_street_of_spots_shares_cuts_and_each_point_keeps_its_bound() {
    // Lamps on both sides of a street, aimed down and tilted towards the
    // road by up to 12 degrees; a patch of road and kerb under them.
    let lamps: Vec<Emitter> = (0..20_000)
        .map(|i| {
            let (x, side) = ((i / 2) as f32 * 3.0, if i % 2 == 0 { -6.0f32 } else { 6.0 });
            let tilt = (i % 13) as f32 / 12.0 * 12f32.to_radians();
            let axis = Vec3::new(0.0, -side.signum() * tilt.sin(), -tilt.cos());
            let spot = if i % 5 == 0 {
                Emission::cosine(axis, 4.0)
            } else {
                Emission::spot(axis, 0.4, 0.9)
            };
            PointLight::new(Vec3::new(x, side, 5.0), Vec3::new(1.0, 0.6, 0.3) * 50.0)
                .with_emission(spot)
        })
        .collect();
    let tree = LightTree::build_emitters(&lamps).unwrap();
    let queries: Vec<Query> = (0..256)
        .map(|k| {
            let (u, v) = ((k % 16) as f32, (k / 16) as f32);
            let n = if k % 7 == 0 {
                Vec3::new(0.2, 0.1, 1.0)
            } else {
                Vec3::Z
            };
            Query::new(Vec3::new(3000.0 + u * 0.5, -4.0 + v * 0.5, 0.0), n).unwrap()
        })
        .collect();
    let mut shading = tree.shading(Lambert::new(Vec3::splat(0.5)));
    for t in [
        Threshold::relative(0.01),
        Threshold::relative(0.05).with_interpolation(2.0),
    ] {
        let mut results = vec![placeholder(); queries.len()];
        let stats = shading
            .shade_batch(&queries, t, Unoccluded, &mut results)
            .unwrap();
        assert!(stats.shared_points > 128, "{stats:?}");
        for (q, r) in queries.iter().zip(&results) {
            let exact = shading.exact_query(q, Unoccluded);
            assert!(r.certifies(exact), "{r:?} against {exact}");
            assert!(exact.x > 0.0);
        }
    }
}
