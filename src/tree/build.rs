//! Building the tree: an adaptive octree over point lights, along the
//! Morton order of their positions (see [`TreeBuilder`] for the shape),
//! and the tree's constructors. The passes after the shape are the
//! statistics pass's ([`statistics_pass`](super::statistics_pass)).

use glam::{DVec3, Vec3};

use super::check::check_and_bound;
use super::layout::LightTree;
use super::morton;
use super::node::Node;
use super::options::TreeBuilder;
use super::pool::Pool;
use super::statistics_pass::fill_nodes;
use crate::emission::{Emitter, Kind, Profile};
use crate::geometry::Aabb;
use crate::{BuildError, PointLight};

impl LightTree {
    /// Builds a tree with the default options of [`TreeBuilder`].
    ///
    /// An empty slice gives an empty tree, which shades to zero with zero
    /// error.
    ///
    /// # Errors
    /// A [`BuildError`] naming the first light with a non-finite or
    /// out-of-range position, or a non-finite or negative intensity channel.
    pub fn build(lights: &[PointLight]) -> Result<Self, BuildError> {
        TreeBuilder::new().build(lights)
    }

    /// Builds a tree of lights with emission profiles (spot lights, virtual
    /// point lights; see [`Emission`](crate::Emission)) with the default
    /// options of [`TreeBuilder`]. Every shading call, bound and the exact
    /// reference then use each light's profile.
    ///
    /// A slice whose every light is isotropic gives the tree
    /// [`build`](Self::build) gives of its lights, bit for bit, with no
    /// memory for profiles.
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{Emission, Lambert, LightTree, PointLight, Threshold};
    ///
    /// // Street lamps aimed at the ground: glTF spots, 20 and 40 degrees.
    /// let lamps: Vec<_> = (0..400)
    ///     .map(|i| {
    ///         let at = Vec3::new((i % 20) as f32 * 10.0, (i / 20) as f32 * 10.0, 6.0);
    ///         let spot = Emission::spot(Vec3::NEG_Z, 20f32.to_radians(), 40f32.to_radians());
    ///         PointLight::new(at, Vec3::splat(50.0)).with_emission(spot)
    ///     })
    ///     .collect();
    /// let tree = LightTree::build_emitters(&lamps)?;
    /// let mut shading = tree.shading(Lambert::new(Vec3::splat(0.5)));
    /// let (p, n) = (Vec3::new(52.0, 48.0, 0.0), Vec3::Z);
    /// let r = shading.shade(p, n, Threshold::relative(0.01))?;
    /// assert!(r.certifies(shading.exact(p, n)?));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// As [`build`](Self::build), and [`BuildError::InvalidEmission`] for a
    /// profile out of range (a zero or non-finite axis, an exponent outside
    /// `[0, 1e4]`, spot angles outside `0 <= inner <= outer <= pi/2`,
    /// `outer > 0`), naming the first such light.
    pub fn build_emitters(emitters: &[Emitter]) -> Result<Self, BuildError> {
        TreeBuilder::new().build_emitters(emitters)
    }

    /// Rebuilds this tree over `emitters` with the options it was built
    /// with, in the memory it holds: the tree
    /// [`build_emitters`](Self::build_emitters) gives.
    ///
    /// # Errors
    /// As [`build_emitters`](Self::build_emitters); the tree is then left
    /// as it was.
    pub fn rebuild_emitters(&mut self, emitters: &[Emitter]) -> Result<(), BuildError> {
        let options = self.options;
        options.rebuild_emitters(self, emitters)
    }

    /// A builder carrying the options (maximum lights per leaf, maximum depth).
    ///
    /// With the `rayon` feature, its `build_parallel` and `rebuild_parallel`
    /// build on rayon's thread pool: `LightTree::builder().build_parallel(..)`
    /// gives the tree [`build`](Self::build) gives, bit for bit.
    pub fn builder() -> TreeBuilder {
        TreeBuilder::new()
    }

