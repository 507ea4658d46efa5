//! Stiff and extreme cases, one named test each. Every
//! case asserts no panic, finite output (or a documented infinite bound),
//! and the certified bound against the exact sum (`Shading::exact_query`,
//! or its one-line form `Shading::exact`), for Lambert (both bounds), Phong
//! over the extreme exponents, and their sum; or a clear error.

use glam::{DVec3, Vec3};
use manylights::shader::Shader;
use manylights::{
    BoundKind, BuildError, Combined, Lambert, LightTree, Phong, PointLight, Query, ShadeError,
    ShadeResult, Stop, Threshold, Unoccluded,
};

/// Thresholds every case is shaded with.
fn thresholds() -> [Threshold; 7] {
    [
        Threshold::zero(),
        Threshold::relative(0.01),
        Threshold::relative(0.2),
        Threshold::absolute(1e-3),
        Threshold::absolute(f64::INFINITY),
        Threshold::relative(0.01).with_budget(1),
        Threshold::relative(0.01).with_budget(200),
    ]
}

/// Phong exponents every case is shaded with.
const EXPONENTS: [f32; 4] = [0.0, 1.0, 100.0, 1e6];

fn assert_contract(what: &str, r: &ShadeResult, exact: DVec3) {
    assert!(exact.is_finite(), "{what}: exact {exact} not finite");
    assert!(
        r.radiance.is_finite(),
        "{what}: radiance {} not finite",
        r.radiance
    );
    assert!(!r.error_bound.is_nan(), "{what}: bound is NaN");
    if r.stop == Stop::ThresholdMet {
        assert!(
            r.error_bound.is_finite(),
            "{what}: met with an infinite bound"
        );
    }
    assert!(
        r.certifies(exact),
        "{what}: |{} - {}| = {} > {}",
        r.radiance,
        exact,
        (r.radiance - exact).abs(),
        r.error_bound
    );
}

/// Shades `p` with every shader, exponent and threshold and checks the
/// contract; returns the exact diffuse value for further checks.
fn check_all(lights: &[PointLight], p: Vec3, n: Vec3, v: Vec3) -> DVec3 {
    let tree = LightTree::build(lights).expect("valid lights");
    tree.validate().expect("valid tree");
    let mut diffuse = DVec3::ZERO;
    for kind in [BoundKind::Series, BoundKind::Paper] {
        let mut s = tree.shading(Lambert::new(Vec3::new(0.9, 0.5, 0.2)).with_bound(kind));
        let exact = s.exact(p, n).unwrap();
        diffuse = exact;
        for t in thresholds() {
            let r = s.shade(p, n, t).unwrap();
            assert_contract(&format!("lambert {kind:?} {t:?}"), &r, exact);
        }
    }
    check_batch(&tree, lights, p, n);
    for e in EXPONENTS {
        let mut s = tree.shading(Phong::new(Vec3::new(0.3, 0.6, 0.9), e));
        let exact = s.exact_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), Unoccluded);
        for t in thresholds() {
            let r = s
                .shade_query(
                    &Query::new(p, n).unwrap().with_view(v).unwrap(),
                    t,
                    Unoccluded,
                )
                .unwrap();
            assert_contract(&format!("phong e={e} {t:?}"), &r, exact);
        }
        let mut s = tree.shading(Combined::new(
            Lambert::new(Vec3::ONE),
            Phong::new(Vec3::ONE, e),
        ));
        let exact = s.exact_query(&Query::new(p, n).unwrap().with_view(v).unwrap(), Unoccluded);
        for t in thresholds() {
            let r = s
                .shade_query(
                    &Query::new(p, n).unwrap().with_view(v).unwrap(),
                    t,
                    Unoccluded,
                )
                .unwrap();
            assert_contract(&format!("combined e={e} {t:?}"), &r, exact);
        }
    }
    diffuse
}

