//! The tracer: a scene's view, the frame derived from it, and the options a walk
//! runs with (triangle test, exit test, x86-64-v3, lanes, locate grid). The walk
//! itself is in `walk.rs` (scalar), `simd/` (SSE, eight lanes), and the calls that pick
//! one are in `one_ray.rs` and `batch.rs`.

use octrace_format::layout::MAX_LEVEL;
use octrace_format::SceneView;

use super::fans::FanIndex;
use super::locate_grid::LocateGrid;
use super::tables::RuleScale;
use super::triangle::{intersect, intersect_f64, TriRay};
use super::watertight::Shear;

/// Traces rays through one scene. Cheap to build (no allocation): make one per batch.
#[derive(Clone, Debug)]
pub struct Tracer<'a> {
    pub(super) view: SceneView<'a>,
    pub(super) frame: TreeFrame,
    pub(super) test: TriangleTest,
    pub(super) exit: ExitTest,
    /// The top levels of point location as a grid, when the scene has one.
    pub(super) grid: Option<&'a LocateGrid>,
    /// The fans of the scene's crowded leaves, when built for it ([`FanIndex`]).
    pub(super) fans: Option<&'a FanIndex>,
    /// Whether the walks run the code compiled for x86-64-v3 (where the processor
    /// has it).
    pub(super) v3: bool,
    /// Whether batch calls may step eight walks at once (with `v3`).
    pub(super) lanes: bool,
    /// When batch calls walk incoherent rays in memory order (`order.rs`).
    pub(super) memory_order: MemoryOrder,
    /// Whether one-ray walks from inside the root ask for the next records before
    /// testing a leaf ([`Tracer::with_read_ahead`]).
    pub(super) read_ahead: bool,
}

/// What a tracer derives from a scene's parameters before it walks: the root cube and
/// mesh box, the cell edge at each level, the step bound, whether the cube map fits.
/// Computed once a scene ([`crate::Scene`] keeps it), so a tracer costs nothing to
/// make for a single ray.
#[derive(Clone, Copy, Debug)]
pub struct TreeFrame {
    pub(super) root_lo: [f32; 3],
    pub(super) root_hi: [f32; 3],
    /// The mesh's box, enlarged by [`box_slack`]: a ray that misses it misses every
    /// triangle, and a walk ends where the ray leaves it.
    pub(super) box_lo: [f32; 3],
    pub(super) box_hi: [f32; 3],
    /// `2^max_depth / root_size`: world to finest-grid coordinates.
    pub(super) grid_scale: f64,
    /// Cell edge at each level, `root_size / 2^level` (exact: the edge is a power of two).
    pub(super) sizes: [f32; 32],
    pub(super) max_depth: u32,
    pub(super) max_steps: u32,
    /// The cube map's level, when the map fits the tree (always, in a valid file; a
    /// hostile one on the trusted path enters from the root instead).
    pub(super) cube_level: Option<u32>,
    /// What decides each ray's exit rule (`tables::exit_rule`).
    pub(super) rule_scale: RuleScale,
    /// The box an origin must lie in to be walked from where it is: the root cube
    /// enlarged by [`FAR_ROOTS`] root edges on every side. A ray from farther out is
    /// re-originated where it enters the cube (`walk::Tracer::begin_far`).
    pub(super) near_lo: [f32; 3],
    pub(super) near_hi: [f32; 3],
    /// Whether the processor has x86-64-v3 (asked once, not per tracer).
    pub(super) v3: bool,
    /// Whether what walks read (leaf records, triangle references, triangles) is
    /// larger than half the processor's largest cache: walks then wait on memory
    /// ([`MemoryOrder::Auto`] sorts incoherent batches then).
    pub(super) outgrows_cache: bool,
}