    /// Rebuilds this tree over `lights` with the options it was built with,
    /// in the memory it holds: the tree [`TreeBuilder::build`] gives, bit
    /// for bit (see [`TreeBuilder::rebuild`]).
    ///
    /// ```
    /// use glam::Vec3;
    /// use manylights::{LightTree, PointLight};
    ///
    /// let mut lights: Vec<PointLight> = (0..1000)
    ///     .map(|i| PointLight::new(Vec3::new((i % 40) as f32, (i / 40) as f32, 5.0), Vec3::ONE))
    ///     .collect();
    /// let mut tree = LightTree::build(&lights)?;
    /// // Next frame: some lights switched off, a new one on.
    /// lights.truncate(600);
    /// lights.push(PointLight::new(Vec3::new(3.0, 4.0, 6.0), Vec3::splat(2.0)));
    /// tree.rebuild(&lights)?;
    /// assert_eq!(tree.len(), 601);
    /// # Ok::<(), manylights::BuildError>(())
    /// ```
    ///
    /// On rayon's thread pool (with the `rayon` feature), the builder of the
    /// same options rebuilds it: `TreeBuilder::rebuild_parallel`.
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was.
    pub fn rebuild(&mut self, lights: &[PointLight]) -> Result<(), BuildError> {
        let options = self.options;
        options.rebuild(self, lights)
    }
}

impl TreeBuilder {
    /// Builds the tree.
    ///
    /// The sort is linear, and so are the node statistics: each leaf sums
    /// its lights' moments (up to degree 5) once, and every other node
    /// shifts its children's moments to its own centroid, with a certified
    /// bound on the rounding carried along (see
    /// [`Node::moment_error`](crate::shader::Node::moment_error)). The radii stay
    /// exact (the farthest member, rounded up): a leaf measures its lights'
    /// distances from the offsets its moment sums take, and every other
    /// node looks for its farthest member through its subtree, skipping the
    /// subtrees that its children's radii show cannot hold it, so that it
    /// reads the lights of a few leaves rather than all of its own. Memory
    /// `O(n)`.
    ///
    /// # Errors
    /// [`BuildError`] for a light with a non-finite or out-of-range
    /// coordinate, a non-finite or negative intensity channel (naming the
    /// first such light), more than `u32::MAX` lights, or
    /// `max_leaf_lights == 0`.
    pub fn build(&self, lights: &[PointLight]) -> Result<LightTree, BuildError> {
        self.build_on(lights, Pool::ONE)
    }

    /// Builds the tree of lights with emission profiles (see
    /// [`LightTree::build_emitters`]): as [`build`](Self::build), the
    /// lights split by the direction of their axes first where
    /// [`group_by_axis`](Self::group_by_axis) says so, and each node
    /// bounding its members' axes and profiles.
    ///
    /// # Errors
    /// As [`LightTree::build_emitters`].
    pub fn build_emitters(&self, emitters: &[Emitter]) -> Result<LightTree, BuildError> {
        let mut tree = self.build_on(&[], Pool::ONE)?;
        self.rebuild_emitters(&mut tree, emitters)?;
        Ok(tree)
    }

    /// Rebuilds `tree` over `emitters` with these options, in the memory
    /// the tree holds, as [`rebuild`](Self::rebuild) does for isotropic
    /// lights.
    ///
    /// # Errors
    /// As [`LightTree::build_emitters`]; the tree is then left as it was.
    pub fn rebuild_emitters(
        &self,
        tree: &mut LightTree,
        emitters: &[Emitter],
    ) -> Result<(), BuildError> {
        let mut profiles = Vec::with_capacity(emitters.len());
        for (index, e) in emitters.iter().enumerate() {
            let profile = e
                .emission
                .profile()
                .map_err(|reason| BuildError::InvalidEmission { index, reason })?;
            profiles.push(profile);
        }
        let lights: Vec<PointLight> = emitters.iter().map(|e| e.light).collect();
        if profiles.iter().all(|p| p.kind == Kind::Isotropic) {
            return self.build_into(tree, &lights, None, Pool::ONE);
        }
        let classes: Option<Vec<u8>> = self
            .group_by_axis
            .then(|| profiles.iter().map(axis_class).collect());
        self.build_into(tree, &lights, classes.as_deref(), Pool::ONE)?;
        let order = &tree.order;
        let mut orientation = tree.orientation.take().unwrap_or_default();
        orientation.profiles.clear();
        orientation
            .profiles
            .extend(order.iter().map(|&k| profiles[k as usize]));
        tree.orientation = Some(orientation);
        // The slab bound is for isotropic lights.
        tree.slabs.clear();
        tree.fill_cones();
        Ok(())
    }

