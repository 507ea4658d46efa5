//! Error against run time: the light hierarchy and its baselines on the same
//! scenes, in one run, after the ground scene's evaluations-per-point table.
//!
//! ```text
//! cargo run --release -p manylights-report                    # full report (see below)
//! cargo run --release -p manylights-report -- --quick         # smoke run, seconds
//! cargo run --release -p manylights-report -- city scaling    # only some parts
//! cargo run --release -p manylights-report -- batch           # batch shading of a camera view
//! cargo run --release -p manylights-report -- shadows         # the occluded scenes alone
//! cargo run --release -p manylights-report -- city-shadows --shadow-lights 100000
//! cargo run --release -p manylights-report -- anatomy         # where a cut's work goes
//! cargo run --release -p manylights-report -- ggx             # GGX against Phong and the exact sum
//! cargo run --release -p manylights-report -- sampling        # light sampling for path tracers
//! cargo run --release -p manylights-report -- stochastic-batch # the stochastic cut over an image
//! cargo run --release -p manylights-report -- emitters        # spot lights and virtual point lights
//! cargo run --release -p manylights-report -- roofs           # roof points among the lamps
//! cargo run --release -p manylights-report -- hostile         # scenes built to defeat the tree
//! ```
//!
//! The full report takes about a minute on 2 cores, plus about two minutes
//! for the batch part (at 10^6 lights; its exact sums dominate).
//!
//! Parts: `evaluations` (the ground scene's evaluations per point), `bounds`
//! (the Lambert bounds on the coloured street city, with build time and
//! memory), `batch` (a camera's view of the street city at 10^6 lights, 10^5
//! with `--quick`, at 320x180 and 1280x720, shaded by one `shade_batch`
//! call per threshold against the SIMD exact sum, and the seams along a
//! scanline), `city`, `chandelier`,
//! `strings`, `specular` (threshold sweeps on unoccluded scenes),
//! `city-shadows`, `canopy` and `city-mesh` (the occluded scenes, the last
//! the city's buildings as triangles under `manylights-mesh`'s host, per
//! point and through the batch call; `shadows` names all three)
//! and `scaling` (time against number of lights); no part named means all
//! of these. `anatomy` (where a certified cut's work goes on the street
//! city at 10^4 to 10^6 lights: refinements, bounded children by depth and
//! distance, the final entries' errors and how loose their bounds are)
//! runs only when named, as do `ggx` (the GGX shader at a certified 1%
//! on the street city, 10^4 to 10^6 lights, against Phong of the matching
//! lobe and the vectorized exact GGX sum, [`manylights_report::ggx`]) and
//! `sampling` (one light per shading point by the crate's `LightSampler`
//! against power sampling, pbrt-v4's and Cycles' importances on the same
//! tree, and the stochastic cut; a few minutes), `stochastic-batch` (the
//! stochastic cut over the batch part's camera view, pixel by pixel against
//! the batch call sharing its cut, [`manylights_report::stochastic_batch`]),
//! `emitters` (spot lights on the street city and instant radiosity's
//! virtual point lights in a room, per point and per pixel,
//! [`manylights_report::emitters`]) and `roofs` (the certified cut on the street city's ground, façades and
//! roofs inside the lamps' layer, 10^5 and 10^6 lights, one core, against
//! the vectorized exact sum, [`manylights_report::roofs`]; under a minute)
//! and `hostile` (scenes built to defeat the tree, single points and the
//! batch call against the vectorized exact sum,
//! [`manylights_report::hostile`]; about a minute).
//! `--shadow-lights N` sets the occluded city's number of lights (20,000);
//! `--roof-lights N` (repeatable) the roofs part's (10^5 and 10^6). Writes
//! to `out/report/` under the repository root:
//!
//! * `errors.csv`, one row per scene and configuration (in occluded scenes
//!   with the mean shadow rays and node classifications per point), and
//!   `error_vs_time_<scene>.svg` (x: time per shading point, y: actual
//!   relative error against the exact sum, max and mean panels, log-log; the
//!   crate's certified bound as dashed series);
//! * `scaling.csv` and `scaling.svg` (time per shading point against number
//!   of lights, city layout at fixed density);
//! * `batch.csv`, `batch_seams.csv`, `batch_seams_points.csv`,
//!   `batch_tree.png` and `batch_small_{tree,exact,diff}.png` (the batch
//!   part, [`manylights_report::batch`]);
//! * a Markdown summary on standard output.
//!
//! The methods, (a) to (g), and how errors and times are measured are
//! printed at the top of the output ([`METHODS`]).

