//! The light sampler and the stochastic cut, in the spirit of pbrt-v4's
//! `lightsamplers_test.cpp`: probabilities sum to 1 over every light,
//! `sample` returns the probability `pmf` gives (to the bit), sample
//! frequencies match the probabilities (a chi-square test), no lit light
//! has probability 0, and the estimates are unbiased (their means against
//! the exact sum, within their standard errors).
//!
//! The statistical tests run with fixed seeds (ChaCha8), so they are
//! deterministic; each states the probability that it would fail for a
//! correct sampler on a fresh seed.

use glam::{DVec3, Vec3};
use manylights::shader::{Shader, Surface};
use manylights::{
    Combined, Coverage, Lambert, LightSampler, LightTree, NodeRegion, Phong, PointLight, Query,
    Threshold, Unoccluded, Visibility,
};
use manylights_report::scenes::{SceneRng, city_lights, rng, sphere_lights};
use proptest::prelude::*;
use rand::RngExt;

use crate::common::{cases, lights};

/// A light's exact term at `surface`, as the sampler's shader gives it.
fn term<S: Shader>(shader: &S, surface: &Surface, light: &PointLight) -> DVec3 {
    let per_point = shader.prepare(surface);
    shader.eval(
        &per_point,
        surface,
        light.position.as_dvec3(),
        light.intensity.as_dvec3(),
    )
}

/// Checks, at one query, what must hold over all lights: the probabilities
/// sum to 1 (or are all 0 when `sample` finds nothing), every light whose
/// term is positive has a positive probability, and `sample` returns, for
/// a spread of `u`, a light whose `pmf` has the same bits as the
/// probability it returned.
fn check_query<S: Shader + manylights::query::Accepts<M>, M>(
    sampler: &LightSampler<'_, S>,
    lights: &[PointLight],
    query: &Query<M>,
) -> Result<(), TestCaseError> {
    let mut sum = 0.0;
    for (i, light) in lights.iter().enumerate() {
        let p = sampler.pmf(query, i);
        prop_assert!(p.is_finite() && (0.0..=1.0).contains(&p), "pmf {p}");
        let f = term(sampler.shader(), query.surface(), light);
        if f.max_element() > 0.0 {
            prop_assert!(p > 0.0, "light {i} contributes {f} with probability 0");
        }
        sum += p;
    }
    let mut visited = vec![0u32; lights.len()];
    let mut mismatch = None;
    sampler.for_each_pmf(query, |light, pmf| {
        visited[light] += 1;
        if pmf.to_bits() != sampler.pmf(query, light).to_bits() {
            mismatch = Some((light, pmf));
        }
    });
    prop_assert!(
        visited.iter().all(|&v| v == 1),
        "for_each_pmf visits every light once"
    );
    prop_assert_eq!(mismatch, None, "for_each_pmf differs from pmf");
    let first = sampler.sample(query, 0.5);
    if first.is_some() {
        prop_assert!((sum - 1.0).abs() <= 1e-12, "probabilities sum to {sum}");
    } else {
        prop_assert_eq!(sum, 0.0);
    }
    for k in 0..32 {
        let u = (f64::from(k) + 0.5) / 32.0;
        let Some(s) = sampler.sample(query, u) else {
            prop_assert!(first.is_none());
            continue;
        };
        let pmf = sampler.pmf(query, s.light);
        prop_assert_eq!(s.pmf.to_bits(), pmf.to_bits(), "light {}", s.light);
        prop_assert!(s.pmf > 0.0);
    }
    Ok(())
}