impl TreeFrame {
    /// The frame of `view`'s tree.
    pub fn of(view: &SceneView<'_>) -> TreeFrame {
        let b = view.bounds;
        // The format's own limit: a file that claims more (on the trusted path) is
        // walked as if it said 20, so no shift overflows and the step bound holds.
        let max_depth = view.params.max_depth.min(MAX_LEVEL);
        let (root_lo, root_hi) = root_corners(view);
        let (box_lo, box_hi) = mesh_box(view);
        TreeFrame {
            root_lo,
            root_hi,
            box_lo,
            box_hi,
            grid_scale: (1u64 << max_depth) as f64 / b.root_size as f64,
            sizes: std::array::from_fn(|l| (b.root_size as f64 / (1u64 << l) as f64) as f32),
            max_depth,
            // A line crosses at most 3 * 2^depth planes of the finest grid, and each
            // step crosses one (or sits on an edge or corner and crosses one at no
            // distance, at most twice more): 3x that, plus slack for tiny trees. And a
            // line enters a convex cell once, so a walk visits no leaf more than three
            // times: 9x the leaves bounds it too, and the smaller bound wins (a small
            // hostile file claiming a deep tree ends its cycles sooner).
            max_steps: (9 * (1u32 << max_depth) + 64).min(9 * view.leaf_count().min(1 << 26) as u32 + 64),
            cube_level: Some(view.params.cube_level).filter(|&level| {
                let res = 1usize << level.min(MAX_LEVEL);
                level <= max_depth && view.cube_map.len() == 6 * res * res
            }),
            rule_scale: RuleScale::of(root_lo, root_hi, b.root_size),
            near_lo: root_lo.map(|c| (c as f64 - FAR_ROOTS * b.root_size as f64) as f32),
            near_hi: root_hi.map(|c| (c as f64 + FAR_ROOTS * b.root_size as f64) as f32),
            v3: wider_simd_available(),
            outgrows_cache: 2 * walked_bytes(view) > super::hw::last_level_cache(),
        }
    }
}

/// Bytes of what walks read: leaf records, triangle references, triangles.
fn walked_bytes(v: &SceneView<'_>) -> u64 {
    4 * (v.octree.len() + v.tri_refs.len() + v.triangles.len()) as u64
}

/// The ray/triangle test a tracer uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TriangleTest {
    /// Woop, Benthin & Wald's watertight test in `f32`: no ray passes between
    /// triangles that share an edge, but a ray within rounding of an edge or a vertex
    /// may be put on either side of it (a crossing listed twice or lost there, a hit
    /// on the neighbour). The GPU's default (`gpu::GpuOptions`), the renderers' test,
    /// and the CPU's in scenes with crowded fans ([`crate::Scene::tracer`]).
    Watertight,
    /// Möller & Trumbore: a ray through a shared edge can, rarely, miss both
    /// triangles.
    MollerTrumbore,
    /// Möller & Trumbore in `f64` (the oracle's arithmetic, `reference::intersect_f64`,
    /// on the `f32` ray and vertices): the slowest; for measuring what `f32` costs.
    F64,
    /// The watertight test as exact arithmetic decides it: the same `f32` edge
    /// functions with an error bound each, decided again on integers wherever a bound
    /// leaves a sign in doubt (a ray within rounding of an edge or a vertex, or nearly
    /// in a triangle's plane); distances correctly rounded from the exact quotient;
    /// of hits at the same rounded distance, the exactly nearer, then the lower input
    /// index; crossings in exact order. Answers equal exact arithmetic on the `f32`
    /// ray and vertices, with the stated rules: a ray in a triangle's plane meets it
    /// nowhere, a hit counts where its rounded distance lies in `[tmin, tmax]`, and
    /// the crossing queries' edge rule ([`crate::cpu::watertight::Shear::intersect_owned`])
    /// decides a ray exactly through an edge or a vertex. Leaves are tested whole (no
    /// fan hierarchies). The default ([`crate::Scene::tracer`] says where not): within
    /// 10 % of [`TriangleTest::Watertight`]'s speed on the standard ray sets
    /// (BENCHMARKS.md), the filter deciding almost every triangle.
    ///
    /// # Example
    /// ```
    /// use octrace_runtime::{Ray, Scene, TriangleTest};
    /// let mesh = octrace_bake::procedural::cube([-1.0; 3], [1.0; 3], 2);
    /// let scene = Scene::from_baked(octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto())?)?;
    /// let exact = scene.tracer().with_triangle_test(TriangleTest::Exact);
    /// // Straight through the vertex at the middle of a face: one triangle owns it.
    /// let ray = Ray::new([0.0, 0.0, -3.0].into(), [0.0, 0.0, 1.0].into());
    /// let crossings = exact.all_crossings(&ray);
    /// assert_eq!(crossings.len(), 2);
    /// assert_eq!((crossings[0].t, crossings[1].t), (2.0, 4.0));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    #[default]
    Exact,
}

