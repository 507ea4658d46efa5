//! The batch part: a camera's image of the street city shaded through
//! [`Shading::shade_batch`](manylights::Shading::shade_batch), one call
//! over every ground pixel, against the SIMD exact sum per pixel; and the
//! seams a shared cut leaves along a scanline.
//!
//! Scene: the street lamps of [`city_lights`] (10^6, or 10^5 with
//! `--quick`), seen from a camera 30 units above the streets in the middle
//! of the city, looking down the ground at an angle (ground from about 40
//! units away to the horizon, past the city's far edge, and a strip of sky
//! at the top). Every
//! pixel whose ray hits the ground plane `z = 0` is a query (normal `+z`,
//! Lambert with unit albedo); sky pixels are black and not shaded.
//!
//! For each relative threshold of [`THRESHOLDS`]: the batch call over all
//! ground pixels (median of five runs, one core), the SIMD exact sum
//! and the single-point `shade_query` on a fixed grid of sampled pixels
//! spread over the image, the largest actual relative error over the
//! sampled pixels against the crate's `f64` `exact_query`, and the
//! certified bound checked there (the part fails if a pixel breaks it).
//! The sweep runs twice: at 320x180 (with the single-point comparison, the
//! threads and the images) and for the same shot at 1280x720 ([`HIGH`]),
//! where each group of points covers a smaller patch of ground.
//!
//! Seams: [`SEAM_POINTS`] ground points along a line in `x`, shaded by one
//! batch call (so groups form along the line) and by `shade_query` point
//! by point, each with and without interpolation across levels; the
//! largest jump of the relative error between neighbouring points.
//!
//! Writes `batch.csv`, `batch_seams.csv` (one row per configuration),
//! `batch_seams_points.csv` (each point's relative errors),
//! `batch_tree.png` (the batch image at 1%) and
//! `batch_small_{tree,exact,diff}.png` (the same view at a lower
//! resolution, against the exact sum) under `out/report/`.

use std::error::Error;
use std::fmt::Write as _;
use std::fs;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use glam::{DVec3, Vec3};
use manylights::{BatchStats, Lambert, LightTree, Query, ShadeResult, Threshold, Unoccluded};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::compare::{max_ratio, timed};
use crate::config::{SEED, SOA_TOLERANCE};
use crate::exact::SoaLights;
use crate::image::{exposure, write_comparison, write_radiance};
use crate::measure::relative;
use crate::scenes::{Material, city_lights};
use crate::sweep::median;

/// The part's name.
pub const BATCH: &str = "batch";

/// Sizes of one run of the part.
#[derive(Clone, Copy, Debug)]
pub struct BatchSizes {
    /// Lights of the street city.
    pub lights: usize,
    /// Timed runs of each configuration; the median counts.
    pub runs: usize,
}

/// The full run.
pub const FULL_BATCH: BatchSizes = BatchSizes {
    lights: 1_000_000,
    runs: 5,
};
/// `--quick`.
pub const QUICK_BATCH: BatchSizes = BatchSizes {
    lights: 100_000,
    runs: 3,
};
/// Rounds of the threads' timing, per timed run of the other
/// configurations: a round takes about 0.1 s, and its ratio is the one
/// figure here that needs both cores undisturbed at once, so more rounds
/// steady the median on a shared machine.
const THREAD_ROUNDS_PER_RUN: usize = 3;
/// The image.
const WIDTH: u32 = 320;
const HEIGHT: u32 = 180;
/// The same shot at a renderer's usual resolution, swept again: denser
/// pixels share cuts over smaller patches of ground.
pub const HIGH: (u32, u32) = (1280, 720);
/// The lower-resolution view the exact image is rendered at.
const SMALL: (u32, u32) = (160, 90);
/// Side of the street city's blocks (see [`city_lights`]): the camera and
/// the scanline sit at fixed places on the block grid.
pub(crate) const BLOCK: f32 = 60.0;
/// The camera, relative to the block corner nearest the city's centre:
/// eye, target, vertical field of view in degrees.
pub(crate) const EYE: Vec3 = Vec3::new(22.0, -35.0, 30.0);
pub(crate) const TARGET: Vec3 = Vec3::new(52.0, 45.0, 0.0);
pub(crate) const FOV_DEGREES: f32 = 50.0;
/// Relative thresholds of the sweep.
pub const THRESHOLDS: [f64; 8] = [0.01, 0.02, 0.05, 0.07, 0.1, 0.15, 0.2, 0.5];
/// The threshold of the headline and of the single-point comparison.
const HEADLINE: f64 = 0.01;
/// Sampled pixels: the centres of a grid of this many columns and rows of
/// cells over the image, those that see the ground.
const SAMPLE_GRID: (u32, u32) = (24, 15);
/// Points of the scanline, its length and where it lies: along `+x` from
/// `SEAM_START` relative to the camera's block corner (between the streets
/// along `x`, across those along `y`).
pub const SEAM_POINTS: usize = 2048;
const SEAM_LENGTH: f32 = 320.0;
const SEAM_START: Vec3 = Vec3::new(10.0, 17.0, 0.0);
/// Columns and lines of the patch of points of the seams rows.
const GRID: (usize, usize) = (128, 16);
/// Interpolation band of the seams rows.
const BAND: f64 = 2.0;
/// Jumps of the relative error between neighbouring scanline points above
/// this are counted (above the smooth variation at this spacing).
const JUMP_LEVEL: f64 = 5e-5;
/// Percentile of the exact image the exposure maps to white.
const EXPOSURE_PERCENTILE: f64 = 0.995;