proptest! {
    #![proptest_config(cases(64))]

    /// Lambert: random scenes (uniform, clustered, one-coloured; 1 to 300
    /// lights), points anywhere, normals any way.
    #[test]
    fn lambert_probabilities_sum_to_one_and_match(
        lights in lights(300),
        point in crate::common::vec_in(12.0),
        normal in crate::common::direction(),
    ) {
        let tree = LightTree::builder().max_leaf_lights(4).build(&lights).unwrap();
        let sampler = tree.sampler(Lambert::new(Vec3::new(0.8, 0.5, 0.3)));
        check_query(&sampler, &lights, &Query::new(point, normal).unwrap())?;
    }

    /// Phong and Lambert plus Phong, with a view: the lobe leaves many
    /// lights dark.
    #[test]
    fn glossy_probabilities_sum_to_one_and_match(
        lights in lights(300),
        point in crate::common::vec_in(12.0),
        normal in crate::common::direction(),
        view in crate::common::direction(),
        exponent in 0.0f32..=200.0,
    ) {
        let tree = LightTree::builder().max_leaf_lights(4).build(&lights).unwrap();
        let query = Query::new(point, normal).unwrap().with_view(view).unwrap();
        let phong = Phong::new(Vec3::splat(0.6), exponent);
        check_query(&tree.sampler(phong), &lights, &query)?;
        let both = Combined::new(Lambert::new(Vec3::splat(0.3)), phong);
        check_query(&tree.sampler(both), &lights, &query)?;
    }

    /// GGX, `alpha` log-uniform over its range, with a view.
    #[test]
    fn ggx_probabilities_sum_to_one_and_match(
        lights in lights(300),
        point in crate::common::vec_in(12.0),
        normal in crate::common::direction(),
        view in crate::common::direction(),
        log_alpha in (1e-3f32).ln()..=0.0,
    ) {
        let tree = LightTree::builder().max_leaf_lights(4).build(&lights).unwrap();
        let query = Query::new(point, normal).unwrap().with_view(view).unwrap();
        let ggx = manylights::Ggx::new(Vec3::new(0.9, 0.6, 0.3), log_alpha.exp());
        check_query(&tree.sampler(ggx), &lights, &query)?;
    }
}

/// Instant radiosity's virtual lights in a furnished room (10^5 cosine
/// lobes on every surface, four primary lights: the report's VPL room):
/// the one-sample estimate's exact relative variance (`sum f^2 / pmf` over
/// every light, from `for_each_pmf`, over `F^2`, less 1) stays moderate at each of
/// 128 points of the room's surfaces (the largest is 28). Points just off
/// a wall or near a corner lie in front of the virtual lights nearest them
/// but behind the centroid of the node holding them; an importance that
/// took each node's emission towards the point from its centroid alone
/// gave those nodes only the defensive share at several levels, with
/// relative variances of 3e8 to 3e10 at the four worst points, which a
/// variance measured from a few thousand samples does not see. Without the
/// near children's even share the largest was 352: a floor point 5 cm
/// from the virtual lights at the foot of a wall, one of which gives a
/// third of its light.
#[test]
fn virtual_lights_near_the_point_are_not_starved() {
    use manylights::Emitter;
    use manylights_report::scenes::Room;
    let room = Room::new();
    let emitters: Vec<Emitter> = room.emitters(100_000, manylights_report::config::SEED);
    let tree = LightTree::build_emitters(&emitters).unwrap();
    let lambert = Lambert::new(Vec3::splat(0.5));
    let sampler = tree.sampler(lambert);
    let mut worst: f64 = 0.0;
    for (point, normal) in room.points(128, manylights_report::config::SEED) {
        let query = Query::new(point, normal).unwrap();
        let mut pmf = vec![0.0; emitters.len()];
        sampler.for_each_pmf(&query, |light, p| pmf[light] = p);
        let (mut exact, mut second) = (0.0, 0.0);
        for (e, &p) in emitters.iter().zip(&pmf) {
            let f = term(&lambert, query.surface(), &e.light);
            let f = (f.x + f.y + f.z) * e.emission.factor(e.light.position, point);
            if f > 0.0 {
                assert!(p > 0.0, "a lit light with probability 0 at {point}");
                exact += f;
                second += f * f / p;
            }
        }
        if exact > 0.0 {
            worst = worst.max(second / (exact * exact) - 1.0);
        }
    }
    assert!(worst < 100.0, "relative variance {worst} at some point");
}