use std::error::Error;
use std::fs;
use std::path::Path;
use std::time::Instant;

use manylights_report::anatomy::print_anatomy;
use manylights_report::batch::{BATCH, FULL_BATCH, QUICK_BATCH, run_batch};
use manylights_report::bounds::print_bounds_table;
use manylights_report::config::{
    self, CANOPY, CANOPY_SWEEPS, CITY_SHADOWS_SWEEPS, FULL, OCCLUDED_NAMES, PAPER_RELATIVE,
    PER_NODE, QUICK, SAMPLE_COUNTS, SCALING, SCENE_NAMES, SEED, SHADOW_PER_NODE, SHADOW_RELATIVE,
    SHADOWS, TREE_ABSOLUTE, TREE_RELATIVE, WARD,
};
use manylights_report::csv::{write_csv, write_scaling_csv};
use manylights_report::emitters::{EMITTERS, run_emitters};
use manylights_report::evaluations::print_evaluations_table;
use manylights_report::ggx::print_ggx;
use manylights_report::hostile::{HOSTILE, run_hostile};
use manylights_report::light_sampling::{SAMPLING, run_sampling};
use manylights_report::measure::MAX_PASSES;
use manylights_report::mesh_city::{CITY_MESH, run_city_mesh};
use manylights_report::occluded::run_occluded;
use manylights_report::plot::{plot_scaling, plot_scene};
use manylights_report::roofs::{QUICK_SIZES, ROOFS, SIZES as ROOF_SIZES, run_roofs};
use manylights_report::scaling::run_scaling;
use manylights_report::scenes::{canopy, city_shadows};
use manylights_report::stochastic_batch::{STOCHASTIC_BATCH, run_stochastic_batch};
use manylights_report::summary::summary;
use manylights_report::sweep::run_scene;

/// The ground scene's table, as a part.
const EVALUATIONS: &str = "evaluations";
/// The Lambert bounds on the coloured street city, as a part.
const BOUNDS: &str = "bounds";
/// Where a certified cut's work goes, as a part run only when named.
const ANATOMY: &str = "anatomy";
/// The GGX shader against Phong and the exact sum, as a part run only
/// when named.
const GGX: &str = "ggx";