/// One threshold's figures over the image.
#[derive(Clone, Copy, Debug)]
pub struct BatchRow {
    /// Relative threshold.
    pub threshold: f64,
    /// Batch call over every ground pixel against the exact sum over the
    /// sampled pixels.
    pub timing: Timing,
    /// Largest actual relative error over the sampled pixels.
    pub max_error: f64,
    /// Largest certified bound over the value, over every ground pixel.
    pub max_bound: f64,
    /// Mean items (node estimates and single lights) per pixel.
    pub items: f64,
    /// What the batch call did.
    pub stats: BatchStats,
}

/// One configuration along the scanline.
#[derive(Clone, Debug)]
struct SeamRow {
    label: &'static str,
    interpolation: bool,
    /// Signed relative error at each point (largest channel of `(L - exact)
    /// / exact`, as the `seams` example).
    errors: Vec<f64>,
    max_error: f64,
    max_jump: f64,
    p99_jump: f64,
    /// Jumps above [`JUMP_LEVEL`].
    big_jumps: usize,
    items: f64,
    micros: f64,
    stats: Option<BatchStats>,
}

/// The ground point each pixel of `camera`'s image sees (`None` for the
/// sky), row-major.
pub(crate) fn ground_hits(camera: &Camera) -> Vec<Option<Vec3>> {
    (0..camera.width * camera.height)
        .map(|i| {
            let d = camera.ray(i % camera.width, i / camera.width);
            (d.z < 0.0).then(|| (camera.eye - d * (camera.eye.z / d.z)).with_z(0.0))
        })
        .collect()
}

/// A method timed against the SIMD exact sum.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// The method, microseconds per point (median round).
    pub us: f64,
    /// The exact sum, microseconds per point (median round).
    pub exact_us: f64,
    /// Median over the rounds of the exact sum's time per point over the
    /// method's.
    pub ratio: f64,
}

/// `runs` rounds of one run of `method` (over `points.0` points) and one
/// of `exact` (over `points.1`), alternating: robust to a machine whose
/// load drifts.
pub fn paired(
    runs: usize,
    points: (usize, usize),
    mut method: impl FnMut(),
    mut exact: impl FnMut(),
) -> Timing {
    let time = |f: &mut dyn FnMut(), n: usize| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64() * 1e6 / n as f64
    };
    let (mut a, mut b, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let x = time(&mut method, points.0);
        let y = time(&mut exact, points.1);
        a.push(x);
        b.push(y);
        ratios.push(y / x);
    }
    Timing {
        us: median(a),
        exact_us: median(b),
        ratio: median(ratios),
    }
}

/// The `q`-quantile of `values` (sorted copy, nearest rank).
fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).ceil() as usize]
}

