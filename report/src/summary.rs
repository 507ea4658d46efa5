//! The summary printed at the end of the report: speed-ups at 1% max
//! error, the cheapest configuration of each method, the shadow targets and
//! the visibility work in the occluded scenes, and where a baseline beats
//! the tree.

use std::fmt::Write as _;

use crate::config::{
    CANOPY, OCCLUDED, OCCLUDED_NAMES, SCALING_RELATIVE, SCENE_NAMES, TARGET_ERROR, USEFUL_ERROR,
};
use crate::measure::{Measurement, Method, Paired, Record};
use crate::scaling::ScalingRow;

/// The cheapest record of `method` whose max error is at most `error`.
fn cheapest<'r>(records: impl Iterator<Item = &'r Record>, error: f64) -> Option<&'r Record> {
    records
        .filter(|r| r.measurement.max_error <= error)
        .min_by(|a, b| {
            a.measurement
                .seconds_per_point
                .total_cmp(&b.measurement.seconds_per_point)
        })
}

/// `12.3 us (rel t=0.1)`-style cell for a record, with its speed-up over
/// `exact_seconds`.
fn speedup_cell(r: Option<&Record>, exact_seconds: f64) -> String {
    match r {
        Some(r) => format!(
            "{:.1}x ({:.2} us, {} {})",
            exact_seconds / r.measurement.seconds_per_point,
            r.measurement.seconds_per_point * 1e6,
            r.method.id(),
            r.parameter
        ),
        None => "not reached".into(),
    }
}

/// Where a baseline beats the tree: configurations with error (by `error`)
/// at most [`USEFUL_ERROR`] that run faster than every best-tree
/// configuration of the same scene with at most that error.
fn beats(records: &[Record], method: Method, error: fn(&Measurement) -> f64) -> Vec<String> {
    let tree: Vec<&Record> = records.iter().filter(|r| r.method.is_best_tree()).collect();
    records
        .iter()
        .filter(|r| r.method == method && error(&r.measurement) <= USEFUL_ERROR)
        .filter_map(|r| {
            let e = error(&r.measurement);
            let t = r.measurement.seconds_per_point;
            let tree_best = tree
                .iter()
                .filter(|x| error(&x.measurement) <= e)
                .map(|x| x.measurement.seconds_per_point)
                .fold(f64::INFINITY, f64::min);
            (t < tree_best).then(|| {
                let vs = if tree_best.is_finite() {
                    format!("{:.2} us", tree_best * 1e6)
                } else {
                    "none reaches it".into()
                };
                format!(
                    "{} (err {e:.1e}, {:.2} us vs tree {vs})",
                    r.parameter,
                    t * 1e6
                )
            })
        })
        .collect()
}

/// Time per point of the exact sum (the shadowed one in an occluded scene)
/// among `records`.
fn exact_time<'r>(records: impl IntoIterator<Item = &'r Record>) -> f64 {
    records
        .into_iter()
        .find(|r| r.method.is_exact())
        .map_or(f64::NAN, |r| r.measurement.seconds_per_point)
}