/// Shades `p` in a batch with a patch of neighbours around it (spread over
/// a thousandth of the scene) and checks every result's contract.
fn check_batch(tree: &LightTree, lights: &[PointLight], p: Vec3, n: Vec3) {
    let (mut lo, mut hi) = (p, p);
    for l in lights {
        (lo, hi) = (lo.min(l.position), hi.max(l.position));
    }
    let step = (hi - lo).max_element() * 1e-3;
    let (u, v) = n.normalize().any_orthonormal_pair();
    let queries: Vec<Query> = (0..49)
        .map(|k| p + (u * (k % 7 - 3) as f32 + v * (k / 7 - 3) as f32) * step)
        .filter(|q| q.is_finite())
        .map(|q| Query::new(q, n).unwrap())
        .collect();
    let mut s = tree.shading(Lambert::new(Vec3::new(0.9, 0.5, 0.2)));
    // Each call writes over results that certify nothing (a NaN radiance),
    // so that a result left unwritten fails.
    let mut unwritten = ShadeResult::default();
    unwritten.radiance = DVec3::NAN;
    let mut results = vec![unwritten; queries.len()];
    for t in thresholds() {
        results.fill(unwritten);
        s.shade_batch(&queries, t, Unoccluded, &mut results)
            .unwrap();
        for (q, r) in queries.iter().zip(&results) {
            let exact = s.exact_query(q, Unoccluded);
            assert_contract(&format!("batch at {} {t:?}", q.point()), r, exact);
        }
    }
}

/// A deterministic generator (xorshift), so the cases need no seed file.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn in_cube(&mut self, h: f32) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next()) * (2.0 * h) - Vec3::splat(h)
    }
}

fn random_lights(n: usize, h: f32, seed: u64) -> Vec<PointLight> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let colour = Vec3::new(rng.next(), rng.next(), rng.next());
            PointLight::new(rng.in_cube(h), colour)
        })
        .collect()
}

const VIEW: Vec3 = Vec3::new(0.3, -0.2, 1.0);

#[test]
fn point_exactly_on_a_light() {
    let mut lights = random_lights(500, 5.0, 1);
    let p = lights[17].position;
    lights.push(PointLight::new(p, Vec3::splat(1e6)));
    check_all(&lights, p, Vec3::Z, VIEW);
}

#[test]
fn point_inside_a_node_ball_not_on_a_light() {
    // A dense cluster around the origin: the point sits between lights.
    let lights = random_lights(2000, 0.5, 2);
    check_all(
        &lights,
        Vec3::new(0.01, -0.02, 0.003),
        Vec3::new(0.2, 0.1, 1.0),
        VIEW,
    );
}

#[test]
fn hundred_thousand_coincident_lights() {
    let lights =
        vec![PointLight::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 0.5, 0.25)); 100_000];
    let tree = LightTree::build(&lights).unwrap();
    assert_eq!(tree.nodes().len(), 1, "coincident lights make one leaf");
    // Seen from afar, from next to them, and from on top of them.
    for p in [
        Vec3::ZERO,
        Vec3::new(1.0, 2.0, 2.999),
        Vec3::new(1.0, 2.0, 3.0),
    ] {
        check_all(&lights, p, Vec3::Z, VIEW);
    }
}

#[test]
fn hundred_thousand_lights_within_1e6() {
    let mut rng = Rng(3);
    let base = Vec3::new(1.0, 2.0, 3.0);
    let lights: Vec<_> = (0..100_000)
        .map(|_| PointLight::new(base + rng.in_cube(1e-6), Vec3::ONE))
        .collect();
    let tree = LightTree::build(&lights).unwrap();
    assert!(tree.depth() <= 64);
    for p in [Vec3::ZERO, base + Vec3::new(0.0, 0.0, -1e-5), base] {
        check_all(&lights, p, Vec3::Z, VIEW);
    }
}

#[test]
fn collinear_lights() {
    let lights: Vec<_> = (0..5000)
        .map(|i| PointLight::new(Vec3::new(i as f32 * 0.01, 1.0, 2.0), Vec3::ONE))
        .collect();
    check_all(&lights, Vec3::new(25.0, 0.0, 0.0), Vec3::Z, VIEW);
    check_all(&lights, Vec3::new(-3.0, 1.0, 2.0), Vec3::X, Vec3::X); // looking along the line
}