/// Runs the part: prints its tables and headlines, writes its CSV files and
/// images under `out`; an error if a sampled pixel or a scanline point
/// breaks its certified bound.
pub fn run_batch(sizes: BatchSizes, out: &Path) -> Result<(), Box<dyn Error>> {
    let (count, runs) = (sizes.lights, sizes.runs);
    let lights = city_lights(count, SEED);
    let (tree, build) = timed(|| LightTree::build(&lights));
    let tree = tree?;
    let (lo, hi) = lights.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), l| (lo.min(l.position), hi.max(l.position)),
    );
    let corner = (((lo + hi) * 0.5) / BLOCK).floor().with_z(0.0) * BLOCK;
    let shader = Lambert::new(Vec3::ONE);
    let material = Material::diffuse(Vec3::ONE);
    let soa = SoaLights::new(&lights);
    let shot = (corner + EYE, corner + TARGET);
    let mut csv_rows = Vec::new();

    let view = View::new(&tree, (&soa, &material), shot, (WIDTH, HEIGHT))?;
    println!(
        "## Batch shading: street city, {} lights, {WIDTH}x{HEIGHT} camera view, one core\n",
        tree.len()
    );
    println!(
        "  tree built in {:.2} s; {}",
        build.as_secs_f64(),
        view.describe()
    );
    let exact_pass = || view.exact_pass(&soa, &material);

    // Single-point shade_query at the headline threshold, sampled pixels.
    let mut shading = tree.shading(shader);
    let headline = Threshold::relative(HEADLINE);
    let mut single = Vec::with_capacity(view.samples.len());
    let single_timing = paired(
        runs,
        (view.samples.len(), view.samples.len()),
        || {
            single.clear();
            for &k in &view.samples {
                single.push(shading.shade_query(&view.queries[k], headline, Unoccluded));
            }
        },
        exact_pass,
    );
    let single: Vec<ShadeResult> = single.into_iter().collect::<Result<_, _>>()?;
    check_certified("shade_query at 1%", &single, &view.exact)?;
    let single_error = max_error(&single, &view.exact);
    let single_items =
        single.iter().map(|r| f64::from(r.cost())).sum::<f64>() / single.len() as f64;

    let mut results = vec![ShadeResult::default(); view.queries.len()];
    let mut headline_image = Vec::new();
    let rows = sweep(
        &tree,
        &view,
        runs,
        &mut results,
        Some(&mut headline_image),
        exact_pass,
    )?;
    print_sweep(&view, runs, &rows);
    let at_one = rows
        .iter()
        .find(|r| r.threshold == HEADLINE)
        .expect("1% is in the sweep");
    println!(
        "\n  single-point shade_query at 1%, sampled pixels: {:.1} us per pixel, {:.0}x the SIMD \
         exact sum, {single_items:.0} items per pixel, max actual error {single_error:.2e}; the \
         batch call is {:.1}x faster per pixel",
        single_timing.us,
        single_timing.ratio,
        single_timing.us / at_one.timing.us
    );
    print_headlines(&view, &rows);
    csv_rows.push((view.size, rows));

    // The same call over the thread pool, against one thread.
    let queries = &view.queries;
    let headline_threshold = Threshold::relative(HEADLINE);
    let mut parallel_results = results.clone();
    let mut parallel_stats = Ok(BatchStats::default());
    let pool = tree.shading(shader);
    let thread_rounds = runs * THREAD_ROUNDS_PER_RUN;
    let threads = paired(
        thread_rounds,
        (queries.len(), queries.len()),
        || {
            parallel_stats = pool.shade_batch_parallel(
                queries,
                headline_threshold,
                Unoccluded,
                &mut parallel_results,
            );
        },
        || {
            black_box(shading.shade_batch(queries, headline_threshold, Unoccluded, &mut results))
                .expect("valid threshold");
        },
    );
    parallel_stats?;
    if parallel_results != results {
        return Err("shade_batch_parallel differs from shade_batch".into());
    }
    // What the machine's threads give a loop with no shared work at all:
    // the SIMD exact sum over the sampled pixels, the same way.
    let exact_threads = paired(
        thread_rounds,
        (view.samples.len(), view.samples.len()),
        || {
            view.samples.par_iter().for_each(|&k| {
                black_box(view.simd(&soa, &material, k));
            });
        },
        exact_pass,
    );
    println!(
        "  {} threads (shade_batch_parallel, feature `rayon`) at 1%: {:.2} us per pixel, {:.2}x \
         one thread (median of {thread_rounds} alternating rounds' ratios), the same bits; the SIMD exact \
         sum over the sampled pixels on the same threads: {:.2}x one thread\n",
        rayon::current_num_threads(),
        threads.us,
        threads.ratio,
        exact_threads.ratio
    );
    write_images(
        out,
        &tree,
        &soa,
        &material,
        shot,
        &view.pixel_query,
        &headline_image,
    )?;
    drop(view);

    // The same shot at the higher resolution: the sweep alone.
    let (w, h) = HIGH;
    let view = View::new(&tree, (&soa, &material), shot, HIGH)?;
    println!("## Batch shading: the same shot at {w}x{h}, one core\n");
    println!("  {}", view.describe());
    let mut results = vec![ShadeResult::default(); view.queries.len()];
    let rows = sweep(&tree, &view, runs, &mut results, None, || {
        view.exact_pass(&soa, &material)
    })?;
    print_sweep(&view, runs, &rows);
    print_headlines(&view, &rows);
    csv_rows.push((view.size, rows));
    drop((view, results));

    write_batch_csv(
        &out.join("batch.csv"),
        tree.len(),
        &csv_rows,
        (single_timing, single_error, single_items),
    )?;
    let line = corner + SEAM_START;
    run_seams(out, &tree, line, runs)
}