/// The chi-square statistic's critical value for `dof` degrees of freedom
/// at the upper quantile of the standard normal `z` (Wilson and Hilferty
/// 1931: `(chi2 / dof)^(1/3)` is close to normal, with mean `1 - 2 / (9
/// dof)` and variance `2 / (9 dof)`; within a fraction of a percent for
/// `dof >= 30`).
fn chi_square_critical(dof: f64, z: f64) -> f64 {
    let s = 2.0 / (9.0 * dof);
    dof * (1.0 - s + z * s.sqrt()).powi(3)
}

/// The upper `1e-6` quantile of the standard normal: a test at
/// significance `1e-6` fails a correct sampler once in a million fresh
/// seeds.
const Z_1E6: f64 = 4.753;

/// Sample frequencies match `pmf`: 400,000 samples at each of a few
/// queries on a scene of 300 street lamps, with a Pearson chi-square test
/// at significance `1e-6` per query (bins of expected count below 5 merged
/// into one).
#[test]
fn frequencies_match_probabilities() {
    let lights = city_lights(300, 7);
    let tree = LightTree::build(&lights).unwrap();
    let sampler = tree.sampler(Lambert::new(Vec3::new(0.8, 0.6, 0.4)));
    let mut rng = rng(11);
    for (point, normal) in [
        (Vec3::new(30.0, 30.0, 0.0), Vec3::Z),
        (Vec3::new(5.0, 60.0, 0.0), Vec3::new(0.6, 0.0, 0.8)),
        (Vec3::new(70.0, 10.0, 5.5), Vec3::new(-0.3, 0.2, 0.9)),
    ] {
        let query = Query::new(point, normal).unwrap();
        const N: usize = 400_000;
        let mut counts = vec![0u64; lights.len()];
        for _ in 0..N {
            let s = sampler.sample(&query, rng.random::<f64>()).unwrap();
            counts[s.light] += 1;
        }
        let (mut chi2, mut bins) = (0.0, 0usize);
        let (mut rest_seen, mut rest_expected) = (0.0, 0.0);
        for (i, &seen) in counts.iter().enumerate() {
            let expected = sampler.pmf(&query, i) * N as f64;
            if expected == 0.0 {
                assert_eq!(seen, 0, "light {i} of probability 0 sampled");
            } else if expected < 5.0 {
                (rest_seen, rest_expected) = (rest_seen + seen as f64, rest_expected + expected);
            } else {
                chi2 += (seen as f64 - expected).powi(2) / expected;
                bins += 1;
            }
        }
        if rest_expected > 0.0 {
            chi2 += (rest_seen - rest_expected).powi(2) / rest_expected;
            bins += 1;
        }
        let critical = chi_square_critical((bins - 1) as f64, Z_1E6);
        assert!(bins > 30, "{bins} bins");
        assert!(
            chi2 <= critical,
            "chi-square {chi2} over {bins} bins > {critical}"
        );
    }
}