    /// [`build`](Self::build) spread over rayon's thread pool (with the
    /// `rayon` feature): the same tree, bit for bit, and the same errors.
    ///
    /// The node statistics (sums, radii and moments), most of a build's
    /// work, are computed subtree by subtree side by side (the calling
    /// thread takes subtrees too), then the few nodes above those subtrees;
    /// from 8,192 lights on. The lighter passes (the checks, the Morton
    /// codes, the sort's buckets, the gathering of the lights and the
    /// planes) run in parallel from 524,288 lights on, below which waking
    /// the pool's threads costs more than they gain. The split into nodes
    /// stays on the calling thread. A pool of one thread builds on the
    /// calling thread.
    ///
    /// # Errors
    /// As [`build`](Self::build).
    #[cfg(feature = "rayon")]
    pub fn build_parallel(&self, lights: &[PointLight]) -> Result<LightTree, BuildError> {
        self.build_on(lights, Pool::for_lights(lights.len()))
    }

    /// Rebuilds `tree` over `lights` with these options, in the memory the
    /// tree holds: the same tree, bit for bit, as [`build`](Self::build)
    /// gives. The tree keeps these options for [`LightTree::rebuild`].
    ///
    /// For scenes whose lights change from frame to frame (lights switched
    /// on and off, added or removed). A fresh build writes its tree into
    /// new memory, which the operating system maps page by page where the
    /// allocator takes it from the system, as it does for the arrays of
    /// millions of lights; a rebuild writes over the memory the tree holds,
    /// growing it only where the new tree is larger (the build's own
    /// working arrays are still taken afresh). So a rebuild gains where the
    /// allocator would map a fresh build's arrays afresh, for large trees,
    /// and costs about what a build does where it hands back memory it has
    /// already mapped. The build table of `cargo run --release -p
    /// manylights-report -- bounds` times both and counts their page
    /// faults (the repository's `docs/tuning.md` records a measurement).
    /// Lights that only move, in the same number, are cheaper still to
    /// [`refit`](LightTree::refit).
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was (the
    /// lights are checked before it is touched).
    pub fn rebuild(&self, tree: &mut LightTree, lights: &[PointLight]) -> Result<(), BuildError> {
        self.build_into(tree, lights, None, Pool::ONE)
    }

    /// [`rebuild`](Self::rebuild) spread over rayon's thread pool (with the
    /// `rayon` feature), as [`build_parallel`](Self::build_parallel): the
    /// same tree, bit for bit.
    ///
    /// # Errors
    /// As [`build`](Self::build); the tree is then left as it was.
    #[cfg(feature = "rayon")]
    pub fn rebuild_parallel(
        &self,
        tree: &mut LightTree,
        lights: &[PointLight],
    ) -> Result<(), BuildError> {
        self.build_into(tree, lights, None, Pool::for_lights(lights.len()))
    }

    fn build_on(&self, lights: &[PointLight], pool: Pool) -> Result<LightTree, BuildError> {
        let mut tree = LightTree {
            nodes: Vec::new(),
            lights: Vec::new(),
            order: Vec::new(),
            depth: 0,
            planes: Vec::new(),
            node_planes: Vec::new(),
            groups: Default::default(),
            options: *self,
            orientation: None,
            slabs: Default::default(),
        };
        self.build_into(&mut tree, lights, None, pool)?;
        Ok(tree)
    }

    /// Builds the tree of `lights` into `tree`, reusing its memory; `tree`
    /// is left as it was on an error. With `classes` (one per light), the
    /// lights are split by class first (see [`axis_class`]); the caller
    /// then sets the tree's orientation, which this leaves empty.
    fn build_into(
        &self,
        tree: &mut LightTree,
        lights: &[PointLight],
        classes: Option<&[u8]>,
        pool: Pool,
    ) -> Result<(), BuildError> {
        if self.max_leaf_lights == 0 {
            return Err(BuildError::InvalidOption("max_leaf_lights must be >= 1"));
        }
        if lights.len() > u32::MAX as usize {
            return Err(BuildError::TooManyLights {
                count: lights.len(),
                max: u32::MAX as usize,
            });
        }
        // The checks and the scene's box in one read of the lights.
        let scene = check_and_bound(lights, pool.cheap(lights.len()))?;

        let n = lights.len();
        // Kept for its memory; the caller refills it for emitters.
        if let Some(o) = tree.orientation.as_mut() {
            o.profiles.clear();
            o.cones.clear();
        }
        let kept = tree.orientation.take();
        if classes.is_some() {
            tree.orientation = kept;
        }
        tree.options = *self;
        tree.depth = 0;
        if n == 0 {
            tree.nodes.clear();
            tree.lights.clear();
            tree.order.clear();
            tree.planes.clear();
            tree.node_planes.clear();
            tree.slabs.clear();
            tree.groups.refill_from_notes(&[], &mut [], Pool::ONE);
            return Ok(());
        }
        let cheap = pool.cheap(n);
        let levels = sort_lights(tree, lights, classes, scene, cheap);
        // Breadth-first: children of a node are appended together, so they
        // are contiguous. The shape comes first, in compact records (lights
        // and children of each node, and its depth); the nodes are made
        // from it in one allocation, and their statistics follow,
        // bottom-up.
        let shapes = self.shapes(tree, &levels);
        drop(levels);
        cheap.map_into(&shapes, &mut tree.nodes, Shape::node);
        drop(shapes);
        fill_nodes(tree, pool);
        Ok(())
    }

    /// The shapes of the tree's nodes, breadth-first, from the split
    /// levels of its lights' sorted Morton codes (see
    /// [`morton::split_levels`]); sets the tree's depth, and reorders the
    /// lights (and their indices) that a median split halves.
    fn shapes(&self, tree: &mut LightTree, levels: &[u8]) -> Vec<Shape> {
        let mut shapes = vec![Shape {
            first_light: 0,
            light_count: tree.lights.len() as u32,
            first_child: 0,
            child_count: 0,
            depth: 0,
        }];
        let mut i = 0;
        while i < shapes.len() {
            let shape = shapes[i];
            let range = shape.lights();
            tree.depth = tree.depth.max(shape.depth);
            if range.len() > self.max_leaf_lights && shape.depth < self.max_depth {
                // The octree cell's occupied sub-cells at the first level
                // where the codes differ; lights in one finest cell are
                // halved at their median instead.
                let groups = match morton::children(
                    &levels[range.start..range.end - 1],
                    self.max_leaf_lights,
                ) {
                    Some(groups) => groups,
                    None => median_split(
                        &mut tree.lights[range.clone()],
                        &mut tree.order[range.clone()],
                    ),
                };
                if groups.len() > 1 {
                    shapes[i].first_child = shapes.len() as u32;
                    shapes[i].child_count = groups.len() as u32;
                    for g in groups {
                        shapes.push(Shape {
                            first_light: (range.start + g.start) as u32,
                            light_count: g.len() as u32,
                            first_child: 0,
                            child_count: 0,
                            depth: shape.depth + 1,
                        });
                    }
                }
            }
            i += 1;
        }
        shapes
    }
}

/// Sorts `lights` (whose box is `scene`) once along the Morton curve and
/// gathers them into that order, into the tree's lights and their indices
/// into its order, on `pool`: every octree cell is then a contiguous run,
/// and every later pass over a node's lights reads memory in sequence.
/// Returns the split levels of the sorted codes (see
/// [`morton::split_levels`]).
fn sort_lights(
    tree: &mut LightTree,
    lights: &[PointLight],
    classes: Option<&[u8]>,
    scene: Aabb,
    pool: Pool,
) -> Vec<u8> {
    let grid = morton::Grid::over(scene);
    let mut unsorted = grid.codes_of(lights, pool);
    if let Some(classes) = classes {
        // The class takes the codes' top digit (the root's split); the
        // cells below lose their finest level, which median splits make
        // up for.
        for (code, &class) in unsorted.iter_mut().zip(classes) {
            *code = u64::from(class) << 60 | *code >> 3;
        }
    }
    // Median splits reorder lights within a run of equal codes only, so
    // the sorted codes stay valid for every run.
    let codes = morton::sort_into(&unsorted, pool, &mut tree.order);
    // Freed before the arrays that follow are taken, which can reuse
    // its memory.
    drop(unsorted);
    pool.map_into(&tree.order, &mut tree.lights, |&k| lights[k as usize]);
    // Each node's sub-cells are read off the levels at which
    // neighbouring codes first differ (one byte a light, scanned in
    // sequence) rather than searched for in the codes, whose reads at
    // each node's ends would miss the cache.
    morton::split_levels(&codes)
}

/// The class of a profile's axis for [`TreeBuilder::group_by_axis`]: its
/// dominant coordinate and sign (0 to 5), two-sided axes taken pointing
/// into the positive half of that coordinate; isotropic lights form class 6.
fn axis_class(p: &Profile) -> u8 {
    if p.kind == Kind::Isotropic {
        return 6;
    }
    let a = p.axis;
    let abs = a.abs();
    let (axis, value) = if abs.x >= abs.y && abs.x >= abs.z {
        (0, a.x)
    } else if abs.y >= abs.z {
        (1, a.y)
    } else {
        (2, a.z)
    };
    2 * axis + u8::from(value < 0.0 && !p.two_sided)
}

/// Halves a run of lights (and their original indices, kept in step) at
/// the median position along the box's longest axis: two ranges, or one
/// when all lights coincide. Used for lights that share a finest Morton
/// cell (exponentially clustered lights, at `2^-k` say): halving the count
/// bounds the extra depth by `log2(n)`.
fn median_split(
    lights: &mut [PointLight],
    order: &mut [u32],
) -> smallvec::SmallVec<[core::ops::Range<usize>; 8]> {
    let aabb = lights
        .iter()
        .fold(Aabb::EMPTY, |b, l| b.union_point(l.position));
    let extent = aabb.max - aabb.min;
    let mut out = smallvec::SmallVec::new();
    if extent.max_element() <= 0.0 {
        // All lights coincide: nothing can separate them.
        out.push(0..lights.len());
        return out;
    }
    let axis = extent.max_position();
    let mut pairs: Vec<(PointLight, u32)> =
        lights.iter().copied().zip(order.iter().copied()).collect();
    let mid = pairs.len() / 2;
    pairs.select_nth_unstable_by(mid, |a, b| {
        a.0.position[axis].total_cmp(&b.0.position[axis])
    });
    for ((l, o), (pl, po)) in lights.iter_mut().zip(order.iter_mut()).zip(pairs) {
        (*l, *o) = (pl, po);
    }
    out.push(0..mid);
    out.push(mid..lights.len());
    out
}

/// A node's place in the tree while the build shapes it: its lights (leaf
/// order), its children and its depth.
#[derive(Clone, Copy, Debug)]
struct Shape {
    first_light: u32,
    light_count: u32,
    first_child: u32,
    child_count: u32,
    depth: u32,
}

impl Shape {
    fn lights(&self) -> core::ops::Range<usize> {
        self.first_light as usize..(self.first_light + self.light_count) as usize
    }

