//! Shading allocates nothing once a session is warmed: a counting global
//! allocator watches the calls.
//!
//! The allocator counts per thread, so that the tests running beside this
//! one on other threads of the harness do not enter its count.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use glam::Vec3;
use manylights::{Combined, Lambert, LightTree, Phong, PointLight, Query, Threshold, Unoccluded};

struct Counting;

thread_local! {
    // A constant initialiser and no destructor: reading it never allocates
    // and never fails, as the allocator needs.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

/// Counts one allocation on the calling thread.
fn count() {
    // `try_with` rather than `with`: never a panic inside the allocator.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

/// Allocations made so far on the calling thread.
fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: forwards every call unchanged to the system allocator; only
// counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn shading_does_not_allocate_once_warmed() {
    let lights: Vec<_> = (0..20_000)
        .map(|i| {
            let (x, y) = ((i % 200) as f32, (i / 200) as f32);
            PointLight::new(
                Vec3::new(x, y, 5.0 + (i % 7) as f32 * 0.3),
                Vec3::new(1.0, 0.8, 0.6),
            )
        })
        .collect();
    let tree = LightTree::build(&lights).unwrap();
    let mut diffuse = tree.shading(Lambert::new(Vec3::splat(0.7)));
    let mut glossy = tree.shading(Combined::new(
        Lambert::new(Vec3::splat(0.5)),
        Phong::new(Vec3::ONE, 80.0),
    ));
    let points: Vec<Vec3> = (0..64)
        .map(|i| Vec3::new(i as f32 * 3.0, 100.0 - i as f32, 0.0))
        .collect();
    let thresholds = [
        Threshold::relative(0.01),
        Threshold::relative(1e-4),
        Threshold::zero(),
    ];
    let view = Vec3::new(0.3, 0.2, 1.0);
    // Warm up: the error list grows to its largest size.
    for &p in &points {
        for &t in &thresholds {
            diffuse.shade(p, Vec3::Z, t).unwrap();
            glossy
                .shade_query(
                    &Query::new(p, Vec3::Z).unwrap().with_view(view).unwrap(),
                    t,
                    Unoccluded,
                )
                .unwrap();
        }
    }
    let before = allocations();
    let mut cost = 0u64;
    for &p in &points {
        for &t in &thresholds {
            cost += u64::from(diffuse.shade(p, Vec3::Z, t).unwrap().cost());
            cost += u64::from(
                glossy
                    .shade_query(
                        &Query::new(p, Vec3::Z).unwrap().with_view(view).unwrap(),
                        t,
                        Unoccluded,
                    )
                    .unwrap()
                    .cost(),
            );
        }
    }
    let after = allocations();
    assert!(cost > 0);
    // The counter sees this thread's allocations.
    let probe = std::hint::black_box(vec![0u8; 16]);
    assert!(allocations() > after, "the counting allocator saw nothing");
    drop(probe);
    assert_eq!(
        after - before,
        0,
        "shading allocated {} times",
        after - before
    );
}

#[test]
fn sampling_does_not_allocate_once_warmed() {
    let lights: Vec<_> = (0..20_000)
        .map(|i| {
            let (x, y) = ((i % 200) as f32, (i / 200) as f32);
            PointLight::new(Vec3::new(x, y, 5.0 + (i % 5) as f32 * 0.4), Vec3::ONE)
        })
        .collect();
    let tree = LightTree::build(&lights).unwrap();
    let lambert = Lambert::new(Vec3::splat(0.7));
    let glossy = Combined::new(Lambert::new(Vec3::splat(0.5)), Phong::new(Vec3::ONE, 80.0));
    let diffuse = tree.sampler(lambert);
    let shiny = tree.sampler(glossy);
    let mut shading = tree.shading(lambert);
    let queries: Vec<_> = (0..64)
        .map(|i| {
            Query::new(Vec3::new(i as f32 * 3.0, 100.0 - i as f32, 0.0), Vec3::Z)
                .unwrap()
                .with_view(Vec3::new(0.3, 0.2, 1.0))
                .unwrap()
        })
        .collect();
    let mut state = 0.0f64;
    let mut uniform = move || {
        // The golden-ratio sequence: enough spread, no allocation.
        state = (state + 0.618_033_988_749_895) % 1.0;
        state
    };
    let mut run = |check: &mut f64| {
        for query in &queries {
            for _ in 0..8 {
                if let Some(s) = diffuse.sample(query, uniform()) {
                    *check += s.pmf + diffuse.pmf(query, s.light);
                }
                if let Some(s) = shiny.sample(query, uniform()) {
                    *check += s.pmf + shiny.pmf(query, s.light);
                }
            }
            let r = shading
                .shade_stochastic(query, Threshold::relative(0.2), Unoccluded, &mut uniform)
                .unwrap();
            *check += r.radiance.x;
        }
    };
    let mut check = 0.0;
    run(&mut check);
    let before = allocations();
    run(&mut check);
    let after = allocations();
    assert!(check > 0.0);
    assert_eq!(
        after - before,
        0,
        "sampling allocated {} times",
        after - before
    );
}