/// The one-sample estimate `f / pmf` is unbiased: its mean over 100,000
/// samples is within 5 standard errors (estimated from the samples) of the
/// exact sum, per channel, at points on the ground of a street city and
/// at points in orbit about a sphere of lights whose tangent planes cut it
/// (many nodes straddle the plane). Five standard errors: a correct
/// sampler fails one check in about 1.7 million (normal approximation; the
/// estimates' tails are light, every term being at most a few times the
/// mean), 30 checks here.
#[test]
fn one_sample_estimate_is_unbiased() {
    let city = city_lights(5000, 3);
    let sphere = sphere_lights(5000, 4);
    let mut rng = rng(5);
    let queries = [
        (&city, Vec3::new(100.0, 120.0, 0.0), Vec3::Z),
        (&city, Vec3::new(31.0, 44.0, 0.0), Vec3::new(0.5, -0.2, 0.8)),
        (&city, Vec3::new(250.0, 10.0, 0.0), Vec3::Z),
        (&sphere, Vec3::new(0.0, 10.0, 300.0), Vec3::X),
        (
            &sphere,
            Vec3::new(-60.0, 10.0, 150.0),
            Vec3::new(0.7, 0.0, -0.3),
        ),
    ];
    for (lights, point, normal) in queries {
        let tree = LightTree::build(lights).unwrap();
        let lambert = Lambert::new(Vec3::new(0.8, 0.6, 0.4));
        let sampler = tree.sampler(lambert);
        let query = Query::new(point, normal).unwrap();
        let exact = tree.shading(lambert).exact_query(&query, Unoccluded);
        let (mean, error) = mean_and_error(100_000, || {
            sampler
                .sample(&query, rng.random::<f64>())
                .map_or(DVec3::ZERO, |s| {
                    term(&lambert, query.surface(), &lights[s.light]) / s.pmf
                })
        });
        let within = (mean - exact).abs().cmple(5.0 * error + 1e-12 * exact);
        assert!(
            within.all(),
            "{point}: mean {mean} +- {error} against {exact}"
        );
    }
}

/// The mean of `n` draws of `draw` and its standard error, per channel.
fn mean_and_error(n: usize, mut draw: impl FnMut() -> DVec3) -> (DVec3, DVec3) {
    let (mut sum, mut sum2) = (DVec3::ZERO, DVec3::ZERO);
    for _ in 0..n {
        let x = draw();
        sum += x;
        sum2 += x * x;
    }
    let n = n as f64;
    let mean = sum / n;
    let variance = (sum2 / n - mean * mean).max(DVec3::ZERO) * (n / (n - 1.0));
    (mean, (variance / n).powf(0.5))
}

/// A host that hides every light with `x < 0` from every point and answers
/// "partial" for every node: the stochastic cut asks a ray for each
/// sampled light of unknown visibility.
struct HalfHidden;

impl Visibility for HalfHidden {
    fn classify(&mut self, _: Vec3, _: &NodeRegion) -> Coverage {
        Coverage::Partial
    }

    fn visible(&mut self, _: Vec3, light: Vec3) -> bool {
        light.x >= 0.0
    }
}

/// The stochastic cut is unbiased: over 4,000 independent calls the mean
/// of its estimates is within 5 standard errors of the exact sum (false
/// failure about 1 in 1.7 million per check), with and without occluders;
/// and its reported variance is right on average: the mean reported
/// variance is within a factor 1.5 of the variance of the estimates
/// (each is within about 10% of the truth with 4,000 calls for these
/// light-tailed estimates).
#[test]
fn stochastic_cut_is_unbiased() {
    let lights: Vec<PointLight> = city_lights(20_000, 9)
        .into_iter()
        .map(|l| PointLight::new(l.position - Vec3::new(300.0, 0.0, 0.0), l.intensity))
        .collect();
    let tree = LightTree::build(&lights).unwrap();
    let lambert = Lambert::new(Vec3::new(0.8, 0.6, 0.4));
    let mut shading = tree.shading(lambert);
    let mut rng: SceneRng = rng(13);
    for (point, normal, threshold) in [
        (
            Vec3::new(10.0, 200.0, 0.0),
            Vec3::Z,
            Threshold::relative(0.2),
        ),
        (
            Vec3::new(-50.0, 30.0, 0.0),
            Vec3::new(0.3, 0.3, 0.9),
            Threshold::relative(0.5),
        ),
        (
            Vec3::new(200.0, 400.0, 0.0),
            Vec3::Z,
            Threshold::per_node(0.1),
        ),
    ] {
        let query = Query::new(point, normal).unwrap();
        for hidden in [false, true] {
            let exact = if hidden {
                shading.exact_query(&query, HalfHidden)
            } else {
                shading.exact_query(&query, Unoccluded)
            };
            let mut reported = DVec3::ZERO;
            const N: usize = 4000;
            let (mean, error) = mean_and_error(N, || {
                let mut uniform = || rng.random::<f64>();
                let r = if hidden {
                    shading.shade_stochastic(&query, threshold, HalfHidden, &mut uniform)
                } else {
                    shading.shade_stochastic(&query, threshold, Unoccluded, &mut uniform)
                }
                .unwrap();
                assert!(r.nodes_sampled > 0);
                reported += r.variance;
                r.radiance
            });
            let within = (mean - exact).abs().cmple(5.0 * error + 1e-12 * exact);
            assert!(
                within.all(),
                "{point} {hidden}: {mean} +- {error} against {exact}"
            );
            let (reported, measured) = (reported / N as f64, error * error * N as f64);
            let ratio = reported / measured;
            assert!(
                ratio.cmpge(DVec3::splat(1.0 / 1.5)).all() && ratio.cmple(DVec3::splat(1.5)).all(),
                "{point} {hidden}: reported variance {reported}, measured {measured}"
            );
        }
    }
}