/// The summary of `records` (every scene), `scaling` (every size) and the
/// occluded scenes' shadow `targets` (timed in alternating passes) as
/// Markdown.
pub fn summary(records: &[Record], scaling: &[ScalingRow], targets: &[(&str, Paired)]) -> String {
    let mut s = String::from("## Summary\n\n");
    let _ = writeln!(
        s,
        "Speed-up = time of (a), the exact sum (vectorized; in {OCCLUDED} and {CANOPY} the exact \
         shadowed sum, one shadow ray per light), over the time of the cheapest configuration whose measured \
         max relative error over all points is <= {}% (no interpolation).\n",
        TARGET_ERROR * 100.0
    );
    s.push_str("| quantity | value |\n|---|---|\n");
    if let Some(largest) = scaling.last() {
        let exact = exact_time(&largest.records);
        let best = cheapest(
            largest.records.iter().filter(|r| r.method.is_best_tree()),
            TARGET_ERROR,
        );
        let _ = writeln!(
            s,
            "| speed-up of the tree (tight bound) at <= 1% max error, city {} lights (scaling \
             part) | {} |",
            largest.lights,
            speedup_cell(best, exact)
        );
        for row in scaling {
            let _ = writeln!(
                s,
                "| speed-up of the tree (tight bound) at t = {SCALING_RELATIVE}, certified, city {} \
                 lights, alternating passes | {:.1}x (median of {} rounds) |",
                row.lights,
                1.0 / row.alternating.ratio,
                row.alternating.rounds
            );
        }
        // The tree's time per point at the largest size against 10^4
        // lights, and per evaluation at the largest size, both from the
        // alternating passes.
        if let Some(small) = scaling.iter().find(|r| r.lights == 10_000)
            && largest.lights > small.lights
        {
            let _ = writeln!(
                s,
                "| time per point of the tree at t = {SCALING_RELATIVE}, city {} lights against {} \
                 lights, alternating passes | {:.1}x ({:.2} against {:.2} us) |",
                largest.lights,
                small.lights,
                largest.alternating.second / small.alternating.second,
                largest.alternating.second * 1e6,
                small.alternating.second * 1e6
            );
        }
        let relative = format!("t={SCALING_RELATIVE}");
        if let Some(cut) = largest
            .records
            .iter()
            .find(|r| r.method == Method::TreeRelative && r.parameter == relative)
            .filter(|r| r.measurement.mean_cost > 0.0)
        {
            let evaluations = cut.measurement.mean_cost;
            let _ = writeln!(
                s,
                "| time per evaluation of the tree at t = {SCALING_RELATIVE}, city {} lights, \
                 alternating passes | {:.1} ns ({:.0} evaluations per point) |",
                largest.lights,
                largest.alternating.second * 1e9 / evaluations,
                evaluations
            );
        }
        let _ = writeln!(
            s,
            "| vectorized exact sum, city {} lights | {:.1} us per point |",
            largest.lights,
            exact * 1e6
        );
        let _ = writeln!(
            s,
            "| build time per light, {} lights | {:.0} ns |",
            largest.lights,
            largest.build.as_secs_f64() * 1e9 / largest.lights as f64
        );
        let _ = writeln!(
            s,
            "| memory per light, {} lights | {:.1} bytes |",
            largest.lights,
            largest.memory as f64 / largest.lights as f64
        );
    }
    let scene_names: Vec<&str> = SCENE_NAMES
        .into_iter()
        .chain(OCCLUDED_NAMES)
        .filter(|n| records.iter().any(|r| r.scene == *n))
        .collect();
    let of_scene =
        |name: &str| -> Vec<&Record> { records.iter().filter(|r| r.scene == name).collect() };
    for name in &scene_names {
        let rs = of_scene(name);
        let exact = exact_time(rs.iter().copied());
        let best = cheapest(
            rs.iter().copied().filter(|r| r.method.is_best_tree()),
            TARGET_ERROR,
        );
        let over = if OCCLUDED_NAMES.contains(name) {
            " (over the exact shadowed sum)"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "| speed-up of the tree (tight bound) at <= 1% max error{over}, {name} {} lights | {} |",
            rs[0].lights,
            speedup_cell(best, exact)
        );
    }
    if scene_names.is_empty() {
        return s;
    }

    s.push_str(
        "\n### Cheapest configuration of each method with max relative error <= 1%\n\n\
         Cells: speed-up over the scene's exact sum (time per point, configuration); `-` where \
         the method is not run on the scene.\n\n",
    );
    let _ = writeln!(s, "| method | {} |", scene_names.join(" | "));
    let _ = writeln!(s, "|---|{}", "---|".repeat(scene_names.len()));
    for method in Method::ALL {
        let mut line = format!("| {} |", method.label());
        for name in &scene_names {
            let rs = of_scene(name);
            let exact = exact_time(rs.iter().copied());
            let mut runs = rs.iter().copied().filter(|r| r.method == method).peekable();
            let cell = if runs.peek().is_none() {
                "-".to_string()
            } else {
                speedup_cell(cheapest(runs, TARGET_ERROR), exact)
            };
            let _ = write!(line, " {cell} |");
        }
        s.push_str(&line);
        s.push('\n');
    }

    for name in OCCLUDED_NAMES
        .into_iter()
        .filter(|n| scene_names.contains(n))
    {
        let target = targets.iter().find(|(n, _)| *n == name).map(|(_, t)| t);
        s.push_str(&shadow_target(name, &of_scene(name), target));
        s.push_str(&visibility_work(name, &of_scene(name)));
    }

    let _ = writeln!(
        s,
        "\n### Does a baseline beat the tree anywhere on the curve?\n\n\
         A baseline configuration beats the tree when it runs faster than every tight-bound tree \
         configuration (relative or absolute threshold) of the same scene whose measured error is at most its own; only configurations with error <= {}% \
         count. The per-node criterion (d) is the crate's own uncertified mode, listed here \
         too.\n",
        USEFUL_ERROR * 100.0
    );
    s.push_str("| baseline | scene | by max error | by mean error |\n|---|---|---|---|\n");
    for method in Method::ALL.into_iter().filter(|m| !m.is_best_tree()) {
        for name in &scene_names {
            let rs: Vec<Record> = of_scene(name).into_iter().cloned().collect();
            if !rs.iter().any(|r| r.method == method) {
                continue;
            }
            let cell = |v: Vec<String>| {
                if v.is_empty() {
                    "no".to_string()
                } else {
                    format!("yes: {}", v.join("; "))
                }
            };
            let _ = writeln!(
                s,
                "| {} | {name} | {} | {} |",
                method.label(),
                cell(beats(&rs, method, |m| m.max_error)),
                cell(beats(&rs, method, |m| m.mean_error))
            );
        }
    }
    s
}