#[test]
fn coplanar_lights() {
    let mut rng = Rng(4);
    let lights: Vec<_> = (0..5000)
        .map(|_| {
            PointLight::new(
                Vec3::new(rng.next() * 10.0, rng.next() * 10.0, 5.0),
                Vec3::ONE,
            )
        })
        .collect();
    check_all(&lights, Vec3::new(5.0, 5.0, 0.0), Vec3::Z, VIEW);
    // A point in the lights' own plane, normal in the plane.
    check_all(&lights, Vec3::new(-1.0, 5.0, 5.0), Vec3::X, VIEW);
}

#[test]
fn lights_exactly_in_the_tangent_plane() {
    // cos = 0 exactly for every light: the diffuse sum is exactly 0.
    let mut rng = Rng(5);
    let lights: Vec<_> = (0..3000)
        .map(|_| {
            PointLight::new(
                Vec3::new(rng.next() * 20.0 - 10.0, rng.next() * 20.0 - 10.0, 0.0),
                Vec3::ONE,
            )
        })
        .collect();
    let exact = check_all(&lights, Vec3::ZERO, Vec3::Z, VIEW);
    assert_eq!(exact, DVec3::ZERO);
}

#[test]
fn grazing_normals() {
    let lights = random_lights(3000, 5.0, 6);
    for tilt in [1e-3f32, 1e-6, 1e-7] {
        // The normal almost in the plane the lights' centre lies in.
        check_all(
            &lights,
            Vec3::new(0.0, 0.0, -20.0),
            Vec3::new(1.0, 0.0, tilt),
            VIEW,
        );
    }
}

#[test]
fn grazing_views() {
    let lights = random_lights(3000, 5.0, 7);
    let p = Vec3::new(0.0, 0.0, -8.0);
    for tilt in [1e-3f32, 1e-7, 0.0, -1e-7] {
        // n.v ~ 0: the mirror direction lies in the tangent plane.
        check_all(&lights, p, Vec3::Z, Vec3::new(1.0, 0.0, tilt));
    }
}

#[test]
fn view_below_the_surface() {
    // n.v < 0 is shaded by the formula as written (documented on Phong).
    let lights = random_lights(2000, 5.0, 8);
    check_all(
        &lights,
        Vec3::new(0.0, 0.0, 6.0),
        Vec3::Z,
        Vec3::new(0.2, 0.1, -1.0),
    );
}

#[test]
fn intensities_from_1e_minus_30_to_1e30() {
    let mut rng = Rng(9);
    let lights: Vec<_> = (0..4000)
        .map(|i| {
            let decade = (i % 61) as f32 - 30.0;
            PointLight::new(
                rng.in_cube(5.0),
                Vec3::new(1.0, rng.next(), 0.5) * 10f32.powf(decade),
            )
        })
        .collect();
    check_all(&lights, Vec3::new(0.0, 0.0, -6.0), Vec3::Z, VIEW);
    check_all(&lights, Vec3::new(0.1, 0.2, 0.3), Vec3::Y, VIEW);
}

#[test]
fn all_intensities_zero() {
    let lights: Vec<_> = random_lights(1000, 5.0, 10)
        .into_iter()
        .map(|l| PointLight::new(l.position, Vec3::ZERO))
        .collect();
    let exact = check_all(&lights, Vec3::new(0.0, 0.0, -6.0), Vec3::Z, VIEW);
    assert_eq!(exact, DVec3::ZERO);
    let tree = LightTree::build(&lights).unwrap();
    let r = tree
        .shading(Lambert::new(Vec3::ONE))
        .shade(Vec3::new(0.0, 0.0, -6.0), Vec3::Z, Threshold::zero())
        .unwrap();
    assert_eq!((r.radiance, r.error_bound), (DVec3::ZERO, DVec3::ZERO));
    assert_eq!(r.cost(), 0, "a dark root is settled without a bound");
}

