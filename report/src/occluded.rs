//! The occluded scenes, `city-shadows` and `canopy`: the exact shadowed
//! sum, the tree with the conservative shaft classifier ([`Shadows`]),
//! Monte Carlo with a shadow ray per sample, and Ward's adaptive shadow
//! testing, all through the same BVH of occluders.

use std::error::Error;

use glam::Vec3;
use manylights::{Coverage, Lambert, LightTree, NodeRegion, Threshold, Visibility};

use crate::bvh::Occluders;
use crate::config::{Config, OccludedSweeps, SOA_TOLERANCE};
use crate::measure::{Counted, Measurement, Method, Paired, Record, Sample, measure, paired};
use crate::scenes::{Scene, ShadingPoint};
use crate::shadowed::{ShadowLights, Ward};
use crate::shadows::Shadows;
use crate::sweep::{
    Bench, absolute_parameter, build_tree, measure_cut, median, print_header, query, recorder,
    references, sample_sweeps,
};

/// The relative threshold of the shadow targets (a certified 1%), at which
/// the tree is also timed in passes alternating with the exact shadowed sum,
/// and the host's visible fraction measured (on against off).
const TARGET_THRESHOLD: f64 = 0.01;
/// Rounds of alternating passes (one of each) of the shadow target.
const PAIRED_ROUNDS: usize = 5;

/// The host of each shading point: the shaft classifier and shadow rays
/// against `occluders`.
fn hosts<'o>(occluders: &'o Occluders) -> impl Fn(&ShadingPoint) -> Shadows<'o> + Sync + 'o {
    move |pt| Shadows::new(occluders, pt.normal)
}

/// The configurations `sweeps` of every method on an occluded scene, with
/// `occluders` the boxes that occlude; and the shadow target: the exact
/// shadowed sum (first) and the tree at a certified 1% (second) timed in
/// alternating passes.
pub fn run_occluded<'o>(
    scene: &Scene,
    occluders: &'o Occluders,
    cfg: &Config,
    sweeps: &OccludedSweeps,
) -> Result<(Vec<Record>, Paired), Box<dyn Error>> {
    let (tree, build) = build_tree(scene)?;
    print_header(scene, &tree, build);
    let shader = Lambert::new(scene.material.kd);
    let host = hosts(occluders);
    // The reference: the crate's exact shadowed sum (one shadow ray per
    // light); points no light reaches are dropped.
    let (points, refs) = references(&tree, shader, &scene.points, &host);
    let up = points.iter().filter(|p| p.normal.z > 0.5).count();
    let median_radiance = median(refs.iter().map(|r| r.max_element()).collect());
    println!(
        "  {} points ({up} facing up, {} sideways; {} dropped: unlit), {} occluders, median \
         exact shadowed radiance {median_radiance:.3e}",
        points.len(),
        points.len() - up,
        scene.points.len() - points.len(),
        occluders.len()
    );

    let mut rows = Vec::new();
    let mut record = recorder(scene.name, scene.lights.len(), &mut rows);
    let (light_count, budget) = (scene.lights.len() as u32, cfg.budget * sweeps.budget_factor);

    let mut soa = ShadowLights::new(&scene.lights, scene.material.kd);
    let m = measure(&refs, budget, |i| {
        let pt = &points[i];
        let (radiance, rays) = soa.exact(pt.point, pt.normal, &mut host(pt));
        Sample::estimate(radiance, light_count, Some(rays))
    });
    if !(m.max_error <= SOA_TOLERANCE) {
        return Err(format!(
            "{}: the exact shadowed sum differs from exact_query with the host by {:.2e} relative",
            scene.name, m.max_error
        )
        .into());
    }
    let m_exact = m.seconds_per_point;
    record(Method::ExactShadowed, "-".into(), m);

    let occluded: Option<&dyn Fn(&ShadingPoint) -> Shadows<'o>> = Some(&host);
    let bench = Bench::new(&points, &refs, budget);
    let cut = |threshold| measure_cut(&tree, shader, bench, threshold, occluded);
    let mut certified = None;
    for &t in sweeps.relative {
        let m = cut(Threshold::relative(t));
        if t == TARGET_THRESHOLD {
            certified = Some(m);
        }
        record(Method::TreeRelative, format!("t={t}"), m);
    }
    if let Some(without) = certified {
        // The host's visible fraction, measured where the targets are
        // stated: five rays per partial answer.
        let with_fraction =
            |pt: &ShadingPoint| Shadows::new(occluders, pt.normal).with_visible_fraction();
        let fraction: Option<&dyn Fn(&ShadingPoint) -> Shadows<'o>> = Some(&with_fraction);
        let with = measure_cut(
            &tree,
            shader,
            bench,
            Threshold::relative(TARGET_THRESHOLD),
            fraction,
        );
        let rays = |m: &Measurement| m.queries.map_or(f64::NAN, |q| q.0);
        println!(
            "  visible fraction on at t={TARGET_THRESHOLD}: {:.2} us/pt ({:.2}x the host without \
             it), {:.0} shadow rays/pt (vs {:.0}), mean error {:.2e} (vs {:.2e}), max {:.2e} (vs \
             {:.2e})",
            with.seconds_per_point * 1e6,
            with.seconds_per_point / without.seconds_per_point,
            rays(&with),
            rays(&without),
            with.mean_error,
            without.mean_error,
            with.max_error,
            without.max_error
        );
    }
    for &f in sweeps.absolute {
        let m = cut(Threshold::absolute(f * median_radiance));
        record(Method::TreeAbsolute, absolute_parameter(f), m);
    }
    for &t in sweeps.per_node {
        record(
            Method::PerNode,
            format!("t={t}"),
            cut(Threshold::per_node(t)),
        );
    }

    sample_sweeps(&mut record, &tree, &shader, bench, sweeps.samples, occluded);

    let mut shading = tree.shading(shader);
    let target = paired(
        points.len(),
        PAIRED_ROUNDS,
        |i| {
            let pt = &points[i];
            let (radiance, rays) = soa.exact(pt.point, pt.normal, &mut host(pt));
            Sample::estimate(radiance, light_count, Some(rays))
        },
        |i| {
            let pt = &points[i];
            let mut h = host(pt);
            let t = Threshold::relative(TARGET_THRESHOLD);
            let r = shading.shade_query(&query(pt), t, &mut h);
            Sample::cut(r.expect("valid threshold"), Some(h.queries()))
        },
    );
    println!(
        "  shadow target, {} alternating passes: tree at t={TARGET_THRESHOLD} {:.2} us/pt, \
         exact shadowed sum {:.2} us/pt, tree / exact {:.3} (median of the rounds' ratios)",
        target.rounds,
        target.second * 1e6,
        target.first * 1e6,
        target.ratio
    );
    let cut_alone = replayed_cut(&tree, shader, bench, &host);
    println!(
        "  the cut alone at t={TARGET_THRESHOLD}, the host's answers replayed: {:.2} us/pt \
         ({:.2}x the exact shadowed sum's fastest pass)",
        cut_alone * 1e6,
        cut_alone / m_exact
    );

    let mut ward = Ward::default();
    for &t in sweeps.ward {
        let m = measure(&refs, budget, |i| {
            let pt = &points[i];
            let (radiance, rays) = ward.shade(&mut soa, pt.point, pt.normal, t, &mut host(pt));
            Sample::estimate(radiance, light_count, Some(rays))
        });
        record(Method::Ward, format!("t={t}"), m);
    }
    drop(record);
    Ok((rows, target))
}