/// The relative threshold the shadow targets are stated at: a certified 1%.
const CERTIFIED: &str = "t=0.01";

/// An occluded scene's target rows: the tree at a certified 1% against the
/// exact shadowed sum, with every classification and shadow ray counted;
/// times from the alternating passes of `target` when there are any.
fn shadow_target(name: &str, rs: &[&Record], target: Option<&Paired>) -> String {
    let exact = rs.iter().find(|r| r.method == Method::ExactShadowed);
    let tree = rs
        .iter()
        .find(|r| r.method == Method::TreeRelative && r.parameter == CERTIFIED);
    let time = |r: Option<&&Record>| r.map_or(f64::NAN, |r| r.measurement.seconds_per_point);
    let (exact_time, tree_time, ratio, timing) = match target {
        Some(t) => (
            t.first,
            t.second,
            t.ratio,
            format!("median of {} alternating passes", t.rounds),
        ),
        None => (
            time(exact),
            time(tree),
            time(tree) / time(exact),
            "fastest pass".into(),
        ),
    };
    let mut s = format!(
        "\n### {name}: the tree at a certified 1% against the exact shadowed sum\n\n\
         Times per point: {timing}; tree / exact: median of the rounds' ratios.\n\n\
         | method | time per point | tree / exact | classifications per point | shadow rays per \
         point | max / mean error | max certified bound |\n|---|---|---|---|---|---|---|\n"
    );
    for (label, r, t, q) in [
        ("(a) exact shadowed sum", exact, exact_time, 1.0),
        ("(c) tree, relative 1% (certified)", tree, tree_time, ratio),
    ] {
        let Some(r) = r else { continue };
        let m = &r.measurement;
        let (rays, classify) = m.queries.unwrap_or((f64::NAN, f64::NAN));
        let bound = m.bound.map_or("-".into(), |(_, max)| format!("{max:.1e}"));
        let _ = writeln!(
            s,
            "| {label} | {:.1} us | {q:.3} | {classify:.1} | {rays:.1} | {:.1e} / {:.1e} | {bound} |",
            t * 1e6,
            m.max_error,
            m.mean_error
        );
    }
    s
}

/// An occluded scene's visibility work: the cheapest configuration of each
/// method with max relative error at most 1%.
fn visibility_work(name: &str, rs: &[&Record]) -> String {
    let exact = exact_time(rs.iter().copied());
    let mut s = format!(
        "\n### {name}: visibility work of the cheapest configuration with max relative error \
         <= 1%\n\n\
         | method | configuration | time per point | speed-up | max / mean error | shadow rays \
         per point | classify queries per point |\n|---|---|---|---|---|---|---|\n"
    );
    for method in Method::ALL {
        let mut runs = rs.iter().copied().filter(|r| r.method == method).peekable();
        if runs.peek().is_none() {
            continue;
        }
        match cheapest(runs, TARGET_ERROR) {
            Some(r) => {
                let m = &r.measurement;
                let (rays, classify) = m.queries.unwrap_or((f64::NAN, f64::NAN));
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.1} us | {:.2}x | {:.1e} / {:.1e} | {rays:.0} | {classify:.0} |",
                    method.label(),
                    r.parameter,
                    m.seconds_per_point * 1e6,
                    exact / m.seconds_per_point,
                    m.max_error,
                    m.mean_error
                );
            }
            None => {
                let _ = writeln!(s, "| {} | not reached | | | | | |", method.label());
            }
        }
    }
    s
}