    /// The node of this shape, with no statistics yet.
    fn node(&self) -> Node {
        Node {
            intensity: DVec3::ZERO,
            weight: 0.0,
            moment_error: 0.0,
            centroid: Vec3::ZERO,
            radius: 0.0,
            channel_offsets: [Vec3::ZERO; 3],
            channel_covariances: [[0.0; 6]; 3],
            harmonic_norms: [Vec3::ZERO; 3],
            aabb: Aabb::EMPTY,
            first_light: self.first_light,
            light_count: self.light_count,
            first_child: self.first_child,
            child_count: self.child_count,
        }
    }
}

#[cfg(test)]
mod test_trees {
    use glam::Vec3;

    use crate::{BuildError, LightTree, PointLight, TreeBuilder};

    /// Lights enough for the pool: clusters of street lights, a tilted roof
    /// of lights exactly in one plane, and coincident lights.
    pub(super) fn lights(seed: u64, count: usize) -> Vec<PointLight> {
        let mut state = seed;
        let mut uniform = move || crate::testing::uniform(&mut state);
        (0..count)
            .map(|i| {
                let p = match i % 5 {
                    0 => Vec3::new(uniform() * 2000.0, uniform() * 2000.0, 6.0),
                    1 => {
                        // z = (x + y) / 4 on the integers: exactly one plane.
                        let (x, y) = ((uniform() * 64.0).floor(), (uniform() * 64.0).floor());
                        Vec3::new(x, y, (x + y) * 0.25)
                    }
                    2 => Vec3::new(500.0, 500.0, 20.0),
                    _ => Vec3::new(uniform() * 300.0, uniform() * 300.0, uniform() * 90.0),
                };
                PointLight::new(p, Vec3::new(uniform(), uniform() * 3.0, uniform() * 0.5))
            })
            .collect()
    }