/// The host's answers at one shading point, in the order the cut asked.
#[derive(Default)]
struct Answers {
    coverage: Vec<Coverage>,
    visible: Vec<bool>,
}

/// A host that records `inner`'s answers.
struct Recording<V> {
    inner: V,
    answers: Answers,
}

impl<V: Visibility> Visibility for Recording<V> {
    fn classify(&mut self, point: Vec3, node: &NodeRegion) -> Coverage {
        let c = self.inner.classify(point, node);
        self.answers.coverage.push(c);
        c
    }

    fn visible(&mut self, point: Vec3, light: Vec3) -> bool {
        let v = self.inner.visible(point, light);
        self.answers.visible.push(v);
        v
    }

    fn visible_fraction(&mut self, point: Vec3, node: &NodeRegion) -> Option<f32> {
        self.inner.visible_fraction(point, node)
    }
}

/// A host that answers from a recording, at no cost: the cut, asking the
/// same questions in the same order, gets the same answers.
struct Replay<'a> {
    answers: &'a Answers,
    next: (usize, usize),
}

impl Visibility for Replay<'_> {
    fn classify(&mut self, _: Vec3, _: &NodeRegion) -> Coverage {
        self.next.0 += 1;
        self.answers.coverage[self.next.0 - 1]
    }

    fn visible(&mut self, _: Vec3, _: Vec3) -> bool {
        self.next.1 += 1;
        self.answers.visible[self.next.1 - 1]
    }
}

/// Seconds per point of the cut at the target threshold with the host's
/// answers replayed: what the tree costs besides its host.
fn replayed_cut<'o>(
    tree: &LightTree,
    shader: Lambert,
    bench: Bench<'_>,
    host: &impl Fn(&ShadingPoint) -> Shadows<'o>,
) -> f64 {
    let threshold = Threshold::relative(TARGET_THRESHOLD);
    let mut shading = tree.shading(shader);
    let recorded: Vec<Answers> = bench
        .points
        .iter()
        .map(|pt| {
            let mut recording = Recording {
                inner: host(pt),
                answers: Answers::default(),
            };
            let r = shading.shade_query(&query(pt), threshold, &mut recording);
            r.expect("valid threshold");
            recording.answers
        })
        .collect();
    let m = measure(bench.refs, bench.budget, |i| {
        let pt = &bench.points[i];
        let replay = Replay {
            answers: &recorded[i],
            next: (0, 0),
        };
        let r = shading.shade_query(&query(pt), threshold, replay);
        Sample::cut(r.expect("valid threshold"), None)
    });
    m.seconds_per_point
}