fn main() -> Result<(), Box<dyn Error>> {
    let started = Instant::now();
    let mut quick = false;
    let mut shadow_lights = None;
    let mut roof_lights = Vec::new();
    let mut parts = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--quick" => quick = true,
            "--shadow-lights" => {
                let n = args.next().and_then(|n| n.parse().ok());
                shadow_lights = Some(n.ok_or("--shadow-lights needs a number of lights")?);
            }
            "--roof-lights" => {
                let n = args.next().and_then(|n| n.parse().ok());
                roof_lights.push(n.ok_or("--roof-lights needs a number of lights")?);
            }
            SHADOWS => {
                parts.extend(OCCLUDED_NAMES.map(String::from));
                parts.push(CITY_MESH.into());
            }
            name if SCENE_NAMES.contains(&name)
                || OCCLUDED_NAMES.contains(&name)
                || [
                    EVALUATIONS,
                    BOUNDS,
                    BATCH,
                    SCALING,
                    ANATOMY,
                    CITY_MESH,
                    GGX,
                    SAMPLING,
                    STOCHASTIC_BATCH,
                    EMITTERS,
                    ROOFS,
                    HOSTILE,
                ]
                .contains(&name) =>
            {
                parts.push(arg)
            }
            _ => {
                return Err(format!(
                    "unknown argument {arg:?}; usage: report [--quick] [--shadow-lights N] \
                     [--roof-lights N]... [{EVALUATIONS} | {BOUNDS} | {BATCH} | {} | {} | \
                     {CITY_MESH} | {SHADOWS} | {SCALING} | {ANATOMY} | {GGX} | {SAMPLING} | \
                     {STOCHASTIC_BATCH} | {EMITTERS} | {ROOFS} | {HOSTILE}]...",
                    SCENE_NAMES.join(" | "),
                    OCCLUDED_NAMES.join(" | ")
                )
                .into());
            }
        }
    }
    let named = |part: &str| parts.iter().any(|p| p == part);
    let wanted = |part: &str| parts.is_empty() || named(part);
    let mut cfg = if quick { QUICK } else { FULL };
    if let Some(n) = shadow_lights {
        cfg.shadow_lights = n;
    }
    let cfg = &cfg;
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../out/report");
    fs::create_dir_all(&out)?;

    println!(
        "# manylights: error against run time{}\n",
        if quick { " (--quick)" } else { "" }
    );
    if wanted(EVALUATIONS) {
        print_evaluations_table()?;
    }
    if wanted(BOUNDS) && !quick {
        print_bounds_table()?;
    }
    if wanted(BATCH) {
        run_batch(if quick { QUICK_BATCH } else { FULL_BATCH }, &out)?;
    }
    if named(ANATOMY) {
        print_anatomy()?;
    }
    if named(GGX) {
        print_ggx()?;
    }
    if named(SAMPLING) {
        run_sampling(quick)?;
    }
    if named(STOCHASTIC_BATCH) {
        run_stochastic_batch(quick)?;
    }
    if named(EMITTERS) {
        run_emitters(quick)?;
    }
    if named(ROOFS) {
        let sizes: &[usize] = match (roof_lights.is_empty(), quick) {
            (false, _) => &roof_lights,
            (true, true) => &QUICK_SIZES,
            (true, false) => &ROOF_SIZES,
        };
        run_roofs(sizes, quick)?;
    }
    if named(HOSTILE) {
        run_hostile(quick)?;
    }
    if !parts.is_empty()
        && parts.iter().all(|p| {
            [
                ANATOMY,
                GGX,
                SAMPLING,
                STOCHASTIC_BATCH,
                EMITTERS,
                ROOFS,
                HOSTILE,
            ]
            .contains(&p.as_str())
        })
    {
        return Ok(());
    }
    println!("{METHODS}");
    println!(
        "Time per point = fastest of up to {MAX_PASSES} passes over all points (repeated while \
         within {} ms per configuration), divided by the number of points: each \
         configuration timed with its data warm in the caches. The scaling part also times the \
         exact sum and the tree at a certified 1% in alternating passes (medians over the rounds, \
         the speed-up the median of the rounds' ratios): each pass then finds the other's data in \
         the caches, and a load that drifts during the run moves both alike. Other processes \
         share the machine: expect some noise.\n",
        cfg.budget.as_millis()
    );
    println!(
        "Shading points per scene: {}. Threshold sweeps: tight bound relative {TREE_RELATIVE:?} and \
         absolute {TREE_ABSOLUTE:?} x median radiance; paper's bound relative {PAPER_RELATIVE:?}; \
         per-node {PER_NODE:?}; Monte Carlo samples {SAMPLE_COUNTS:?}. Occluded city: tight \
         bound relative {SHADOW_RELATIVE:?} and absolute {TREE_ABSOLUTE:?} x median radiance; \
         per-node {SHADOW_PER_NODE:?}; Monte Carlo samples {SAMPLE_COUNTS:?}; Ward {WARD:?}. \
         Canopy ({} points): tight bound relative {:?}; Ward {:?}.\n",
        cfg.points, cfg.canopy_points, CANOPY_SWEEPS.relative, CANOPY_SWEEPS.ward
    );

    let mut records = Vec::new();
    let mut targets = Vec::new();
    for name in SCENE_NAMES.into_iter().filter(|n| wanted(n)) {
        let scene = config::make_scene(name, cfg);
        let rows = run_scene(&scene, cfg)?;
        let path = out.join(format!("error_vs_time_{}.svg", scene.name));
        plot_scene(&path, &scene, &rows)?;
        println!("  plot: {}\n", path.display());
        records.extend(rows);
    }
    for name in OCCLUDED_NAMES.into_iter().filter(|n| wanted(n)) {
        let (scene, occluders, sweeps) = if name == CANOPY {
            let (scene, leaves) = canopy(cfg.canopy_lights, cfg.canopy_points, SEED);
            (scene, leaves, &CANOPY_SWEEPS)
        } else {
            let (scene, city) = city_shadows(cfg.shadow_lights, cfg.points, SEED);
            (scene, city.occluders, &CITY_SHADOWS_SWEEPS)
        };
        let (rows, target) = run_occluded(&scene, &occluders, cfg, sweeps)?;
        targets.push((name, target));
        let path = out.join(format!("error_vs_time_{name}.svg"));
        plot_scene(&path, &scene, &rows)?;
        println!("  plot: {}\n", path.display());
        records.extend(rows);
    }
    if wanted(CITY_MESH) {
        run_city_mesh(cfg, quick)?;
        println!();
    }
    if !records.is_empty() {
        write_csv(&out.join("errors.csv"), &records)?;
    }

    let scaling = if wanted(SCALING) {
        let rows = run_scaling(cfg)?;
        write_scaling_csv(&out.join("scaling.csv"), &rows)?;
        plot_scaling(&out.join("scaling.svg"), &rows)?;
        println!("  plot: {}\n", out.join("scaling.svg").display());
        rows
    } else {
        Vec::new()
    };

    print!("{}", summary(&records, &scaling, &targets));
    println!("\nTotal run time: {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// The methods paragraph printed at the top (the crate docs of
/// `manylights_report` list the same modules).
const METHODS: &str = "\
Methods (all single-threaded, same shading points, errors against the crate's f64 exact_query,
with the host's shadow rays in the occluded scenes):
(a) exact sum written to vectorize: f32 structure-of-arrays in chunks of 8, auto-vectorized,
    f64 flush every 1024 lights; plotted at its measured f32 rounding error (no 0 on a log axis).
    Like the crate's own kernels, it runs a copy compiled for AVX2 where the processor has it
    (picked at run time; the same bits as the SSE2 copy of a default x86-64 build, which takes
    about 1.17x its time on the street city at 10^4 lights and 1.1x at 10^6).
    Occluded scenes: the exact shadowed sum, one any-hit shadow ray per light above the tangent
    plane (unoccluded terms vectorized the same way), through the obvhs BVH of the occluders.
(b) the crate's cut with the paper's first-order bound (BoundKind::Paper), relative thresholds.
(c) the crate's cut with its tightest bound (default), relative and absolute thresholds;
    occluded scenes: shade_query with the shaft classifier (Haines & Wallace 1994) and shadow
    rays of `Shadows`, through the same BVH; every classification and ray is timed and counted.
(d) the crate's cut with Lightcuts' per-node criterion (Threshold::per_node): refine the node of
    largest error until it is below t x estimate (t = 5%..0.5% around Lightcuts' 2%, plus 0.2% and
    0.1% to reach 1% max error; 2%..0.01% in the occluded scene); certified bound reported
    (dashed), not held to t.
(e) Monte Carlo light sampling proportional to power (Shirley et al. 1996), alias table.
(f) importance sampling down the light tree (pbrt-v4 / Conty & Kulla 2018): child chosen by
    weight x max cos / max(D^2, R^2), leaf light by contribution.
    Occluded scenes: (e) and (f) cast one shadow ray per sample.
(g) Ward 1991 adaptive shadow testing, occluded scenes only: all unoccluded contributions,
    shadow rays in decreasing order until the untested remainder < t x visible sum so far,
    remainder added x hit rate (visible / tested lights, as Radiance's direct()).
Relative error = max channel |L - exact| / max channel exact.
";
