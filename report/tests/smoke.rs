//! Every part of the report runs on tiny scenes, and the scenes are
//! reproducible from their seed.

use std::time::Duration;

use manylights_report::batch::{BatchSizes, run_batch};
use manylights_report::config::{self, Config, SCENE_NAMES};
use manylights_report::measure::Method;
use manylights_report::occluded::run_occluded;
use manylights_report::scaling::run_scaling;
use manylights_report::scenes;
use manylights_report::summary::summary;
use manylights_report::sweep::run_scene;

const TINY: Config = Config {
    points: 8,
    city_lights: 500,
    chandelier_lights: 300,
    strings_lights: 200,
    specular_lights: 200,
    shadow_lights: 300,
    canopy_lights: 200,
    canopy_points: 8,
    scaling_sizes: &[1, 100, 1_000],
    scaling_points: 8,
    budget: Duration::from_millis(1),
};

#[test]
fn every_part_runs_and_keeps_the_bound() {
    let mut records = Vec::new();
    for name in SCENE_NAMES {
        records.extend(run_scene(&config::make_scene(name, &TINY), &TINY).unwrap());
    }
    let mut targets = Vec::new();
    let (scene, city) = scenes::city_shadows(TINY.shadow_lights, TINY.points, config::SEED);
    let sweeps = &config::CITY_SHADOWS_SWEEPS;
    let (rows, target) = run_occluded(&scene, &city.occluders, &TINY, sweeps).unwrap();
    records.extend(rows);
    targets.push((config::OCCLUDED, target));
    let (scene, leaves) = scenes::canopy(TINY.canopy_lights, TINY.canopy_points, config::SEED);
    let (rows, target) = run_occluded(&scene, &leaves, &TINY, &config::CANOPY_SWEEPS).unwrap();
    records.extend(rows);
    targets.push((config::CANOPY, target));
    let scaling = run_scaling(&TINY).unwrap();
    for r in records
        .iter()
        .chain(scaling.iter().flat_map(|s| &s.records))
    {
        assert_eq!(
            r.measurement.violations, 0,
            "{} {:?} {}",
            r.scene, r.method, r.parameter
        );
        if r.method == Method::TreeAbsolute && r.parameter == "abs=0 (exact)" {
            assert_eq!(r.measurement.max_error, 0.0, "{}: the exact limit", r.scene);
        }
    }
    for row in &scaling {
        let a = row.alternating;
        assert!(a.rounds >= 5 && a.rounds % 2 == 1, "{} rounds", a.rounds);
        assert!(a.first > 0.0 && a.second > 0.0 && a.ratio > 0.0, "{a:?}");
    }
    let text = summary(&records, &scaling, &targets);
    assert!(text.contains("## Summary"));
    assert!(text.contains("certified, city 1000 lights, alternating passes"));
    assert!(text.contains("canopy: the tree at a certified 1%"));
}

#[test]
fn scenes_are_reproducible_from_their_seed() {
    let positions = |seed| -> Vec<_> {
        let scene = scenes::city(1_000, 16, seed);
        let points = scene.points.iter().map(|p| p.point);
        scene
            .lights
            .iter()
            .map(|l| l.position)
            .chain(points)
            .collect()
    };
    assert_eq!(positions(7), positions(7));
    assert_ne!(positions(7), positions(8));
    let windows = |seed| scenes::City::new(4, 1_000, seed).lights;
    assert_eq!(windows(7).len(), 1_000);
    assert_eq!(
        windows(7).iter().map(|l| l.position).collect::<Vec<_>>(),
        windows(7).iter().map(|l| l.position).collect::<Vec<_>>()
    );
}

#[test]
fn the_batch_part_runs_and_keeps_the_bound() {
    let out = std::env::temp_dir().join("manylights-report-batch-smoke");
    std::fs::create_dir_all(&out).unwrap();
    let sizes = BatchSizes {
        lights: 2_000,
        runs: 1,
    };
    run_batch(sizes, &out).unwrap();
    for file in ["batch.csv", "batch_seams.csv", "batch_seams_points.csv"] {
        let text = std::fs::read_to_string(out.join(file)).unwrap();
        assert!(text.lines().count() > 2, "{file}");
    }
}