/// The batch's stochastic cut is unbiased at every point of its groups:
/// tiles of 16 points each (on the ground, on a tilted patch, and behind
/// a wall that splits the lights, classified for whole groups) share one
/// cut per group, and over 1,000 calls each point's mean is within 5
/// standard errors of its exact sum (false failure about 1 in 1.7 million
/// per check, 3 channels x 16 points x 4 cases); the reported variance,
/// summed over the points, is within a factor 1.5 of the measured one. The
/// last case is a tree of emitters (diffuse lobes facing down) over a
/// tile of neighbouring pixels, whose lights' profiles vary over the
/// group. At least half the points must have shared a cut.
#[test]
fn stochastic_batch_is_unbiased() {
    use manylights::{BatchStats, Emission, Emitter, Stochastic};
    let lights: Vec<PointLight> = city_lights(20_000, 9)
        .into_iter()
        .map(|l| PointLight::new(l.position - Vec3::new(300.0, 0.0, 0.0), l.intensity))
        .collect();
    let mut rng: SceneRng = rng(17);
    // Diffuse lobes facing down, as virtual lights on a ceiling: each
    // light's profile varies over a group of points.
    let emitters: Vec<Emitter> = lights
        .iter()
        .map(|l| l.with_emission(Emission::cosine(Vec3::NEG_Z, 1.0)))
        .collect();
    let plain = LightTree::build(&lights).unwrap();
    let oriented = LightTree::build_emitters(&emitters).unwrap();
    let lambert = Lambert::new(Vec3::new(0.8, 0.6, 0.4));
    let tile = |origin: Vec3, normal: Vec3, step: f32| -> Vec<Query> {
        (0..16)
            .map(|k| {
                let p = origin + Vec3::new((k % 4) as f32 * step, (k / 4) as f32 * step, 0.0);
                Query::new(p, normal).unwrap()
            })
            .collect()
    };
    let cases = [
        (
            &plain,
            tile(Vec3::new(10.0, 200.0, 0.0), Vec3::Z, 0.7),
            false,
        ),
        (
            &plain,
            tile(Vec3::new(-50.0, 30.0, 0.0), Vec3::new(0.3, 0.3, 0.9), 0.7),
            false,
        ),
        (
            &plain,
            tile(Vec3::new(-6.0, 100.0, 0.0), Vec3::Z, 0.7),
            true,
        ),
        (
            &oriented,
            tile(Vec3::new(10.0, 200.0, 0.0), Vec3::Z, 0.1),
            false,
        ),
    ];
    let wall = crate::common::Wall { x: 0.0 };
    for (case, (tree, queries, walled)) in cases.iter().enumerate() {
        let mut shading = tree.shading(lambert);
        let exact: Vec<DVec3> = queries
            .iter()
            .map(|q| {
                if *walled {
                    shading.exact_query(q, wall)
                } else {
                    shading.exact_query(q, Unoccluded)
                }
            })
            .collect();
        const N: usize = 1000;
        let (mut sum, mut sum2, mut reported) = (
            vec![DVec3::ZERO; 16],
            vec![DVec3::ZERO; 16],
            vec![DVec3::ZERO; 16],
        );
        let mut results = vec![Stochastic::default(); 16];
        let mut stats = BatchStats::default();
        for _ in 0..N {
            let uniform = || rng.random::<f64>();
            let threshold = Threshold::relative(0.2);
            stats += if *walled {
                shading.shade_stochastic_batch(queries, threshold, wall, uniform, &mut results)
            } else {
                shading.shade_stochastic_batch(
                    queries,
                    threshold,
                    Unoccluded,
                    uniform,
                    &mut results,
                )
            }
            .unwrap();
            for (k, r) in results.iter().enumerate() {
                sum[k] += r.radiance;
                sum2[k] += r.radiance * r.radiance;
                reported[k] += r.variance;
            }
        }
        assert!(
            stats.shared_points >= 8 * N as u32,
            "case {case}: the points shared no cut ({stats:?})"
        );
        let (mut reported_total, mut measured_total) = (DVec3::ZERO, DVec3::ZERO);
        let n = N as f64;
        for k in 0..16 {
            let mean = sum[k] / n;
            let variance = (sum2[k] / n - mean * mean).max(DVec3::ZERO) * (n / (n - 1.0));
            let error = (variance / n).powf(0.5);
            let within = (mean - exact[k])
                .abs()
                .cmple(5.0 * error + 1e-12 * exact[k]);
            assert!(
                within.all(),
                "case {case}, point {k}: {mean} +- {error} against {}",
                exact[k]
            );
            reported_total += reported[k] / n;
            measured_total += variance;
        }
        let ratio = reported_total / measured_total;
        assert!(
            ratio.cmpge(DVec3::splat(1.0 / 1.5)).all() && ratio.cmple(DVec3::splat(1.5)).all(),
            "case {case}: reported variance {reported_total}, measured {measured_total}"
        );
    }
}