/// The ground pixels of one image of the shot, the sampled pixels among
/// them and their references.
struct View {
    size: (u32, u32),
    eye: Vec3,
    /// Per pixel (row-major), its query's index, `None` for the sky.
    pixel_query: Vec<Option<usize>>,
    queries: Vec<Query>,
    /// Indices into `queries` of the sampled pixels.
    samples: Vec<usize>,
    /// The crate's `f64` exact sum at the sampled pixels.
    exact: Vec<DVec3>,
    /// Largest relative difference of the SIMD sum from `exact`.
    soa_worst: f64,
}

impl View {
    /// The image of `shot` (eye, target) at `size`, its queries, sampled
    /// pixels and references; an error if the SIMD sum strays from the
    /// crate's exact sum.
    fn new(
        tree: &LightTree,
        (soa, material): (&SoaLights, &Material),
        (eye, target): (Vec3, Vec3),
        size: (u32, u32),
    ) -> Result<Self, Box<dyn Error>> {
        let (width, height) = size;
        let camera = Camera::new(eye, target, FOV_DEGREES, width, height);
        let hits = ground_hits(&camera);
        let mut pixel_query = vec![None; hits.len()];
        let mut queries = Vec::new();
        for (i, hit) in hits.iter().enumerate() {
            if let Some(p) = hit {
                pixel_query[i] = Some(queries.len());
                queries.push(Query::new(*p, Vec3::Z)?);
            }
        }
        let (gx, gy) = SAMPLE_GRID;
        let samples: Vec<usize> = (0..gx * gy)
            .filter_map(|k| {
                let x = ((k % gx) * 2 + 1) * width / (2 * gx);
                let y = ((k / gx) * 2 + 1) * height / (2 * gy);
                pixel_query[(y * width + x) as usize]
            })
            .collect();
        // References at the sampled pixels: the crate's f64 exact sum (in
        // parallel, not timed), and the SIMD sum checked against it.
        let shader = Lambert::new(Vec3::ONE);
        let exact: Vec<DVec3> = samples
            .par_iter()
            .map(|&k| tree.shading(shader).exact_query(&queries[k], Unoccluded))
            .collect();
        if let Some(k) = exact.iter().position(|e| !(e.min_element() > 0.0)) {
            return Err(format!("sampled pixel {k}: exact radiance {:?}", exact[k]).into());
        }
        let mut view = Self {
            size,
            eye,
            pixel_query,
            queries,
            samples,
            exact,
            soa_worst: 0.0,
        };
        view.soa_worst = view
            .samples
            .iter()
            .zip(&view.exact)
            .map(|(&k, &e)| relative(view.simd(soa, material, k) - e, e))
            .fold(0.0, |a: f64, d| if d.is_nan() || d > a { d } else { a });
        if view.soa_worst.is_nan() || view.soa_worst > SOA_TOLERANCE {
            return Err(format!(
                "the SIMD exact sum is off by {:.2e} relative",
                view.soa_worst
            )
            .into());
        }
        Ok(view)
    }

    /// The SIMD exact sum at query `k`.
    fn simd(&self, soa: &SoaLights, material: &Material, k: usize) -> DVec3 {
        soa.shade(material, self.queries[k].point(), Vec3::Z, Vec3::Z)
    }

    /// The SIMD exact sum over the sampled pixels (timed against the batch).
    fn exact_pass(&self, soa: &SoaLights, material: &Material) {
        for &k in &self.samples {
            black_box(self.simd(soa, material, black_box(k)));
        }
    }

    /// Ground pixels, distances and samples, as a sentence.
    fn describe(&self) -> String {
        let (min_d, max_d) = self
            .queries
            .iter()
            .fold((f32::INFINITY, 0.0f32), |(a, b), q| {
                let d = q.point().distance(self.eye);
                (a.min(d), b.max(d))
            });
        let (gx, gy) = SAMPLE_GRID;
        format!(
            "{} ground pixels of {} (the rest is sky), at {min_d:.0} to {max_d:.0} units from the \
             eye; {} sampled pixels (centres of a {gx}x{gy} grid of cells that see the ground)",
            self.queries.len(),
            self.pixel_query.len(),
            self.samples.len()
        )
    }
}

