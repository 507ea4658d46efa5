use glam::Vec3;
use manylights::*;
use std::time::Instant;

fn rng(state: &mut u64) -> f32 {
    *state ^= *state << 13; *state ^= *state >> 7; *state ^= *state << 17;
    (*state >> 40) as f32 / (1u64 << 24) as f32
}

fn main() {
    let n: usize = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(10_000);
    let mut s = 0x9E3779B97F4A7C15u64;
    let lights: Vec<PointLight> = (0..n).map(|_| PointLight::new(
        Vec3::new(rng(&mut s) * 1000.0, rng(&mut s) * 1000.0, 4.0 + 2.0 * rng(&mut s)), Vec3::splat(1.0))).collect();
    let t = Instant::now();
    let leaf: usize = std::env::args().nth(2).map(|s| s.parse().unwrap()).unwrap_or(1); let tree = LightTree::builder().max_leaf_lights(leaf).build(&lights).unwrap();
    println!("build {:?} nodes {} depth {} mem/light {}", t.elapsed(), tree.nodes().len(), tree.depth(), tree.memory_bytes() / n);
    tree.validate().unwrap();
    for kind in [BoundKind::Paper, BoundKind::Tight] {
        let mut sh = tree.shading(Lambert::new(Vec3::splat(1.0)).with_bound(kind));
        let mut nodes = 0u64; let mut maxrel = 0f64; let mut tt = 0.0; let mut te = 0.0;
        let pts = 20;
        for _ in 0..pts {
            let p = Vec3::new(rng(&mut s) * 1000.0, rng(&mut s) * 1000.0, 0.0);
            let t0 = Instant::now();
            let r = sh.shade(p, Vec3::Z, Threshold::relative(0.01)).unwrap();
            tt += t0.elapsed().as_secs_f64();
            let t1 = Instant::now();
            let e = sh.shade_exact(p, Vec3::Z).unwrap();
            te += t1.elapsed().as_secs_f64();
            assert!((r.radiance - e).abs().max_element() <= r.error_bound.max_element() * (1.0 + 1e-9) + 1e-9 * e.max_element());
            nodes += r.cost() as u64;
            maxrel = maxrel.max(((r.radiance - e).abs() / e).max_element());
        }
        println!("{kind:?}: cost/pt {} actual max rel {maxrel:.2e} time/pt {:.1}us exact {:.1}us", nodes / pts, tt / pts as f64 * 1e6, te / pts as f64 * 1e6);
    }
}