/// The batch's stochastic cut on bad and degenerate input: a results
/// slice of the wrong length and a NaN threshold are errors; an empty
/// batch, an empty tree and a shader whose cuts are not shared (Phong:
/// every point shaded on its own) give finite results, one per query.
#[test]
fn stochastic_batch_edge_cases() {
    use manylights::{ShadeError, Stochastic};
    let lights = city_lights(2_000, 3);
    let tree = LightTree::build(&lights).unwrap();
    let queries: Vec<Query> = (0..12)
        .map(|k| Query::new(Vec3::new(k as f32, 40.0, 0.0), Vec3::Z).unwrap())
        .collect();
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let mut short = vec![Stochastic::default(); 11];
    let t = Threshold::relative(0.2);
    assert!(matches!(
        shading.shade_stochastic_batch(&queries, t, Unoccluded, || 0.5, &mut short),
        Err(ShadeError::BatchLength { .. })
    ));
    let mut results = vec![Stochastic::default(); 12];
    assert!(
        shading
            .shade_stochastic_batch(
                &queries,
                Threshold::relative(f64::NAN),
                Unoccluded,
                || 0.5,
                &mut results
            )
            .is_err()
    );
    let stats = shading
        .shade_stochastic_batch::<manylights::query::NoView, _>(&[], t, Unoccluded, || 0.5, &mut [])
        .unwrap();
    assert_eq!(stats.shared_points + stats.points_alone, 0);

    let empty = LightTree::build(&[]).unwrap();
    let mut shading = empty.shading(Lambert::new(Vec3::ONE));
    shading
        .shade_stochastic_batch(&queries, t, Unoccluded, || 0.5, &mut results)
        .unwrap();
    assert!(
        results
            .iter()
            .all(|r| r.radiance == DVec3::ZERO && r.variance == DVec3::ZERO)
    );

    let phong = Phong::new(Vec3::splat(0.5), 4.0);
    let mut shading = tree.shading(phong);
    let queries: Vec<_> = queries
        .iter()
        .map(|q| q.with_view(Vec3::new(0.0, -1.0, 1.0)).unwrap())
        .collect();
    let mut u = 0.0f64;
    let stats = shading
        .shade_stochastic_batch(
            &queries,
            t,
            Unoccluded,
            || {
                u = (u + 0.618_034) % 1.0;
                u
            },
            &mut results,
        )
        .unwrap();
    assert_eq!(stats.points_alone, 12);
    assert!(
        results
            .iter()
            .all(|r| r.radiance.is_finite() && r.variance.is_finite())
    );
    assert!(results.iter().any(|r| r.radiance.x > 0.0));
}