/// [`TriangleTest`]s as the const parameters of the SIMD step.
pub(crate) const TEST_WATERTIGHT: u8 = 0;
pub(crate) const TEST_MOLLER_TRUMBORE: u8 = 1;
pub(crate) const TEST_F64: u8 = 2;
pub(crate) const TEST_EXACT: u8 = 3;

/// `with_tests!(tracer; ANY; f; args)` calls `f::<ANY, TEST, SLAB>(args)` with the
/// tracer's triangle and exit tests as const generics: one dispatch a call, none a step.
macro_rules! with_tests {
    ($tracer:expr; $any:tt; $($f:ident)::+; $($args:expr),*) => {{
        use $crate::cpu::tracer::{
            ExitTest as E, TriangleTest as T, TEST_EXACT, TEST_F64, TEST_MOLLER_TRUMBORE, TEST_WATERTIGHT,
        };
        match ($tracer.triangle_test(), $tracer.exit_test()) {
            (T::Watertight, E::Plucker) => $($f)::+::<$any, TEST_WATERTIGHT, false>($($args),*),
            (T::Watertight, E::Slab) => $($f)::+::<$any, TEST_WATERTIGHT, true>($($args),*),
            (T::MollerTrumbore, E::Plucker) => $($f)::+::<$any, TEST_MOLLER_TRUMBORE, false>($($args),*),
            (T::MollerTrumbore, E::Slab) => $($f)::+::<$any, TEST_MOLLER_TRUMBORE, true>($($args),*),
            (T::F64, E::Plucker) => $($f)::+::<$any, TEST_F64, false>($($args),*),
            (T::F64, E::Slab) => $($f)::+::<$any, TEST_F64, true>($($args),*),
            (T::Exact, E::Plucker) => $($f)::+::<$any, TEST_EXACT, false>($($args),*),
            (T::Exact, E::Slab) => $($f)::+::<$any, TEST_EXACT, true>($($args),*),
        }
    }};
}
pub(crate) use with_tests;

/// When the batch calls walk a batch in memory order: sorted by the cell of a 64^3
/// grid over the scene that each ray starts in, then by direction octant, so that rays
/// reading the same leaves follow each other. Only ever a batch of at least 4,096
/// rays that are not coherent already (camera rays, or shadow rays towards one light,
/// in pixel order walk the same leaves one after another and are left as given).
///
/// Measured on one thread (BENCHMARKS.md, "Memory order"): the dragon's incoherent
/// rays 1.5-1.6x faster sort included (a 64 MB scene, on a processor with 32 MiB of
/// last-level cache); the bunny's (7 MB) no faster, the sort then a cost.
///
/// # Example
/// ```
/// use octrace_bake::{bake, procedural, BuildParams};
/// use octrace_runtime::{MemoryOrder, Ray, Scene};
/// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
/// let rays = vec![Ray::new([0.0, 0.0, 3.0].into(), [0.0, 0.0, -1.0].into()); 8192];
/// let (mut sorted, mut given) = (vec![None; rays.len()], vec![None; rays.len()]);
/// scene.tracer().with_memory_order(MemoryOrder::Incoherent).intersect_batch(&rays, &mut sorted);
/// scene.tracer().with_memory_order(MemoryOrder::Off).intersect_batch(&rays, &mut given);
/// assert_eq!(sorted, given); // each ray's own answer, whatever the order
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MemoryOrder {
    /// Where the scene's walked arrays (records, references, triangles) are larger
    /// than half the processor's last-level cache (read from Linux's sysfs; 32 MiB
    /// assumed elsewhere): where the walks wait on memory (the default).
    #[default]
    Auto,
    /// Every incoherent batch, whatever the scene's size.
    Incoherent,
    /// Never: batches are walked as given.
    Off,
}