/// The batch call over every ground pixel of `view` at each threshold of
/// [`THRESHOLDS`], timed against `exact_pass` and checked against the
/// references; the results at [`HEADLINE`] are copied into `headline` when
/// one is given.
fn sweep(
    tree: &LightTree,
    view: &View,
    runs: usize,
    results: &mut [ShadeResult],
    mut headline: Option<&mut Vec<ShadeResult>>,
    exact_pass: impl Fn(),
) -> Result<Vec<BatchRow>, Box<dyn Error>> {
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let mut rows = Vec::new();
    for t in THRESHOLDS {
        let threshold = Threshold::relative(t);
        let mut stats = Ok(BatchStats::default());
        let timing = paired(
            runs,
            (view.queries.len(), view.samples.len()),
            || stats = shading.shade_batch(&view.queries, threshold, Unoccluded, results),
            &exact_pass,
        );
        let stats = stats?;
        let sampled: Vec<ShadeResult> = view.samples.iter().map(|&k| results[k]).collect();
        let (w, h) = view.size;
        check_certified(
            &format!("shade_batch at {w}x{h}, t = {t}"),
            &sampled,
            &view.exact,
        )?;
        let max_bound = results
            .iter()
            .map(|r| r.error_bound.max_element() / r.radiance.max_element())
            .fold(0.0, f64::max);
        if !(max_bound <= t) {
            return Err(format!("shade_batch at t = {t}: a bound of {max_bound:.3e}").into());
        }
        rows.push(BatchRow {
            threshold: t,
            timing,
            max_error: max_error(&sampled, &view.exact),
            max_bound,
            items: results.iter().map(|r| f64::from(r.cost())).sum::<f64>() / results.len() as f64,
            stats,
        });
        if t == HEADLINE
            && let Some(headline) = headline.as_deref_mut()
        {
            headline.clear();
            headline.extend_from_slice(results);
        }
    }
    Ok(rows)
}

/// Prints the sweep's table.
fn print_sweep(view: &View, runs: usize, rows: &[BatchRow]) {
    println!(
        "  per pixel: the batch call over all ground pixels and the SIMD exact sum over the \
         sampled pixels, {runs} rounds alternating one run of each; times are medians over the \
         rounds, speed-ups the medians of the rounds' ratios. Errors and bound checks against \
         the crate's f64 exact_query at the sampled pixels (the SIMD sum agrees with it to \
         {:.1e}).\n",
        view.soa_worst
    );
    println!(
        "| threshold | batch / pixel | SIMD exact / pixel | exact / batch | max actual rel. error \
         (sampled) | max bound / value (all pixels) | bound held (sampled) | items / pixel | \
         groups | shared points | points alone | shared bounds / pixel |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        println!(
            "| {} | {:.2} us | {:.0} us | {:.0}x | {:.2e} | {:.2e} | yes | {:.0} | {} | {} | {} \
             | {:.1} |",
            r.threshold,
            r.timing.us,
            r.timing.exact_us,
            r.timing.ratio,
            r.max_error,
            r.max_bound,
            r.items,
            r.stats.groups,
            r.stats.shared_points,
            r.stats.points_alone,
            r.stats.shared_evaluations as f64 / view.queries.len() as f64
        );
    }
}

/// Prints the certified 1% speed-up and the fastest threshold whose
/// largest actual error over the sampled pixels is at most 1%.
fn print_headlines(view: &View, rows: &[BatchRow]) {
    let (w, h) = view.size;
    let at_one = rows
        .iter()
        .find(|r| r.threshold == HEADLINE)
        .expect("1% is in the sweep");
    println!(
        "\n{w}x{h}, certified 1% per pixel: {:.0} x the SIMD exact sum",
        at_one.timing.ratio
    );
    // Fastest relative to the exact sum timed beside it.
    match rows
        .iter()
        .filter(|r| r.max_error <= 0.01)
        .max_by(|a, b| a.timing.ratio.total_cmp(&b.timing.ratio))
    {
        Some(r) => println!(
            "{w}x{h}, fastest threshold whose largest actual error over the sampled pixels is \
             <= 1%: {}, {:.0} x\n",
            r.threshold, r.timing.ratio
        ),
        None => println!(
            "{w}x{h}, fastest threshold whose largest actual error over the sampled pixels is \
             <= 1%: none\n"
        ),
    }
}