#[test]
fn some_channels_zero() {
    let lights: Vec<_> = random_lights(2000, 5.0, 11)
        .into_iter()
        .enumerate()
        .map(|(i, l)| {
            let mask = [Vec3::X, Vec3::Y, Vec3::new(1.0, 0.0, 1.0)][i % 3];
            PointLight::new(l.position, l.intensity * mask)
        })
        .collect();
    check_all(&lights, Vec3::new(0.0, 0.0, -6.0), Vec3::Z, VIEW);
}

#[test]
fn zero_lights() {
    let tree = LightTree::build(&[]).unwrap();
    tree.validate().unwrap();
    assert!(tree.is_empty() && tree.root().is_none());
    let mut s = tree.shading(Combined::new(
        Lambert::new(Vec3::ONE),
        Phong::new(Vec3::ONE, 10.0),
    ));
    for t in thresholds() {
        let r = s
            .shade_query(
                &Query::new(Vec3::ZERO, Vec3::Z)
                    .unwrap()
                    .with_view(VIEW)
                    .unwrap(),
                t,
                Unoccluded,
            )
            .unwrap();
        assert_eq!(
            (r.radiance, r.error_bound, r.cost()),
            (DVec3::ZERO, DVec3::ZERO, 0)
        );
    }
}

#[test]
fn one_light() {
    let lights = [PointLight::new(
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(4.0, 5.0, 6.0),
    )];
    let exact = check_all(&lights, Vec3::ZERO, Vec3::Z, VIEW);
    let expected = DVec3::new(0.9, 0.5, 0.2) * DVec3::new(4.0, 5.0, 6.0) * 3.0 / 14f64.powf(1.5);
    assert!((exact - expected).abs().max_element() <= 1e-7 * expected.max_element());
}

#[test]
fn coordinates_near_1e_minus_20() {
    let lights: Vec<_> = random_lights(2000, 1.0, 12)
        .into_iter()
        .map(|l| PointLight::new(l.position * 1e-20, l.intensity))
        .collect();
    check_all(&lights, Vec3::new(0.0, 0.0, -2e-20), Vec3::Z, VIEW);
    check_all(&lights, Vec3::new(1e-21, 0.0, 0.0), Vec3::Z, VIEW);
}

/// 2000 random lights within `size` of `base`, checked from `3 size` below
/// `base` and from `base` itself.
fn check_cluster(base: Vec3, size: f32, seed: u64) {
    let lights: Vec<_> = random_lights(2000, 1.0, seed)
        .into_iter()
        .map(|l| PointLight::new(base + l.position * size, l.intensity))
        .collect();
    check_all(
        &lights,
        base + Vec3::new(0.0, 0.0, -3.0 * size),
        Vec3::Z,
        VIEW,
    );
    check_all(&lights, base, Vec3::Z, VIEW);
}

#[test]
fn coordinates_near_1e15() {
    check_cluster(Vec3::splat(1e15), 1e12, 13);
}

#[test]
fn coordinates_up_to_the_largest_allowed() {
    let max = PointLight::MAX_COORDINATE;
    // A cluster near the largest coordinate, seen from beside it and from
    // one of its lights' coordinates.
    check_cluster(Vec3::splat(0.9 * max), 1e15, 15);
    // Lights over the whole allowed cube, corners included: squared
    // distances up to 1.2e37, beyond what the single-precision bound of
    // children takes.
    let mut spread: Vec<_> = random_lights(2000, max, 16);
    for (i, corner) in [
        Vec3::splat(max),
        Vec3::splat(-max),
        Vec3::new(max, -max, max),
        Vec3::new(-max, max, -max),
    ]
    .into_iter()
    .enumerate()
    {
        spread[i].position = corner;
    }
    check_all(&spread, Vec3::new(0.0, 0.0, -max), Vec3::Z, VIEW);
    check_all(
        &spread,
        Vec3::new(0.5 * max, 0.25 * max, 0.0),
        Vec3::Z,
        VIEW,
    );
    check_all(&spread, Vec3::splat(-max), Vec3::ONE, VIEW);
}

fn lattice_scene() -> Vec<PointLight> {
    let mut rng = Rng(14);
    (0..3000)
        .map(|_| {
            let c = rng.in_cube(16.0) + Vec3::new(0.0, 0.0, 20.0);
            PointLight::new(c, Vec3::new(1.0, rng.next(), 0.3))
        })
        .collect()
}