/// How a walk picks the face it leaves a leaf by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ExitTest {
    /// The paper's: the signs of three Plücker products with the edges at the exit
    /// corner, a 3-bit code into a table (the default).
    #[default]
    Plucker,
    /// Slab distances: the nearest of the three planes at the exit corner, compared
    /// (ties to the lowest axis). For measuring what the Plücker test buys.
    Slab,
}

/// What a walk did, for the cells view and for statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkStats {
    /// Leaves visited.
    pub leaves: u32,
    /// Triangle tests run.
    pub triangle_tests: u32,
    /// Whether the walk was stopped by [`Tracer::max_steps`] (never for a valid file:
    /// the bound is proven; a hostile file opened on the trusted path can reach it).
    pub stopped_at_bound: bool,
}

/// What a walk counts as it goes: [`WalkStats`] where a caller reads the counts,
/// nothing ([`NoTally`]) where none does. The one-ray calls counted for nobody:
/// 3 % of their instructions (callgrind, the bunny's camera rays: 1,449 a ray -> 1,407).
pub(crate) trait Tally {
    /// A leaf is visited.
    fn leaf(&mut self);
    /// `count` triangles are tested.
    fn tests(&mut self, count: u32);
    /// The walk reached the step bound.
    fn bound(&mut self);
}

impl Tally for WalkStats {
    #[inline(always)]
    fn leaf(&mut self) {
        self.leaves += 1;
    }
    #[inline(always)]
    fn tests(&mut self, count: u32) {
        self.triangle_tests = self.triangle_tests.saturating_add(count);
    }
    #[inline(always)]
    fn bound(&mut self) {
        self.stopped_at_bound = true;
    }
}

/// Counts nothing: the walks whose callers read no [`WalkStats`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct NoTally;

impl Tally for NoTally {
    #[inline(always)]
    fn leaf(&mut self) {}
    #[inline(always)]
    fn tests(&mut self, _: u32) {}
    #[inline(always)]
    fn bound(&mut self) {}
}