    pub(super) fn assert_same(a: &LightTree, b: &LightTree) {
        assert_eq!(a.nodes, b.nodes);
        assert_eq!(a.lights, b.lights);
        assert_eq!(a.order, b.order);
        assert_eq!(a.depth, b.depth);
        assert_eq!(a.planes, b.planes);
        assert_eq!(a.node_planes, b.node_planes);
        assert_eq!(a.groups, b.groups);
        assert_eq!(a.options, b.options);
    }

    /// A rebuild gives the tree a fresh build gives, whatever the tree held
    /// before: more lights, fewer, none, or a tilted plane no longer there;
    /// and it keeps the options the tree was built with.
    #[test]
    fn a_rebuild_gives_the_tree_of_a_fresh_build() {
        let many = lights(11, 30_000);
        let flat: Vec<PointLight> = lights(12, 9_000)
            .into_iter()
            .map(|l| PointLight::new(l.position.with_z(4.0), l.intensity))
            .collect();
        let builder = TreeBuilder::new().max_leaf_lights(5).max_depth(12);
        let mut tree = LightTree::build(&[]).unwrap();
        for (options, scene) in [
            (TreeBuilder::new(), &many[..]),
            (TreeBuilder::new(), &many[..700]),
            (builder, &flat[..]),
            (builder, &many[..]),
            (TreeBuilder::new(), &[][..]),
            (TreeBuilder::new(), &many[5..20_000]),
        ] {
            options.rebuild(&mut tree, scene).unwrap();
            assert_same(&tree, &options.build(scene).unwrap());
            assert!(tree.validate().is_ok());
        }
        // The options it was last built with.
        let mut tree = builder.build(&many[..100]).unwrap();
        tree.rebuild(&flat).unwrap();
        assert_same(&tree, &builder.build(&flat).unwrap());
    }