/// Shades the scene scaled by `s` (lights and point) and returns the result
/// and the exact value, both multiplied by `s^2`.
fn shade_scaled(lights: &[PointLight], s: f32) -> (ShadeResult, DVec3) {
    let (p, n) = (Vec3::new(1.0, -2.0, 0.0), Vec3::new(0.1, 0.0, 1.0));
    let scaled: Vec<_> = lights
        .iter()
        .map(|l| PointLight::new(l.position * s, l.intensity))
        .collect();
    let tree = LightTree::build(&scaled).unwrap();
    let mut sh = tree.shading(Lambert::new(Vec3::ONE));
    let mut r = sh.shade(p * s, n, Threshold::relative(0.01)).unwrap();
    let e = sh.exact(p * s, n).unwrap();
    assert_contract(&format!("scale {s}"), &r, e);
    let s2 = f64::from(s) * f64::from(s);
    r.radiance *= s2;
    r.error_bound *= s2;
    (r, e * s2)
}

/// Rescaling lights and point by `s` scales the exact value by `1/s^2`, and
/// the estimate and bound the same way (pbrt-v4 clamps a squared distance
/// with a length and fails this). With `s` a power of two the scaled scene
/// is exactly representable, so the cut must be identical and every value
/// scale to `f64` rounding: any unit-dependent constant would show.
#[test]
fn rescaled_scene_scales_exactly_for_powers_of_two() {
    let lights = lattice_scene();
    let (r1, e1) = shade_scaled(&lights, 1.0);
    // Powers of two nearest 1e-6, 1e-3, 1e3, 1e6.
    for s in [2f32.powi(-20), 2f32.powi(-10), 2f32.powi(10), 2f32.powi(20)] {
        let (r, e) = shade_scaled(&lights, s);
        let close = |a: DVec3, b: DVec3| (a - b).abs().max_element() <= 1e-12 * b.max_element();
        assert!(close(e, e1), "s={s}: exact {e} vs {e1}");
        assert_eq!(
            (r.nodes_evaluated, r.lights_evaluated),
            (r1.nodes_evaluated, r1.lights_evaluated),
            "s={s}"
        );
        assert!(
            close(r.radiance, r1.radiance),
            "s={s}: estimate {} vs {}",
            r.radiance,
            r1.radiance
        );
        assert!(
            close(r.error_bound, r1.error_bound),
            "s={s}: bound {} vs {}",
            r.error_bound,
            r1.error_bound
        );
    }
}

/// Decimal scale factors: coordinates then round to `f32`
/// differently (relative `2^-24`), which may flip a split or a refinement
/// at a tie, so the cut may differ slightly; the model must still scale to
/// that rounding and both certified results must agree within their bounds.
#[test]
fn rescaled_scene_scales_as_the_model() {
    let lights = lattice_scene();
    let (r1, e1) = shade_scaled(&lights, 1.0);
    for s in [1e-6f32, 1e-3, 1e3, 1e6] {
        let (r, e) = shade_scaled(&lights, s);
        // A few f32 roundings of each coordinate, through 1/d^2.
        assert!(
            (e - e1).abs().max_element() <= 1e-6 * e1.max_element(),
            "s={s}: exact {e} vs {e1}"
        );
        for k in 0..3 {
            let gap = (r.radiance[k] - r1.radiance[k]).abs();
            assert!(
                gap <= r.error_bound[k] + r1.error_bound[k],
                "s={s}: estimates disagree beyond their bounds"
            );
            let ratio = r.error_bound[k] / r1.error_bound[k];
            assert!((0.9..=1.1).contains(&ratio), "s={s}: bound ratio {ratio}");
        }
        let ratio = f64::from(r.nodes_evaluated) / f64::from(r1.nodes_evaluated);
        assert!((0.9..=1.1).contains(&ratio), "s={s}: node ratio {ratio}");
    }
}