impl<'a> Tracer<'a> {
    /// Prepares a tracer for a validated view.
    pub fn new(view: SceneView<'a>) -> Tracer<'a> {
        let frame = TreeFrame::of(&view);
        Tracer::with_frame(view, frame)
    }

    /// A tracer over `view` with its frame computed already ([`TreeFrame::of`] the
    /// same view): what [`crate::Scene`]'s one-ray calls use, at no setup cost.
    #[inline]
    pub fn with_frame(view: SceneView<'a>, frame: TreeFrame) -> Tracer<'a> {
        Tracer {
            frame,
            view,
            test: TriangleTest::default(),
            exit: ExitTest::default(),
            grid: None,
            fans: None,
            v3: frame.v3,
            lanes: true,
            memory_order: MemoryOrder::Auto,
            read_ahead: true,
        }
    }

    /// The same tracer with or without the walk compiled for x86-64-v3 (AVX2, BMI;
    /// on by default where the processor has it, and never where it does not). Both
    /// give the same answers bit for bit; off runs the SSE2 baseline, for tests and
    /// comparisons.
    pub fn with_x86_64_v3(mut self, on: bool) -> Self {
        self.v3 = on && wider_simd_available();
        self
    }

    /// Whether the walks run the code compiled for x86-64-v3.
    pub fn uses_x86_64_v3(&self) -> bool {
        self.v3
    }

    /// The same tracer with or without the batch calls' eight-lane walk (on by
    /// default where the processor has x86-64-v3; off, batches step one walk at a time,
    /// several in flight). The answers are the same bits either way; off is for
    /// measuring what the lanes buy (the slab exit test always runs without them).
    pub fn with_lanes(mut self, on: bool) -> Self {
        self.lanes = on;
        self
    }

    /// Whether batch calls may use the eight-lane walk.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    pub(crate) fn uses_lanes(&self) -> bool {
        self.lanes
    }

    /// The same tracer with or without reading ahead in its one-ray walks. A walk that
    /// reads ahead asks, at each step, for the records across every face the ray can
    /// leave by (one face an axis; the first neighbour where a face has four) before
    /// it tests the leaf's triangles, so that the next record's load overlaps the
    /// tests: a lone walk has nothing else to overlap it with. Nearest-hit walks of
    /// rays that start inside the root cube read ahead (random and bounce rays, whose
    /// next records are seldom in the cache: one at a time, the bunny's and dragon's
    /// incoherent rays 1.06x and 1.17x, example `read_ahead`); rays from outside do
    /// not (camera rays, which find the records of the ray before them in the cache
    /// and lost 1-3 % to the extra loads), nor occlusion queries (shadow rays toward
    /// one light lost 2-5 %). On by default; the same answers either way. (The batch
    /// calls keep several walks in flight instead, and their eight-lane walk asks for
    /// its next records itself.)
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let ray = Ray::new([0.0, 0.1, 0.2].into(), [1.0, 0.3, 0.0].into()); // from inside
    /// assert!(scene.tracer().reads_ahead());
    /// let plain = scene.tracer().with_read_ahead(false);
    /// assert_eq!(plain.intersect(&ray), scene.tracer().intersect(&ray));
    /// assert!(plain.intersect(&ray).is_some());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn with_read_ahead(mut self, on: bool) -> Self {
        self.read_ahead = on;
        self
    }

    /// Whether the one-ray nearest-hit walks of rays from inside the root cube read
    /// ahead ([`Tracer::with_read_ahead`]).
    pub fn reads_ahead(&self) -> bool {
        self.read_ahead
    }

    /// Whether the scene's walked arrays outgrow the processor's cache (half its
    /// largest): what [`MemoryOrder::Auto`] goes by.
    pub(crate) fn outgrows_cache(&self) -> bool {
        self.frame.outgrows_cache
    }

    /// The same tracer with another rule for memory order in the batch calls
    /// ([`MemoryOrder`]; [`MemoryOrder::Auto`] by default). The answers, each ray's
    /// own, are the same under every rule.
    pub fn with_memory_order(mut self, rule: MemoryOrder) -> Self {
        self.memory_order = rule;
        self
    }

    /// The same tracer locating points with `grid` (built for this scene).
    #[inline]
    pub fn with_locate_grid(mut self, grid: &'a LocateGrid) -> Self {
        self.grid = Some(grid);
        self
    }

    /// The same tracer testing the leaves that `fans` (built for this scene) indexes
    /// through their hierarchies, or, with `None`, every triangle of every leaf. The
    /// answers are the same bits either way; a [`crate::Scene`]'s tracers have it.
    #[inline]
    pub fn with_fans(mut self, fans: Option<&'a FanIndex>) -> Self {
        self.fans = fans;
        self
    }

    /// The same tracer with another triangle test.
    pub fn with_triangle_test(mut self, test: TriangleTest) -> Self {
        self.test = test;
        self
    }

    /// The triangle test in use.
    pub fn triangle_test(&self) -> TriangleTest {
        self.test
    }

    /// The same tracer with another exit-face test.
    pub fn with_exit_test(mut self, exit: ExitTest) -> Self {
        self.exit = exit;
        self
    }

    /// The exit-face test in use.
    pub fn exit_test(&self) -> ExitTest {
        self.exit
    }