    /// A rebuild over lights it cannot build leaves the tree as it was.
    #[test]
    fn a_failed_rebuild_leaves_the_tree_as_it_was() {
        let mut scene = lights(13, 4_000);
        let mut tree = LightTree::build(&scene).unwrap();
        let before = tree.clone();
        scene[3_210].position.y = f32::NAN;
        assert_eq!(
            tree.rebuild(&scene),
            Err(BuildError::NonFinitePosition { index: 3_210 })
        );
        assert_same(&tree, &before);
        assert_eq!(
            TreeBuilder::new()
                .max_leaf_lights(0)
                .rebuild(&mut tree, &scene[..10]),
            Err(BuildError::InvalidOption("max_leaf_lights must be >= 1"))
        );
        assert_same(&tree, &before);
    }
}

#[cfg(all(test, feature = "rayon"))]
mod parallel {
    use glam::Vec3;

    use super::test_trees::{assert_same, lights};
    use crate::{BuildError, LightTree, PointLight, TreeBuilder};

    /// `f` on a pool of two threads, whatever the machine has.
    fn on_two_threads<T: Send>(f: impl FnOnce() -> T + Send) -> T {
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(f)
    }

    #[test]
    fn a_parallel_build_and_refit_give_the_tree_of_one_thread() {
        let lights = lights(5, 60_000);
        let one = LightTree::build(&lights).unwrap();
        let pool = on_two_threads(|| LightTree::builder().build_parallel(&lights).unwrap());
        assert!(!one.planes.is_empty(), "the roof is recorded as a plane");
        assert_same(&one, &pool);

        let builder = TreeBuilder::new().max_leaf_lights(3).max_depth(9);
        let one = builder.build(&lights).unwrap();
        let mut pool = on_two_threads(|| builder.build_parallel(&lights).unwrap());
        assert_same(&one, &pool);

        let moved: Vec<PointLight> = lights
            .iter()
            .map(|l| PointLight::new(l.position * 0.5 - Vec3::ONE, l.intensity * 2.0))
            .collect();
        let mut one = one;
        one.refit(&moved).unwrap();
        on_two_threads(|| pool.refit_parallel(&moved).unwrap());
        assert_same(&one, &pool);

        // Rebuilt in place on the pool, over fewer lights and then more.
        on_two_threads(|| {
            builder
                .rebuild_parallel(&mut pool, &lights[..20_000])
                .unwrap()
        });
        assert_same(&builder.build(&lights[..20_000]).unwrap(), &pool);
        on_two_threads(|| builder.rebuild_parallel(&mut pool, &moved).unwrap());
        assert_same(&builder.build(&moved).unwrap(), &pool);
    }

    #[test]
    fn a_parallel_build_reports_the_first_bad_light() {
        let mut lights = lights(9, 50_000);
        lights[41_234].intensity.y = f32::NAN;
        lights[45_000].position.x = f32::INFINITY;
        let one = LightTree::build(&lights).unwrap_err();
        let pool = on_two_threads(|| LightTree::builder().build_parallel(&lights).unwrap_err());
        assert_eq!(one, BuildError::NonFiniteIntensity { index: 41_234 });
        assert_eq!(one, pool);

        let mut tree = LightTree::build(&lights[..40_000]).unwrap();
        lights[33_000].intensity.z = -1.0;
        let refit = on_two_threads(|| tree.refit_parallel(&lights[3_001..43_001]).unwrap_err());
        assert_eq!(refit, BuildError::NegativeIntensity { index: 29_999 });
    }
}