#[test]
fn phong_exponent_zero_and_1e6() {
    let lights = random_lights(3000, 5.0, 15);
    for e in [0.0f32, 1e6] {
        let tree = LightTree::build(&lights).unwrap();
        let mut s = tree.shading(Phong::new(Vec3::ONE, e));
        let p = Vec3::new(0.0, 0.0, -7.0);
        let exact = s.exact_query(
            &Query::new(p, Vec3::Z).unwrap().with_view(VIEW).unwrap(),
            Unoccluded,
        );
        for t in thresholds() {
            assert_contract(
                &format!("e={e}"),
                &s.shade_query(
                    &Query::new(p, Vec3::Z).unwrap().with_view(VIEW).unwrap(),
                    t,
                    Unoccluded,
                )
                .unwrap(),
                exact,
            );
        }
    }
}

/// A lobe (e = 1e6, about 0.1 degree wide) much narrower than the cone of a
/// node, with coincident lights exactly on the mirror direction: the upper
/// bound is attained, so any loss in the cosine bound shows.
#[test]
fn phong_lobe_narrower_than_a_node_cone() {
    let n = Vec3::Z;
    let v = Vec3::new(0.6, 0.0, 0.8);
    let r = Vec3::new(-0.6, 0.0, 0.8); // mirror of v about n
    let mut lights = vec![PointLight::new(r * 10.0, Vec3::ONE); 64];
    let mut rng = Rng(16);
    lights
        .extend((0..3000).map(|_| PointLight::new(r * 10.0 + rng.in_cube(3.0), Vec3::splat(0.5))));
    let tree = LightTree::build(&lights).unwrap();
    for e in [1e4f32, 1e6] {
        let mut s = tree.shading(Phong::new(Vec3::ONE, e));
        let exact = s.exact_query(
            &Query::new(Vec3::ZERO, n).unwrap().with_view(v).unwrap(),
            Unoccluded,
        );
        assert!(
            exact.min_element() > 0.5,
            "the lobe sees the coincident lights: {exact}"
        );
        for t in thresholds() {
            assert_contract(
                &format!("e={e}"),
                &s.shade_query(
                    &Query::new(Vec3::ZERO, n).unwrap().with_view(v).unwrap(),
                    t,
                    Unoccluded,
                )
                .unwrap(),
                exact,
            );
        }
    }
    // Coincident lights alone: the node bound must contain the exact value
    // although the node's cone is a point. (The cut evaluates such a node as
    // one light of the summed intensity, so the bound is checked directly.)
    let tree = LightTree::build(&lights[..64]).unwrap();
    let phong = Phong::new(Vec3::ONE, 1e6);
    let mut s = tree.shading(phong);
    let query = Query::new(Vec3::ZERO, n).unwrap().with_view(v).unwrap();
    let exact = s.exact_query(&query, Unoccluded);
    let root = tree.root().unwrap();
    let surface = query.surface();
    let bound = phong.bound(
        &phong.prepare(surface),
        surface,
        root,
        &root.cone(surface.point).unwrap(),
    );
    let slack = ShadeResult::ROUNDING_ALLOWANCE * exact;
    assert!(
        bound.lower.cmple(exact + slack).all() && (exact - slack).cmple(bound.upper).all(),
        "coincident in the lobe: {exact} outside [{}, {}]",
        bound.lower,
        bound.upper
    );
    let root_only = s
        .shade_query(&query, Threshold::absolute(f64::INFINITY), Unoccluded)
        .unwrap();
    assert_eq!(root_only.cost(), 1);
    assert_contract("coincident in the lobe", &root_only, exact);
}