/// Fails if a result breaks its certified bound against `exact`.
fn check_certified(what: &str, results: &[ShadeResult], exact: &[DVec3]) -> Result<(), String> {
    let broken = results
        .iter()
        .zip(exact)
        .filter(|(r, e)| !r.certifies(**e))
        .count();
    match broken {
        0 => Ok(()),
        n => Err(format!("{what}: {n} points break the certified bound")),
    }
}

/// Largest relative error, per point the largest channel of `|L - exact| /
/// exact`.
fn max_error(results: &[ShadeResult], exact: &[DVec3]) -> f64 {
    results
        .iter()
        .zip(exact)
        .map(|(r, &e)| max_ratio((r.radiance - e).abs(), e))
        .fold(0.0, f64::max)
}

/// Writes `batch.csv`: one row per threshold of the batch call, and the
/// single-point row.
fn write_batch_csv(
    path: &Path,
    lights: usize,
    views: &[((u32, u32), Vec<BatchRow>)],
    (single, single_error, single_items): (Timing, f64, f64),
) -> Result<(), Box<dyn Error>> {
    let mut text = String::from(
        "lights,width,height,method,threshold,time_per_pixel_us,exact_per_pixel_us,exact_over_time,\
         max_rel_error_sampled,max_rel_bound,bound_held,mean_items,groups,shared_points,\
         points_alone,shared_evaluations\n",
    );
    for (r, (w, h)) in views
        .iter()
        .flat_map(|(size, rows)| rows.iter().map(move |r| (r, *size)))
    {
        let (s, t) = (r.stats, r.timing);
        let _ = writeln!(
            text,
            "{lights},{w},{h},shade_batch,{},{:.4},{:.2},{:.2},{:.6e},{:.6e},true,{:.1},{},{},{},{}",
            r.threshold,
            t.us,
            t.exact_us,
            t.ratio,
            r.max_error,
            r.max_bound,
            r.items,
            s.groups,
            s.shared_points,
            s.points_alone,
            s.shared_evaluations
        );
    }
    let _ = writeln!(
        text,
        "{lights},{WIDTH},{HEIGHT},shade_query (sampled pixels),{HEADLINE},{:.4},{:.2},{:.2},{single_error:.6e},,\
         true,{single_items:.1},,,,",
        single.us, single.exact_us, single.ratio
    );
    fs::write(path, text)?;
    println!("  wrote {}", path.display());
    Ok(())
}

/// Writes the batch image at 1% (`batch_tree.png`) and, at the lower
/// resolution [`SMALL`], the batch image, the exact image and their
/// difference (`batch_small_*.png`); nothing here is timed, the exact image
/// is summed in parallel.
fn write_images(
    out: &Path,
    tree: &LightTree,
    soa: &SoaLights,
    material: &Material,
    (eye, target): (Vec3, Vec3),
    pixel_query: &[Option<usize>],
    results: &[ShadeResult],
) -> Result<(), Box<dyn Error>> {
    let small = Camera::new(eye, target, FOV_DEGREES, SMALL.0, SMALL.1);
    let small_hits = ground_hits(&small);
    let small_queries: Vec<Query> = small_hits
        .iter()
        .flatten()
        .map(|&p| Query::new(p, Vec3::Z))
        .collect::<Result<_, _>>()?;
    let mut shading = tree.shading(Lambert::new(Vec3::ONE));
    let mut small_results = vec![ShadeResult::default(); small_queries.len()];
    shading.shade_batch(
        &small_queries,
        Threshold::relative(HEADLINE),
        Unoccluded,
        &mut small_results,
    )?;
    let small_exact: Vec<DVec3> = small_queries
        .par_iter()
        .map(|q| soa.shade(material, q.point(), Vec3::Z, Vec3::Z))
        .collect();
    let spread = |values: &[DVec3]| {
        let mut it = values.iter();
        small_hits
            .iter()
            .map(|h| h.and_then(|_| it.next().copied()).unwrap_or(DVec3::ZERO))
            .collect::<Vec<_>>()
    };
    let small_tree: Vec<DVec3> =
        spread(&small_results.iter().map(|r| r.radiance).collect::<Vec<_>>());
    let small_exact = spread(&small_exact);
    write_comparison(
        out,
        "batch_small",
        SMALL,
        &small_tree,
        &small_exact,
        HEADLINE,
        EXPOSURE_PERCENTILE,
    )?;
    let image: Vec<DVec3> = pixel_query
        .iter()
        .map(|q| q.map_or(DVec3::ZERO, |k| results[k].radiance))
        .collect();
    let path = out.join("batch_tree.png");
    write_radiance(
        &path,
        (WIDTH, HEIGHT),
        &image,
        exposure(&small_exact, EXPOSURE_PERCENTILE),
    )?;
    println!("wrote {}\n", path.display());
    Ok(())
}