/// Edge cases: an empty tree, one light (lit, behind the surface, on the
/// point), a scene wholly below the tangent plane, and `u` out of range.
#[test]
fn edge_cases() {
    let lambert = Lambert::new(Vec3::ONE);
    let query = Query::new(Vec3::ZERO, Vec3::Z).unwrap();

    let empty = LightTree::build(&[]).unwrap();
    let sampler = empty.sampler(lambert);
    assert_eq!(sampler.sample(&query, 0.5), None);
    assert_eq!(sampler.pmf(&query, 0), 0.0);
    let mut shading = empty.shading(lambert);
    let r = shading
        .shade_stochastic(&query, Threshold::relative(0.1), Unoccluded, || 0.5)
        .unwrap();
    assert_eq!(
        (r.radiance, r.variance, r.nodes_sampled),
        (DVec3::ZERO, DVec3::ZERO, 0)
    );

    // One light: probability 1 where it is lit, 0 where it is not.
    for (position, lit) in [
        (Vec3::new(1.0, 2.0, 3.0), true),
        (Vec3::new(1.0, 2.0, -3.0), false),
        (Vec3::ZERO, false),
        (Vec3::new(1.0, 2.0, 0.0), false),
    ] {
        let tree = LightTree::build(&[PointLight::new(position, Vec3::ONE)]).unwrap();
        let sampler = tree.sampler(lambert);
        let s = sampler.sample(&query, 0.3);
        assert_eq!(s.is_some(), lit, "{position}");
        assert_eq!(sampler.pmf(&query, 0), if lit { 1.0 } else { 0.0 });
        assert_eq!(sampler.pmf(&query, 1), 0.0);
    }

    // A light on the shading point contributes 0 and is never chosen, nor
    // are the lights in its tangent plane; the lights above share the
    // choice.
    let lights: Vec<PointLight> = (0..50)
        .map(|i| {
            PointLight::new(
                Vec3::new(i as f32 * 0.5, 0.0, 1.0 + (i % 2) as f32),
                Vec3::ONE,
            )
        })
        .collect();
    let tree = LightTree::builder()
        .max_leaf_lights(2)
        .build(&lights)
        .unwrap();
    let sampler = tree.sampler(lambert);
    let on = Query::new(lights[6].position, Vec3::Z).unwrap();
    for i in 0..lights.len() {
        let p = sampler.pmf(&on, i);
        assert_eq!(p > 0.0, i % 2 == 1, "light {i}: {p}");
    }
    let sum: f64 = (0..lights.len()).map(|i| sampler.pmf(&on, i)).sum();
    assert!((sum - 1.0).abs() <= 1e-12, "{sum}");

    // Everything below the tangent plane: the root's ball crosses the
    // plane, so the root is not certified dark, and the descent ends in
    // nodes whose children all are (dead ends, chosen evenly): whatever
    // `sample` returns contributes 0, its probability is still `pmf`'s and
    // the probabilities still sum to 1.
    let below: Vec<PointLight> = city_lights(2000, 1)
        .into_iter()
        .map(|l| PointLight::new(l.position * Vec3::new(1.0, 1.0, -1.0), l.intensity))
        .collect();
    let tree = LightTree::build(&below).unwrap();
    let sampler = tree.sampler(lambert);
    let ground = Query::new(Vec3::new(60.0, 60.0, 0.0), Vec3::Z).unwrap();
    let sum: f64 = (0..below.len()).map(|i| sampler.pmf(&ground, i)).sum();
    for u in [0.0, 0.5, 0.999] {
        match sampler.sample(&ground, u) {
            Some(s) => {
                let f = term(&lambert, ground.surface(), &below[s.light]);
                assert_eq!(f, DVec3::ZERO);
                assert_eq!(s.pmf.to_bits(), sampler.pmf(&ground, s.light).to_bits());
                assert!((sum - 1.0).abs() <= 1e-12, "{sum}");
            }
            None => assert_eq!(sum, 0.0),
        }
    }
    // Wholly below the plane and in it, as a node's lights in one plane
    // are known to be: certified dark at the root, nothing to sample.
    let flat: Vec<PointLight> = (0..500)
        .map(|i| PointLight::new(Vec3::new((i % 25) as f32, (i / 25) as f32, -2.0), Vec3::ONE))
        .collect();
    let tree = LightTree::build(&flat).unwrap();
    let sampler = tree.sampler(lambert);
    for u in [0.0, 0.5, 0.999] {
        assert_eq!(sampler.sample(&ground, u), None);
    }
    assert!((0..flat.len()).all(|i| sampler.pmf(&ground, i) == 0.0));

    // `u` out of range is clamped into [0, 1), NaN read as 0.
    let lights = city_lights(2000, 2);
    let tree = LightTree::build(&lights).unwrap();
    let sampler = tree.sampler(lambert);
    let q = Query::new(Vec3::new(60.0, 60.0, 0.0), Vec3::Z).unwrap();
    let one_below = 1.0 - f64::EPSILON / 2.0;
    assert_eq!(sampler.sample(&q, f64::NAN), sampler.sample(&q, 0.0));
    assert_eq!(sampler.sample(&q, -3.0), sampler.sample(&q, 0.0));
    assert_eq!(sampler.sample(&q, 1.0), sampler.sample(&q, one_below));
    assert_eq!(
        sampler.sample(&q, f64::INFINITY),
        sampler.sample(&q, one_below)
    );
    assert!(sampler.sample(&q, one_below).is_some());
}

