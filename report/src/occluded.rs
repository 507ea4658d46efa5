//! The occluded scene, `city-shadows`: the exact shadowed sum, the tree
//! with the night city's conservative classifier ([`Shadows`]), Monte Carlo
//! with a shadow ray per sample, and Ward's adaptive shadow testing.

use std::error::Error;

use manylights::{Lambert, Threshold};

use crate::config::{Config, SHADOW_PER_NODE, SHADOW_RELATIVE, SOA_TOLERANCE, TREE_ABSOLUTE, WARD};
use crate::measure::{Method, Record, Sample, measure};
use crate::scenes::{City, Scene, ShadingPoint};
use crate::shadowed::{ShadowLights, Ward};
use crate::shadows::Shadows;
use crate::sweep::{
    Bench, absolute_parameter, build_tree, measure_cut, median, print_header, recorder, references,
    sample_sweeps,
};

/// The host of each shading point: the city's classifier and shadow rays.
fn hosts<'c>(city: &'c City) -> impl Fn(&ShadingPoint) -> Shadows<'c> + Sync + 'c {
    move |pt| Shadows::new(city, pt.normal)
}

/// Every configuration of every method on the occluded scene, with `city`
/// holding the buildings that occlude.
pub fn run_occluded<'c>(
    scene: &Scene,
    city: &'c City,
    cfg: &Config,
) -> Result<Vec<Record>, Box<dyn Error>> {
    let (tree, build) = build_tree(scene)?;
    print_header(scene, &tree, build);
    let shader = Lambert::new(scene.material.kd);
    let host = hosts(city);
    // The reference: the crate's exact shadowed sum (one shadow ray per
    // light); points no light reaches are dropped.
    let (points, refs) = references(&tree, shader, &scene.points, &host);
    let on_ground = points.iter().filter(|p| p.normal.z > 0.5).count();
    let median_radiance = median(refs.iter().map(|r| r.max_element()).collect());
    println!(
        "  {} points ({on_ground} on the ground, {} on façades; {} dropped: unlit), median \
         exact shadowed radiance {median_radiance:.3e}",
        points.len(),
        points.len() - on_ground,
        scene.points.len() - points.len()
    );

    let mut rows = Vec::new();
    let mut record = recorder(scene.name, scene.lights.len(), &mut rows);
    let (light_count, budget) = (scene.lights.len() as u32, cfg.budget);

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
    record(Method::ExactShadowed, "-".into(), m);

    let occluded: Option<&dyn Fn(&ShadingPoint) -> Shadows<'c>> = Some(&host);
    let bench = Bench::new(&points, &refs, budget);
    let cut = |threshold| measure_cut(&tree, shader, bench, threshold, occluded);
    for t in SHADOW_RELATIVE {
        record(
            Method::TreeRelative,
            format!("t={t}"),
            cut(Threshold::relative(t)),
        );
    }
    for f in TREE_ABSOLUTE {
        let m = cut(Threshold::absolute(f * median_radiance));
        record(Method::TreeAbsolute, absolute_parameter(f), m);
    }
    for t in SHADOW_PER_NODE {
        record(
            Method::PerNode,
            format!("t={t}"),
            cut(Threshold::per_node(t)),
        );
    }

    sample_sweeps(&mut record, &tree, &shader, bench, occluded);

    let mut ward = Ward::default();
    for t in WARD {
        let m = measure(&refs, budget, |i| {
            let pt = &points[i];
            let (radiance, rays) = ward.shade(&mut soa, pt.point, pt.normal, t, &mut host(pt));
            Sample::estimate(radiance, light_count, Some(rays))
        });
        record(Method::Ward, format!("t={t}"), m);
    }
    drop(record);
    Ok(rows)
}