/// A row of the seams table: `results` against `exact`, with the jumps of
/// the relative error between the neighbours that `jumps` pairs, and the
/// call's `times` (seconds per run).
fn seam_row(
    (label, interpolation): (&'static str, bool),
    (results, exact): (&[ShadeResult], &[DVec3]),
    jumps: impl Fn(&[f64]) -> Vec<f64>,
    (times, stats): (Vec<f64>, Option<BatchStats>),
) -> SeamRow {
    let errors: Vec<f64> = results
        .iter()
        .zip(exact)
        .map(|(r, &e)| ((r.radiance - e) / e).max_element())
        .collect();
    let jumps = jumps(&errors);
    let n = results.len() as f64;
    SeamRow {
        label,
        interpolation,
        max_error: max_error(results, exact),
        max_jump: jumps.iter().copied().fold(0.0, f64::max),
        p99_jump: quantile(&jumps, 0.99),
        big_jumps: jumps.iter().filter(|&&j| j > JUMP_LEVEL).count(),
        items: results.iter().map(|r| f64::from(r.cost())).sum::<f64>() / n,
        micros: median(times) * 1e6 / n,
        errors,
        stats,
    }
}

/// The scanline: [`SEAM_POINTS`] ground points from `start` along `+x`,
/// shaded at 1% by one batch call and by `shade_query` point by point, each
/// with and without interpolation; prints the table and writes
/// `batch_seams.csv` and `batch_seams_points.csv`.
fn run_seams(out: &Path, tree: &LightTree, start: Vec3, runs: usize) -> Result<(), Box<dyn Error>> {
    let step = SEAM_LENGTH / (SEAM_POINTS - 1) as f32;
    let points: Vec<Vec3> = (0..SEAM_POINTS)
        .map(|i| start + Vec3::X * (step * i as f32))
        .collect();
    let queries: Vec<Query> = points
        .iter()
        .map(|&p| Query::new(p, Vec3::Z))
        .collect::<Result<_, _>>()?;
    let shader = Lambert::new(Vec3::ONE);
    let exact: Vec<DVec3> = queries
        .par_iter()
        .map(|q| tree.shading(shader).exact_query(q, Unoccluded))
        .collect();
    let mut shading = tree.shading(shader);
    let mut results = vec![ShadeResult::default(); queries.len()];
    let discrete = Threshold::relative(HEADLINE);
    let configurations = [
        ("shade_batch", false),
        ("shade_batch", true),
        ("shade_query", false),
        ("shade_query", true),
    ];
    let with_band = |interpolation: bool| {
        if interpolation {
            discrete.with_interpolation(BAND)
        } else {
            discrete
        }
    };
    let mut rows = Vec::new();
    for (label, interpolation) in configurations {
        let threshold = with_band(interpolation);
        let (mut stats, mut times) = (None, Vec::new());
        for _ in 0..runs {
            let started = Instant::now();
            if label == "shade_batch" {
                stats = Some(shading.shade_batch(&queries, threshold, Unoccluded, &mut results)?);
            } else {
                for (q, r) in queries.iter().zip(results.iter_mut()) {
                    *r = shading.shade_query(q, threshold, Unoccluded)?;
                }
            }
            times.push(started.elapsed().as_secs_f64());
        }
        let what = format!("scanline, {label}, interpolation {interpolation}");
        check_certified(&what, &results, &exact)?;
        rows.push(seam_row(
            (label, interpolation),
            (&results, &exact),
            |errors| errors.windows(2).map(|w| (w[1] - w[0]).abs()).collect(),
            (times, stats),
        ));
    }

    // The same spacing over a patch, as a renderer hands a tile: groups
    // border each other along both axes. Jumps between horizontal and
    // vertical neighbours.
    let (columns, lines) = GRID;
    let grid: Vec<Query> = (0..lines)
        .flat_map(|j| (0..columns).map(move |i| (i, j)))
        .map(|(i, j)| {
            Query::new(
                start + Vec3::new(step * i as f32, step * j as f32, 0.0),
                Vec3::Z,
            )
        })
        .collect::<Result<_, _>>()?;
    let grid_exact: Vec<DVec3> = grid
        .par_iter()
        .map(|q| tree.shading(shader).exact_query(q, Unoccluded))
        .collect();
    let mut grid_results = vec![ShadeResult::default(); grid.len()];
    for interpolation in [false, true] {
        let threshold = with_band(interpolation);
        let (mut stats, mut times) = (None, Vec::new());
        for _ in 0..runs {
            let started = Instant::now();
            stats = Some(shading.shade_batch(&grid, threshold, Unoccluded, &mut grid_results)?);
            times.push(started.elapsed().as_secs_f64());
        }
        let what = format!("grid, shade_batch, interpolation {interpolation}");
        check_certified(&what, &grid_results, &grid_exact)?;
        let jumps = |errors: &[f64]| {
            let at = |i: usize, j: usize| errors[j * columns + i];
            let mut jumps = Vec::new();
            for j in 0..lines {
                for i in 0..columns {
                    if i + 1 < columns {
                        jumps.push((at(i + 1, j) - at(i, j)).abs());
                    }
                    if j + 1 < lines {
                        jumps.push((at(i, j + 1) - at(i, j)).abs());
                    }
                }
            }
            jumps
        };
        rows.push(seam_row(
            ("shade_batch, 128 x 16 patch", interpolation),
            (&grid_results, &grid_exact),
            jumps,
            (times, stats),
        ));
    }

    println!(
        "### Seams: {SEAM_POINTS} ground points along x from ({:.0}, {:.0}), {SEAM_LENGTH} units \
        ({:.1} blocks, {:.3} units apart), certified 1%, interpolation band {BAND}\n",
        start.x,
        start.y,
        SEAM_LENGTH / BLOCK,
        step
    );
    println!(
        "  relative error = largest channel of (L - exact) / exact against exact_query at every \
         point; jump = its change between neighbouring points; time: median of {runs} runs, one \
         core. With interpolation the batch call blends each shared cut's last nodes with their \
         children, and each point near a group's border with the neighbouring groups' cuts. The \
         patch rows: a {}x{} grid of points at the same spacing from the same start, one batch \
         call, jumps between horizontal and vertical neighbours.\n",
        GRID.0, GRID.1
    );
    println!(
        "| call | interpolation | max rel. error | largest jump | 99th percentile jump | jumps > \
         {JUMP_LEVEL:.0e} | items / point | time / point | groups | shared points | points alone |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let (groups, shared, alone) = r.stats.map_or(("-".into(), "-".into(), "-".into()), |s| {
            (
                s.groups.to_string(),
                s.shared_points.to_string(),
                s.points_alone.to_string(),
            )
        });
        println!(
            "| {} | {} | {:.2e} | {:.2e} | {:.2e} | {} | {:.0} | {:.1} us | {groups} | {shared} \
             | {alone} |",
            r.label,
            if r.interpolation { "on" } else { "off" },
            r.max_error,
            r.max_jump,
            r.p99_jump,
            r.big_jumps,
            r.items,
            r.micros
        );
    }
    println!();

    let mut text = String::from(
        "call,interpolation,max_rel_error,max_jump,p99_jump,jumps_above_5e-5,mean_items,\
         time_per_point_us,groups,shared_points,points_alone\n",
    );
    for r in &rows {
        let stats = r.stats.map_or(",,".into(), |s| {
            format!("{},{},{}", s.groups, s.shared_points, s.points_alone)
        });
        let _ = writeln!(
            text,
            "{},{},{:.6e},{:.6e},{:.6e},{},{:.1},{:.3},{stats}",
            r.label,
            r.interpolation,
            r.max_error,
            r.max_jump,
            r.p99_jump,
            r.big_jumps,
            r.items,
            r.micros
        );
    }
    let path = out.join("batch_seams.csv");
    fs::write(&path, text)?;
    println!("  wrote {}", path.display());

    let scanline = &rows[..configurations.len()];
    let mut text = String::from("x,y");
    for r in scanline {
        let on = if r.interpolation { "_interpolated" } else { "" };
        let _ = write!(text, ",{}{on}", r.label);
    }
    text.push('\n');
    for (i, p) in points.iter().enumerate() {
        let _ = write!(text, "{},{}", p.x, p.y);
        for r in scanline {
            let _ = write!(text, ",{:.6e}", r.errors[i]);
        }
        text.push('\n');
    }
    let path = out.join("batch_seams_points.csv");
    fs::write(&path, text)?;
    println!("  wrote {}\n", path.display());
    Ok(())
}