    /// Tests one triangle (nine floats) with the tracer's triangle test.
    #[inline(always)]
    pub(crate) fn hit_triangle(
        &self,
        shear: &Shear,
        tri: &TriRay,
        t: &[f32],
        tmin: f32,
        tmax: f32,
    ) -> Option<(f32, f32, f32)> {
        match self.test {
            TriangleTest::Watertight => shear.intersect(t, tmin, tmax),
            TriangleTest::MollerTrumbore => intersect(tri, t, tmin, tmax),
            TriangleTest::F64 => intersect_f64(tri, t, tmin, tmax),
            TriangleTest::Exact => shear.intersect_exact(t, tmin, tmax),
        }
    }

    /// The view this tracer reads.
    pub fn view(&self) -> &SceneView<'a> {
        &self.view
    }

    /// The most leaves one walk may visit; see the module docs.
    pub fn max_steps(&self) -> u32 {
        self.frame.max_steps
    }

    /// The root cube's low corner.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    pub(crate) fn root_lo(&self) -> [f32; 3] {
        self.frame.root_lo
    }

    /// The root cube, as its two corners.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn root_box(&self) -> ([f32; 3], [f32; 3]) {
        (self.frame.root_lo, self.frame.root_hi)
    }

    /// The (enlarged) mesh box a walk is clipped to: a ray that misses it cannot hit.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn walked_box(&self) -> ([f32; 3], [f32; 3]) {
        (self.frame.box_lo, self.frame.box_hi)
    }

    /// Cell edges by level (32 of them: a level masked to five bits indexes it).
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn cell_sizes(&self) -> &[f32; 32] {
        &self.frame.sizes
    }

    /// The edge of a cell at `level` (masked into the table: a hostile level cannot
    /// index out of bounds).
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn cell_size(&self, level: u32) -> f32 {
        self.frame.sizes[level as usize & 31]
    }
}

/// Whether this processor runs the walks compiled for x86-64-v3.
fn wider_simd_available() -> bool {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    return super::hw::x86_64_v3();
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    false
}

/// How many root edges outside the root cube an origin may lie and still be walked
/// from where it is; a ray from farther out is re-originated where it enters the cube
/// (`walk::Tracer::begin_far`). Cameras of the standard sets stand about 2.3 root
/// edges from the centre, and keep their bits.
pub const FAR_ROOTS: f64 = 4.0;

/// Relative slack on the distance where a ray leaves the mesh box: f32 distances far
/// from the origin carry a relative error of a few ulps (2^-21); this is 32 times that.
pub(crate) const BOX_T_SLACK: f32 = 1.0 / (1 << 16) as f32;

/// How far the mesh box is enlarged on every side: 2^-16 of the root edge, and at least
/// 16 f32 spacings of the root's largest coordinate, so that rounding in the clip never
/// moves a triangle on the box's faces outside it.
pub(crate) fn box_slack(root_lo: [f32; 3], root_hi: [f32; 3], root_size: f32) -> f32 {
    let largest = root_lo.iter().chain(&root_hi).fold(0.0f32, |m, c| m.max(c.abs()));
    (root_size / (1 << 16) as f32).max(16.0 * f32::EPSILON * largest)
}

/// The mesh box enlarged on every side (by 2^-16 of the root edge, and at least 16 f32
/// spacings of the root's largest coordinate), as the walks clip to it.
pub fn mesh_box(view: &SceneView<'_>) -> ([f32; 3], [f32; 3]) {
    let b = view.bounds;
    let (root_lo, root_hi) = root_corners(view);
    let slack = box_slack(root_lo, root_hi, b.root_size);
    (b.mesh_lo.map(|c| c - slack), b.mesh_hi.map(|c| c + slack))
}

/// The root cube's low and high corners, as the format computes cell planes.
pub fn root_corners(view: &SceneView<'_>) -> ([f32; 3], [f32; 3]) {
    let b = view.bounds;
    let r = octrace_format::layout::cell_box(b.root_lo, b.root_size, 0, [0; 3]);
    ([r[0], r[1], r[2]], [r[3], r[4], r[5]])
}