#[test]
fn thresholds_zero_infinite_nan_negative() {
    let lights = random_lights(1000, 5.0, 17);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let p = Vec3::new(0.0, 0.0, -20.0);
    let exact = s.exact(p, Vec3::Z).unwrap();
    let zero = s.shade(p, Vec3::Z, Threshold::zero()).unwrap();
    assert!(
        (zero.radiance - exact).abs().max_element()
            <= 2.0 * ShadeResult::ROUNDING_ALLOWANCE * exact.max_element()
    );
    assert_eq!(zero.error_bound, DVec3::ZERO);
    let inf = s
        .shade(p, Vec3::Z, Threshold::absolute(f64::INFINITY))
        .unwrap();
    assert_eq!(inf.nodes_evaluated, 1);
    assert_contract("infinite", &inf, exact);
    for bad in [f64::NAN, -1.0, -0.0 - 1e-300] {
        for t in [
            Threshold::absolute(bad),
            Threshold::relative(bad),
            Threshold::absolute(1.0).with_max_contribution(bad),
        ] {
            assert!(
                matches!(s.shade(p, Vec3::Z, t), Err(ShadeError::InvalidThreshold(_))),
                "{t:?} accepted"
            );
        }
    }
}

#[test]
fn node_budgets_zero_and_one() {
    let lights = random_lights(1000, 5.0, 18);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let p = Vec3::new(0.0, 0.0, -8.0);
    let exact = s.exact(p, Vec3::Z).unwrap();
    for b in [0, 1] {
        let r = s
            .shade(p, Vec3::Z, Threshold::zero().with_budget(b))
            .unwrap();
        assert_eq!(r.cost(), 1, "budget {b}: the root only");
        assert_eq!(r.stop, Stop::Budget);
        assert_contract(&format!("budget {b}"), &r, exact);
    }
    // Inside the root's ball: the root has no finite bound, so a budget of 1
    // reports an infinite (documented) bound rather than a wrong one.
    let r = s
        .shade(Vec3::ZERO, Vec3::Z, Threshold::zero().with_budget(1))
        .unwrap();
    assert_eq!(r.stop, Stop::Budget);
    assert!(r.error_bound.max_element().is_infinite() && r.radiance.is_finite());
}

#[test]
fn non_unit_normals_are_normalized() {
    let lights = random_lights(1000, 5.0, 19);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let p = Vec3::new(0.0, 0.0, -8.0);
    let n = Vec3::new(0.2, -0.1, 1.0);
    let unit = s
        .shade(p, n.normalize(), Threshold::relative(0.01))
        .unwrap();
    for scale in [1e-30f32, 1e-3, 7.0, 1e30] {
        let r = s.shade(p, n * scale, Threshold::relative(0.01)).unwrap();
        assert!(
            (r.radiance - unit.radiance).abs().max_element() <= 1e-6 * unit.radiance.max_element()
        );
    }
}

#[test]
fn zero_or_non_finite_normal_and_view_are_errors() {
    let lights = random_lights(100, 5.0, 20);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::ONE));
    let t = Threshold::relative(0.01);
    for n in [
        Vec3::ZERO,
        Vec3::new(f32::NAN, 0.0, 1.0),
        Vec3::new(f32::INFINITY, 0.0, 0.0),
    ] {
        assert_eq!(s.shade(Vec3::ZERO, n, t), Err(ShadeError::InvalidNormal));
        assert_eq!(s.exact(Vec3::ZERO, n), Err(ShadeError::InvalidNormal));
    }
    assert_eq!(
        s.shade(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::Z, t),
        Err(ShadeError::NonFinitePoint)
    );
    for v in [Vec3::ZERO, Vec3::new(0.0, f32::NAN, 1.0)] {
        assert_eq!(
            Query::new(Vec3::ZERO, Vec3::Z).unwrap().with_view(v),
            Err(ShadeError::InvalidView)
        );
    }
    // A subnormal normal is not zero: it is normalized like any other.
    let tiny = s.shade(Vec3::ZERO, Vec3::new(0.0, 0.0, 1e-45), t).unwrap();
    assert_eq!(tiny, s.shade(Vec3::ZERO, Vec3::Z, t).unwrap());
}

#[test]
fn sums_that_overflow_f32() {
    // 1000 lights of 1e38 at unit distance: the sum (~1e41) exceeds f32::MAX.
    let mut rng = Rng(21);
    let lights: Vec<_> = (0..1000)
        .map(|_| {
            PointLight::new(
                Vec3::new(0.0, 0.0, 1.0) + rng.in_cube(0.1),
                Vec3::splat(1e38),
            )
        })
        .collect();
    let exact = check_all(&lights, Vec3::ZERO, Vec3::Z, VIEW);
    assert!(exact.max_element() > f64::from(f32::MAX));
    let tree = LightTree::build(&lights).unwrap();
    assert!(tree.root().unwrap().intensity().x > f64::from(f32::MAX));
}