/// Lights certified dark are never chosen while others may be lit: a
/// cluster below the tangent plane next to one above gets probability 0
/// in every light, and so does a cluster of no intensity.
#[test]
fn dark_nodes_are_never_chosen() {
    let mut lights = Vec::new();
    let mut rng = rng(21);
    for k in 0..3 {
        for _ in 0..200 {
            let offset = Vec3::new(
                rng.random::<f32>(),
                rng.random::<f32>(),
                rng.random::<f32>(),
            );
            let (centre, intensity) = match k {
                0 => (Vec3::new(0.0, 0.0, 5.0), Vec3::ONE),
                1 => (Vec3::new(40.0, 0.0, -6.0), Vec3::ONE),
                _ => (Vec3::new(-40.0, 0.0, 5.0), Vec3::ZERO),
            };
            lights.push(PointLight::new(centre + offset, intensity));
        }
    }
    let tree = LightTree::build(&lights).unwrap();
    let sampler = tree.sampler(Lambert::new(Vec3::ONE));
    let query = Query::new(Vec3::new(0.0, 0.0, 0.0), Vec3::Z).unwrap();
    for (i, light) in lights.iter().enumerate() {
        let p = sampler.pmf(&query, i);
        if light.position.z < 0.0 || light.intensity == Vec3::ZERO {
            assert_eq!(p, 0.0, "light {i}");
        } else {
            assert!(p > 0.0, "light {i}");
        }
    }
}

/// One sampler serves every thread.
#[test]
fn the_sampler_is_send_and_sync() {
    fn shared<T: Send + Sync>() {}
    shared::<LightSampler<'static, Lambert>>();
    shared::<LightSampler<'static, Combined<Lambert, Phong>>>();
}