#[test]
fn bad_lights_are_refused_with_their_index() {
    let good = PointLight::new(Vec3::ONE, Vec3::ONE);
    let cases = [
        (
            PointLight::new(Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ONE),
            BuildError::NonFinitePosition { index: 2 },
        ),
        (
            PointLight::new(Vec3::new(0.0, f32::INFINITY, 0.0), Vec3::ONE),
            BuildError::NonFinitePosition { index: 2 },
        ),
        (
            PointLight::new(Vec3::new(0.0, 0.0, 1e19), Vec3::ONE),
            BuildError::PositionOutOfRange {
                index: 2,
                max: PointLight::MAX_COORDINATE,
            },
        ),
        (
            PointLight::new(Vec3::ONE, Vec3::new(1.0, f32::NAN, 0.0)),
            BuildError::NonFiniteIntensity { index: 2 },
        ),
        (
            PointLight::new(Vec3::ONE, Vec3::new(1.0, 0.0, -1e-30)),
            BuildError::NegativeIntensity { index: 2 },
        ),
    ];
    for (bad, err) in cases {
        assert_eq!(LightTree::build(&[good, good, bad, good]).unwrap_err(), err);
    }
    assert!(matches!(
        LightTree::builder().max_leaf_lights(0).build(&[good]),
        Err(BuildError::InvalidOption(_))
    ));
}

#[test]
fn bad_materials_are_refused() {
    let refused = Err(ShadeError::InvalidMaterial("kd must be finite and >= 0"));
    assert_eq!(Lambert::try_new(Vec3::new(-1.0, 0.0, 0.0)), refused);
    assert_eq!(Lambert::try_new(Vec3::new(f32::NAN, 0.0, 0.0)), refused);
    assert!(Phong::try_new(Vec3::new(0.0, f32::INFINITY, 0.0), 1.0).is_err());
    assert!(Phong::try_new(Vec3::ONE, f32::NAN).is_err());
    assert!(Phong::try_new(Vec3::ONE, 2e6).is_err());
    assert!(Phong::try_new(Vec3::ONE, -1.0).is_err());
    // -0.0 is a valid exponent, stored as +0.0.
    let e = Phong::try_new(Vec3::ONE, -0.0).unwrap().exponent();
    assert!(e == 0.0 && e.is_sign_positive());
}

/// The convenience constructors assert valid materials in debug builds.
#[test]
#[cfg(debug_assertions)]
#[should_panic(expected = "kd must be finite and >= 0")]
fn nan_albedo_is_a_debug_assertion() {
    let _ = Lambert::new(Vec3::new(f32::NAN, 0.0, 0.5));
}

/// Release builds keep results finite: NaN and negative channels read as 0.
#[test]
#[cfg(not(debug_assertions))]
fn nan_albedo_reads_as_zero_in_release() {
    assert_eq!(
        Lambert::new(Vec3::new(f32::NAN, -1.0, 0.5)).kd(),
        DVec3::new(0.0, 0.0, 0.5)
    );
    let lights = random_lights(100, 5.0, 22);
    let tree = LightTree::build(&lights).unwrap();
    let mut s = tree.shading(Lambert::new(Vec3::new(f32::NAN, -1.0, 0.5)));
    let r = s
        .shade(Vec3::ZERO, Vec3::Z, Threshold::relative(0.01))
        .unwrap();
    assert!(r.radiance.is_finite() && r.radiance.x == 0.0);
}

#[test]
fn large_phong_exponents_are_clamped() {
    assert_eq!(
        Phong::new(Vec3::ONE, f32::INFINITY).exponent(),
        Phong::MAX_EXPONENT
    );
    let lights = random_lights(100, 5.0, 22);
    check_all(&lights, Vec3::new(0.0, 0.0, -8.0), Vec3::Z, VIEW);
}
