//! The octree walk of Portalez & Duguet 2016 (section 4.2.3): enter a leaf, test its
//! triangles, leave through the face the Plücker signs give, follow the link.
//!
//! What the paper leaves out, and this walk does:
//! * a triangle hit beyond the current leaf's exit is kept as a candidate but not
//!   returned until the walk reaches a leaf whose exit lies beyond it, so the result
//!   is the nearest hit whatever leaf a triangle is listed in;
//! * rays that start inside the root cube start in the leaf holding their first point,
//!   found by descending the point-location tree; rays from outside enter through the
//!   cube map, which holds a leaf or the node to descend from;
//! * a walk is bounded by [`Tracer::max_steps`] whatever the file holds.
//!
//! # Termination
//! In exact arithmetic each leaf the walk visits either holds a piece of the ray of
//! positive length, and these pieces follow each other along the ray, or is crossed
//! at a single point where the ray passes through an edge or a corner. A line meets at
//! most `3 * 2^depth + 1` cells of the finest grid, so at most that many leaves hold a
//! piece of positive length; between two of them the ray passes at most one corner,
//! where at most two leaves (of the up to eight around it) are crossed at a point. So a
//! walk visits at most `3 * (3 * 2^depth + 1)` leaves; [`Tracer::max_steps`] adds a
//! margin for rounding (`9 * 2^depth + 64`). The loop stops there in every build, so no
//! file, trusted or not, makes a walk loop forever; [`WalkStats::stopped_at_bound`]
//! says when a walk was stopped, and the hard-case suite checks that no walk through a
//! valid file ever is.

use octrace_format::layout::{
    links_before, other_axes, texel_index, NodeRef, COARSER_SHIFT, LEAF_HEADER_WORDS, MAX_LEVEL, TRIANGLE_FLOATS,
};
use octrace_format::SceneView;

use super::tables::{exit_code, octant, EXIT_FACE};
pub(crate) use super::triangle::{intersect, intersect_f64, TriRay};
use super::watertight::Shear;
use crate::ray::{Hit, Ray};

/// Traces rays through one scene. Cheap to build (no allocation): make one per batch.
#[derive(Clone, Debug)]
pub struct Tracer<'a> {
    view: SceneView<'a>,
    frame: TreeFrame,
    test: TriangleTest,
    exit: ExitTest,
    /// The top levels of point location as a grid, when the scene has one.
    grid: Option<&'a LocateGrid>,
    /// Whether the walks run the code compiled for x86-64-v3 (where the processor
    /// has it).
    v3: bool,
    /// Whether batch calls may step eight walks at once (with `v3`).
    lanes: bool,
}

/// What a tracer derives from a scene's parameters before it walks: the root cube and
/// mesh box, the cell edge at each level, the step bound, whether the cube map fits.
/// Computed once a scene ([`crate::Scene`] keeps it), so a tracer costs nothing to
/// make for a single ray.
#[derive(Clone, Copy, Debug)]
pub struct TreeFrame {
    root_lo: [f32; 3],
    root_hi: [f32; 3],
    /// The mesh's box, enlarged by [`box_slack`]: a ray that misses it misses every
    /// triangle, and a walk ends where the ray leaves it.
    box_lo: [f32; 3],
    box_hi: [f32; 3],
    /// `2^max_depth / root_size`: world to finest-grid coordinates.
    grid_scale: f64,
    /// Cell edge at each level, `root_size / 2^level` (exact: the edge is a power of two).
    sizes: [f32; 32],
    max_depth: u32,
    max_steps: u32,
    /// The cube map's level, when the map fits the tree (always, in a valid file; a
    /// hostile one on the trusted path enters from the root instead).
    cube_level: Option<u32>,
    /// Whether the processor has x86-64-v3 (asked once, not per tracer).
    v3: bool,
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
            v3: wider_simd_available(),
        }
    }
}

/// The ray/triangle test a tracer uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TriangleTest {
    /// Woop, Benthin & Wald's watertight test: no ray passes between triangles that
    /// share an edge (the default).
    #[default]
    Watertight,
    /// Möller & Trumbore: a ray through a shared edge can, rarely, miss both
    /// triangles.
    MollerTrumbore,
    /// Möller & Trumbore in `f64` (the oracle's arithmetic, `reference::intersect_f64`,
    /// on the `f32` ray and vertices): the slowest; for measuring what `f32` costs.
    F64,
}

/// [`TriangleTest`]s as the const parameters of the SIMD step.
pub(crate) const TEST_WATERTIGHT: u8 = 0;
pub(crate) const TEST_MOLLER_TRUMBORE: u8 = 1;
pub(crate) const TEST_F64: u8 = 2;

/// `with_tests!(tracer; ANY; f; args)` calls `f::<ANY, TEST, SLAB>(args)` with the
/// tracer's triangle and exit tests as const generics: one dispatch a call, none a step.
macro_rules! with_tests {
    ($tracer:expr; $any:tt; $($f:ident)::+; $($args:expr),*) => {{
        use $crate::cpu::traverse::{ExitTest as E, TriangleTest as T, TEST_F64, TEST_MOLLER_TRUMBORE, TEST_WATERTIGHT};
        match ($tracer.triangle_test(), $tracer.exit_test()) {
            (T::Watertight, E::Plucker) => $($f)::+::<$any, TEST_WATERTIGHT, false>($($args),*),
            (T::Watertight, E::Slab) => $($f)::+::<$any, TEST_WATERTIGHT, true>($($args),*),
            (T::MollerTrumbore, E::Plucker) => $($f)::+::<$any, TEST_MOLLER_TRUMBORE, false>($($args),*),
            (T::MollerTrumbore, E::Slab) => $($f)::+::<$any, TEST_MOLLER_TRUMBORE, true>($($args),*),
            (T::F64, E::Plucker) => $($f)::+::<$any, TEST_F64, false>($($args),*),
            (T::F64, E::Slab) => $($f)::+::<$any, TEST_F64, true>($($args),*),
        }
    }};
}
pub(crate) use with_tests;

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

/// One ray's walk in progress: what every step needs, computed once, and where the
/// walk is. Batch calls keep several in flight so that their memory loads overlap.
#[derive(Clone, Debug)]
pub(crate) struct RayWalk {
    o: [f32; 3],
    d: [f32; 3],
    inv: [f32; 3],
    /// 1 where the exit corner is on the cell's high side (direction not negative).
    high: [u32; 3],
    /// Exit-face row of the ray's octant.
    exits: &'static [u8; 8],
    /// Whether a direction component is zero (`+0.0` or `-0.0`): the exit face is
    /// then decided by [`exit_along_moving_axes`], never by the table.
    flat: bool,
    tmin: f32,
    /// Where the walk stops: the ray's `tmax`, or sooner where it leaves the mesh box.
    tmax: f32,
    /// The current leaf: record address, level and cell.
    address: u32,
    level: u32,
    cell: [u32; 3],
    /// The ray's shear for the watertight test.
    shear: Shear,
    /// The nearest hit so far (possibly beyond the current leaf) and its distance.
    pub(crate) best: Option<Hit>,
    t_best: f32,
    steps: u32,
}

/// A step's triangle test, for [`Tracer::visit_leaf`]: a trait rather than a closure
/// so that it is inlined (`inline(always)`) into the step, in whatever target
/// features the step is compiled with.
pub(crate) trait LeafTest {
    /// The hit `(t, u, v)` of the triangle (nine floats) in `[tmin, tmax]`.
    fn hit(&self, tri: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)>;

    /// How many triangles [`LeafTest::batch`] takes at once; 0 where it does not.
    #[inline(always)]
    fn batch_size(&self) -> usize {
        0
    }

    /// Tests the stored triangles `refs` (1 to `batch_size`) of `triangles` at once:
    /// the answer a test of one after the other would keep.
    #[inline(always)]
    fn batch<const ANY: bool>(&self, _triangles: &[f32], _refs: &[u32], _tmin: f32, _tmax: f32) -> Batch {
        Batch::OneByOne
    }
}

/// What a batch of triangles tested at once answered ([`LeafTest::batch`]).
pub(crate) enum Batch {
    /// No triangle hit within `[tmin, tmax]`.
    Miss,
    /// The hit that testing the triangles one after another would keep (the nearest;
    /// of equal ones the last, since a test accepts `t <= t_best`; for an any-hit
    /// query the first): index in the batch, `t`, `u`, `v`.
    Hit(usize, f32, f32, f32),
    /// Test these one by one (an edge function rounded to zero, which the scalar test
    /// decides in f64; an index out of range; no batch form).
    OneByOne,
}

/// The scalar step's test: the tracer's.
struct ScalarTest<'t, 'a> {
    tracer: &'t Tracer<'a>,
    shear: Shear,
    tri: TriRay,
}

impl LeafTest for ScalarTest<'_, '_> {
    #[inline(always)]
    fn hit(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.tracer.hit_triangle(&self.shear, &self.tri, t, tmin, tmax)
    }
}

/// The parts of a walk's state that [`Tracer::visit_leaf`] updates.
pub(crate) struct LeafVisit<'w> {
    pub tmin: f32,
    pub t_best: &'w mut f32,
    pub best: &'w mut Option<Hit>,
}

#[allow(dead_code)] // some accessors serve only the SIMD steps
impl RayWalk {
    pub(crate) fn o(&self) -> [f32; 3] {
        self.o
    }
    pub(crate) fn d(&self) -> [f32; 3] {
        self.d
    }
    pub(crate) fn inv(&self) -> [f32; 3] {
        self.inv
    }
    pub(crate) fn high(&self) -> [u32; 3] {
        self.high
    }
    pub(crate) fn exits(&self) -> &'static [u8; 8] {
        self.exits
    }
    pub(crate) fn tmin(&self) -> f32 {
        self.tmin
    }
    pub(crate) fn tmax(&self) -> f32 {
        self.tmax
    }
    pub(crate) fn t_best(&self) -> f32 {
        self.t_best
    }
    pub(crate) fn address(&self) -> u32 {
        self.address
    }
    pub(crate) fn level(&self) -> u32 {
        self.level
    }
    pub(crate) fn cell(&self) -> [u32; 3] {
        self.cell
    }
    pub(crate) fn shear(&self) -> Shear {
        self.shear
    }
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
            v3: frame.v3,
            lanes: true,
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
    pub(crate) fn uses_lanes(&self) -> bool {
        self.lanes
    }

    /// The same tracer locating points with `grid` (built for this scene).
    #[inline]
    pub fn with_locate_grid(mut self, grid: &'a LocateGrid) -> Self {
        self.grid = Some(grid);
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

    /// The nearest hit in `[tmin, tmax]`, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<false>(ray, &mut WalkStats::default())
    }

    /// [`Tracer::intersect`] on the portable scalar step, whatever SIMD the build
    /// has: the reference the SIMD steps are tested against.
    pub fn intersect_scalar(&self, ray: &Ray) -> Option<Hit> {
        let mut w = self.begin(ray)?;
        while !self.step::<false>(&mut w, &mut WalkStats::default()) {}
        self.answer(w.best)
    }

    /// [`Tracer::occluded`] on the portable scalar step.
    pub fn occluded_scalar(&self, ray: &Ray) -> bool {
        let Some(mut w) = self.begin(ray) else { return false };
        while !self.step::<true>(&mut w, &mut WalkStats::default()) {}
        w.best.is_some()
    }

    /// Whether anything is hit in `[tmin, tmax]`; stops at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.walk::<true>(ray, &mut WalkStats::default()).is_some()
    }

    /// Some hit in `[tmin, tmax]` (not necessarily the nearest): the occluder that
    /// [`Tracer::occluded`] found.
    pub fn occluder(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<true>(ray, &mut WalkStats::default())
    }

    /// [`Tracer::intersect`], counting what the walk did.
    pub fn intersect_with_stats(&self, ray: &Ray) -> (Option<Hit>, WalkStats) {
        let mut stats = WalkStats::default();
        (self.walk::<false>(ray, &mut stats), stats)
    }

    /// Any hit for `ANY`, else the nearest: on the SIMD step where the build has one.
    fn walk<const ANY: bool>(&self, ray: &Ray, stats: &mut WalkStats) -> Option<Hit> {
        let w = self.begin(ray)?;
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        return with_tests!(self; ANY; super::simd::sse2::walk; self, &w, stats);
        #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
        {
            let mut w = w;
            while !self.step::<ANY>(&mut w, stats) {}
            self.answer(w.best)
        }
    }

    /// The root cube's low corner.
    pub(crate) fn root_lo(&self) -> [f32; 3] {
        self.frame.root_lo
    }

    /// Cell edges by level (32 of them: a level masked to five bits indexes it).
    #[inline(always)]
    pub(crate) fn cell_sizes(&self) -> &[f32; 32] {
        &self.frame.sizes
    }

    /// The edge of a cell at `level` (masked into the table: a hostile level cannot
    /// index out of bounds).
    #[inline(always)]
    pub(crate) fn cell_size(&self, level: u32) -> f32 {
        self.frame.sizes[level as usize & 31]
    }

    /// Prepares a ray's walk: clips it to the root cube and finds its first leaf, or
    /// returns `None` for a ray that cannot hit (no memory touched).
    #[inline(always)]
    pub(crate) fn begin(&self, ray: &Ray) -> Option<RayWalk> {
        if !ray.is_traceable() {
            return None;
        }
        let o = ray.origin.to_array();
        let d = ray.dir.to_array();
        let (t_enter, t_leave, entry_axis) = clip(o, d, self.frame.root_lo, self.frame.root_hi)?;
        // Beyond the (enlarged) mesh box there is nothing to hit: a ray that misses it
        // costs nothing more, and a walk stops where the ray leaves it (a little later:
        // a relative slack for the rounding of distances far from the origin).
        let (box_enter, box_leave, _) = clip(o, d, self.frame.box_lo, self.frame.box_hi)?;
        let t_start = t_enter.max(ray.tmin);
        let t_stop = ray.tmax.min(box_leave + box_leave.abs() * BOX_T_SLACK);
        if t_start > t_leave.min(ray.tmax) || t_start.max(box_enter) > t_stop {
            return None; // misses the root cube or the mesh box within [tmin, tmax]
        }
        // The entry leaf, and its cell: with the cell, every box along the walk is
        // computed rather than loaded (the paper's own suggestion, section 6).
        let (address, level, cell) = if box_enter > t_start {
            self.locate_cell(point_at(o, d, box_enter))
        } else if t_enter > ray.tmin {
            self.enter_through_cube_map(o, d, t_enter, entry_axis)
        } else {
            self.locate_cell(point_at(o, d, t_start))
        };
        Some(RayWalk {
            o,
            d,
            inv: [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]],
            high: [!d[0].is_sign_negative() as u32, !d[1].is_sign_negative() as u32, !d[2].is_sign_negative() as u32],
            exits: &EXIT_FACE[octant(d)],
            flat: d.contains(&0.0),
            shear: Shear::new(o, d),
            tmin: ray.tmin,
            tmax: t_stop,
            address,
            level,
            cell,
            best: None,
            t_best: ray.tmax,
            steps: 0,
        })
    }

    /// The start of every step, scalar or SIMD: counts it against the bound, reads
    /// the leaf record at `address` and tests the leaf's triangles with `test`, keeping
    /// the nearest hit in `[tmin, t_best]`. Returns the record's box index and `nCount`,
    /// or `None` when the walk is over (the step bound, or any hit for `ANY`).
    #[inline(always)]
    pub(crate) fn visit_leaf<const ANY: bool>(
        &self,
        address: u32,
        steps: &mut u32,
        walk: &mut LeafVisit<'_>,
        stats: &mut WalkStats,
        test: &impl LeafTest,
    ) -> Option<(u32, u32)> {
        let v = &self.view;
        stats.leaves += 1;
        *steps += 1;
        if *steps > self.frame.max_steps {
            stats.stopped_at_bound = true;
            return None;
        }
        let a = address as usize;
        // A valid file's links are record starts; a hostile one on the trusted path
        // ends the walk here.
        let rec = v.octree.get(a..a + LEAF_HEADER_WORDS)?;
        let (count, offset, box_index, ncount) = (rec[0], rec[1], rec[2], rec[3]);
        stats.triangle_tests = stats.triangle_tests.saturating_add(count);
        (!self.test_leaf::<ANY>(count, offset, box_index, walk, test)).then_some((box_index, ncount))
    }

    /// Tests a leaf's `count` triangles (references from `offset` on), keeping the
    /// nearest hit in `[tmin, t_best]`; returns whether an any-hit query is answered.
    #[inline(always)]
    pub(crate) fn test_leaf<const ANY: bool>(
        &self,
        count: u32,
        offset: u32,
        box_index: u32,
        walk: &mut LeafVisit<'_>,
        test: &impl LeafTest,
    ) -> bool {
        let v = &self.view;
        // References past the array (a hostile file on the trusted path): none.
        let refs = v.tri_refs.get(offset as usize..offset as usize + count as usize).unwrap_or_default();
        let size = test.batch_size();
        if size == 0 {
            return self.one_by_one::<ANY>(refs, box_index, walk, test);
        }
        for chunk in refs.chunks(size) {
            match test.batch::<ANY>(v.triangles, chunk, walk.tmin, *walk.t_best) {
                Batch::Miss => {}
                Batch::Hit(i, t, u, vv) => {
                    self.keep(walk, chunk[i], box_index, (t, u, vv));
                    if ANY {
                        return true;
                    }
                }
                Batch::OneByOne => {
                    if self.one_by_one::<ANY>(chunk, box_index, walk, test) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Tests the stored triangles `refs` one after another, keeping the nearest hit;
    /// returns whether an any-hit query is answered.
    #[inline(always)]
    fn one_by_one<const ANY: bool>(
        &self,
        refs: &[u32],
        box_index: u32,
        walk: &mut LeafVisit<'_>,
        test: &impl LeafTest,
    ) -> bool {
        for &tri in refs {
            // A reference past the triangles (a hostile file on the trusted path) is skipped.
            let Some(data) =
                self.view.triangles.get(tri as usize * TRIANGLE_FLOATS..).and_then(|t| t.get(..TRIANGLE_FLOATS))
            else {
                continue;
            };
            if let Some(hit) = test.hit(data, walk.tmin, *walk.t_best) {
                self.keep(walk, tri, box_index, hit);
                if ANY {
                    return true;
                }
            }
        }
        false
    }

    /// Makes stored triangle `tri`'s hit `(t, u, v)` the walk's best (its `triangle`
    /// is set by [`Tracer::answer`]).
    #[inline(always)]
    fn keep(&self, walk: &mut LeafVisit<'_>, tri: u32, box_index: u32, (t, u, v): (f32, f32, f32)) {
        *walk.t_best = t;
        // The input id is looked up when the walk ends (`answer`): a later hit may
        // replace this one, and an any-hit query needs none. Ask for it now.
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        super::simd::sse2::prefetch(self.view.triangle_ids, tri);
        *walk.best = Some(Hit { t, triangle: u32::MAX, u, v, leaf: box_index, prim: tri });
    }

    /// A finished walk's answer, its triangle named by its input id.
    #[inline(always)]
    pub(crate) fn answer(&self, best: Option<Hit>) -> Option<Hit> {
        // A stored triangle without an id (a hostile file on the trusted path): a miss.
        best.and_then(|h| Some(Hit { triangle: *self.view.triangle_ids.get(h.prim as usize)?, ..h }))
    }

    /// Visits the walk's current leaf and moves to the next; returns whether the walk
    /// is over (its answer is then in `w.best`).
    #[inline(always)]
    pub(crate) fn step<const ANY: bool>(&self, w: &mut RayWalk, stats: &mut WalkStats) -> bool {
        let v = &self.view;
        let lo = self.frame.root_lo;
        let a = w.address as usize;
        // 1. The leaf's triangles: keep the nearest in [tmin, t_best].
        let test = ScalarTest { tracer: self, shear: w.shear, tri: TriRay { o: w.o, d: w.d } };
        let mut visit = LeafVisit { tmin: w.tmin, t_best: &mut w.t_best, best: &mut w.best };
        let Some((box_index, ncount)) = self.visit_leaf::<ANY>(w.address, &mut w.steps, &mut visit, stats, &test)
        else {
            return true;
        };
        // 2. The exit corner from the cell (the same bits as the stored box: an
        //    integer times a power of two is exact, and one rounding follows), then
        //    the exit face from the signs of three Plücker products.
        let (cell, level) = (w.cell, w.level);
        let size = self.frame.sizes[level as usize & 31];
        let corner = |k: usize| (lo[k] + (cell[k] + w.high[k]) as f32 * size) - w.o[k];
        // (Closures called three times: `[0, 1, 2].map` is not inlined in this loop.)
        let off = [corner(0), corner(1), corner(2)];
        debug_assert!(
            v.boxes
                .get(box_index as usize * 6..box_index as usize * 6 + 6)
                .is_none_or(|b| (0..3).all(|k| b[k + 3 * w.high[k] as usize] - w.o[k] == off[k])),
            "walked cell {level}/{cell:?} is not leaf {box_index}'s box"
        );
        // (A ray with a zero direction component leaves by the slab rule: see
        // `exit_along_moving_axes` for why the table cannot serve it.)
        let mut face = w.exits[exit_code(off, w.d)] as usize;
        if w.flat || self.exit == ExitTest::Slab {
            face = exit_along_moving_axes(off, w.d, w.inv);
        }
        let axis = face >> 1;
        // Every per-axis quantity below is computed on all three lanes with fixed
        // indices; only the exit axis's offset, direction and inverse are picked.
        // (Indexing local arrays by `axis` sends them through the stack.)
        let pick = |x: [f32; 3]| {
            if axis == 0 {
                x[0]
            } else if axis == 1 {
                x[1]
            } else {
                x[2]
            }
        };
        let (off_a, d_a) = (pick(off), pick(w.d));
        // 3. A candidate inside this leaf is the nearest: nothing after the exit can
        //    be nearer. Past tmax, nothing more can count.
        let t_exit = off_a * pick(w.inv);
        if w.best.is_some_and(|h| h.t <= t_exit) || t_exit >= w.tmax {
            return true;
        }
        // 4. The neighbour across the face: none at the root's boundary, else one, or
        //    one of four picked by the sides of the face's median lines (the Plücker
        //    products with the lines through the face's centre).
        let n = (ncount >> (4 * face)) & 0xF;
        if n == 0 {
            return true;
        }
        let half = 0.5 * size;
        let negative_a = face & 1 == 0;
        let side = |k: usize| {
            let mid = lo[k] + (2 * cell[k] + 1) as f32 * half;
            let p = off_a * w.d[k] - (mid - w.o[k]) * d_a;
            ((p > 0.0) ^ negative_a) as u32
        };
        let sides = [side(0), side(1), side(2)];
        // The quadrant: the side bits of the two other axes, in increasing order.
        let side_bits = sides[0] | sides[1] << 1 | sides[2] << 2;
        let quadrant = (side_bits & ((1 << axis) - 1)) | ((side_bits >> (axis + 1)) << axis);
        let link = a + LEAF_HEADER_WORDS + (links_before(ncount, face) + (n >> 2) * quadrant) as usize;
        // A link past the array (a hostile file on the trusted path) ends the walk.
        let Some(&next) = v.octree.get(link) else { return true };
        w.address = next;
        // 5. The neighbour's cell: across the face at this level, then one level finer
        //    (four neighbours: the quadrant's child on our side), the same, or one
        //    coarser (the flag in nCount), without a branch:
        //    cell' = ((across << 1) | child bits) >> (1 - d).
        let coarser = (ncount >> (COARSER_SHIFT as usize + face)) & 1;
        let finer = n >> 2;
        // 0 to 2 in a valid file; `& 31` keeps a hostile file's counts (on the trusted
        // path) from overflowing the shift, as release builds would anyway.
        let shift = (1 + coarser).wrapping_sub(finer) & 31;
        let up = (face as u32 & 1) * 2; // 0 to go down the axis, 2 to go up
        let next = |k: usize| {
            let on_axis = k == axis;
            let across = if on_axis { cell[k].wrapping_add(up).wrapping_sub(1) } else { cell[k] };
            let bit = if on_axis { negative_a as u32 } else { sides[k] };
            ((across << 1) | bit) >> shift
        };
        w.cell = [next(0), next(1), next(2)];
        w.level = level.wrapping_add(finer).wrapping_sub(coarser);
        false
    }
}

/// Whether this processor runs the walks compiled for x86-64-v3.
fn wider_simd_available() -> bool {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    return super::x86_64_v3();
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    false
}

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

/// The ray's parameter interval inside the box `lo..hi` and the axis it enters by (the
/// first of equal ones), or `None` if it misses. Zero components are handled
/// explicitly: `0 * inf` never happens. On SSE2 the six divisions are two (8 % faster
/// primary rays), with the same answer.
#[inline(always)]
pub(crate) fn clip(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> Option<(f32, f32, usize)> {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    if !d.contains(&0.0) {
        return super::simd::sse2::clip(o, d, lo, hi);
    }
    clip_scalar(o, d, lo, hi)
}

/// [`clip`] on scalars: the portable form, and the one for rays with a zero direction
/// component.
#[inline(always)]
pub(crate) fn clip_scalar(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> Option<(f32, f32, usize)> {
    // One slab an axis, written out three times (a loop over the axes stays a loop
    // here, with a branch an axis: 150 instructions a ray for the two clips of
    // `begin`). An axis the ray does not move along is the whole line, or nothing.
    let slab = |a: usize| {
        if d[a] == 0.0 {
            return (o[a] >= lo[a] && o[a] <= hi[a]).then_some((f32::NEG_INFINITY, f32::INFINITY));
        }
        let (ta, tb) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
        Some(if ta < tb { (ta, tb) } else { (tb, ta) })
    };
    let ((n0, f0), (n1, f1), (n2, f2)) = (slab(0)?, slab(1)?, slab(2)?);
    // The entry axis is the first holding the largest entry distance.
    let (mut t0, mut axis) = (n0, 0);
    if n1 > t0 {
        (t0, axis) = (n1, 1);
    }
    if n2 > t0 {
        (t0, axis) = (n2, 2);
    }
    let t1 = f0.min(f1).min(f2);
    (t0 <= t1).then_some((t0, t1, axis))
}

impl Tracer<'_> {
    /// Finest-grid coordinates of a point, clamped into the root.
    #[inline(always)]
    fn grid_coords(&self, p: [f32; 3]) -> [u32; 3] {
        let last = ((1u64 << self.frame.max_depth) - 1) as f64;
        // Clamped to [0, last] first, so truncation is the floor; NaN clamps to 0.
        // Rounding can only move a point to a neighbouring cell, which the bake
        // margin covers.
        let q =
            |a: usize| ((p[a] as f64 - self.frame.root_lo[a] as f64) * self.frame.grid_scale).max(0.0).min(last) as u32;
        [q(0), q(1), q(2)]
    }

    /// The address of the leaf holding point `p` (clamped into the root).
    pub fn locate(&self, p: [f32; 3]) -> u32 {
        self.locate_cell(p).0
    }

    /// The leaf holding point `p`: its address, level and cell. With a locate grid,
    /// one load replaces the top levels of the descent.
    #[inline(always)]
    fn locate_cell(&self, p: [f32; 3]) -> (u32, u32, [u32; 3]) {
        let q = self.grid_coords(p);
        match self.grid {
            Some(grid) => {
                let (word, level) = grid.entry(q, self.frame.max_depth);
                self.descend(word, level, q)
            }
            None => self.descend(self.view.root, 0, q),
        }
    }

    /// Descends from `word` (a node at `level`) to the leaf holding finest-grid cell
    /// `q`: its address, level and cell.
    #[inline(always)]
    fn descend(&self, word: u32, level: u32, q: [u32; 3]) -> (u32, u32, [u32; 3]) {
        let (address, level) = descend_to(&self.view, word, level, q, self.frame.max_depth, self.frame.max_depth);
        let shift = self.frame.max_depth.saturating_sub(level).min(31);
        (address, level, q.map(|c| c >> shift))
    }

    /// The leaf a ray from outside enters first (address, level, cell): the cube-map
    /// texel under its entry point holds that leaf, or the node to descend from.
    #[inline(always)]
    fn enter_through_cube_map(&self, o: [f32; 3], d: [f32; 3], t: f32, axis: usize) -> (u32, u32, [u32; 3]) {
        let mut q = self.grid_coords(point_at(o, d, t));
        let high = d[axis] < 0.0;
        q[axis] = if high { (1u32 << self.frame.max_depth) - 1 } else { 0 };
        let face = 2 * axis + high as usize;
        let Some(level) = self.frame.cube_level else {
            return self.descend(self.view.root, 0, q);
        };
        let res = 1usize << level;
        let (u, v) = other_axes(axis);
        let shift = self.frame.max_depth - level;
        let texel = texel_index(face, res, (q[u] >> shift) as usize, (q[v] >> shift) as usize);
        let word = self.view.cube_map[texel];
        match NodeRef::decode(word) {
            NodeRef::Internal(_) => self.descend(word, level, q),
            // The texel's leaf may be coarser than the texel: its level is read off its
            // box, whose edge is the root's divided by a power of two.
            NodeRef::Leaf(address) => {
                let view = &self.view;
                let edge =
                    view.octree.get(address as usize + 2).and_then(|&b| view.boxes.get(b as usize * 6..)?.get(..6));
                // A leaf or box past its array (a hostile file): from the root instead.
                let Some(edge) = edge.map(|b| b[3] as f64 - b[0] as f64) else {
                    return self.descend(view.root, 0, q);
                };
                // Edges are the root's over powers of two: compare binary exponents
                // (rounding of the planes moves an edge by far less than a factor 2).
                let ratio = self.view.bounds.root_size as f64 / edge * std::f64::consts::SQRT_2;
                let leaf_level = (((ratio.to_bits() >> 52) & 0x7FF) as i64 - 1023).clamp(0, level as i64) as u32;
                let shift = self.frame.max_depth - leaf_level;
                (address, leaf_level, [q[0] >> shift, q[1] >> shift, q[2] >> shift])
            }
        }
    }
}

/// Descends the point-location tree from `word` (a node at `level`) towards
/// finest-grid cell `q` until a leaf or level `stop`: (the word there, its level). A
/// valid tree has no internal node at `max_depth`; a hostile one (on the trusted path)
/// stops there too, so the descent is bounded whatever the file.
#[inline(always)]
fn descend_to(view: &SceneView<'_>, mut word: u32, mut level: u32, q: [u32; 3], stop: u32, depth: u32) -> (u32, u32) {
    // `q` is on the grid of `depth`, the depth the tracer uses (the file's, at most the
    // format's limit); `stop <= depth`, so the shift cannot underflow.
    debug_assert!(stop <= depth);
    while let NodeRef::Internal(i) = NodeRef::decode(word) {
        if level >= stop {
            break;
        }
        let shift = (depth - level - 1).min(31);
        let child = (q[0] >> shift & 1) | (q[1] >> shift & 1) << 1 | (q[2] >> shift & 1) << 2;
        word = view.nodes.get(8 * i as usize + child as usize).copied().unwrap_or(0);
        level += 1;
    }
    (word, level)
}

/// The point-location tree's top levels as a grid: for each cell of level `level`, the
/// leaf that holds it (and that leaf's level) or the internal node at that level. A
/// point is located with one load and a short descent instead of up to `max_depth`
/// dependent loads. Built once per scene (`Scene` keeps it).
#[derive(Debug)]
pub struct LocateGrid {
    level: u32,
    words: Vec<u32>,
    levels: Vec<u8>,
}

impl LocateGrid {
    /// Grid cells a side at most: 2^6 (262,144 cells, 1.25 MB).
    const MAX_LEVEL: u32 = 6;

    /// The grid of a validated scene.
    pub fn build(view: &SceneView<'_>) -> LocateGrid {
        let depth = view.params.max_depth.min(MAX_LEVEL);
        let level = depth.min(Self::MAX_LEVEL);
        let res = 1u32 << level;
        let shift = depth - level;
        let cells = (res as usize).pow(3);
        let (mut words, mut levels) = (Vec::with_capacity(cells), Vec::with_capacity(cells));
        for z in 0..res {
            for y in 0..res {
                for x in 0..res {
                    let q = [x << shift, y << shift, z << shift];
                    let (word, l) = descend_to(view, view.root, 0, q, level, depth);
                    words.push(word);
                    levels.push(l as u8);
                }
            }
        }
        LocateGrid { level, words, levels }
    }

    /// The word and level to descend from for finest-grid cell `q`.
    #[inline(always)]
    fn entry(&self, q: [u32; 3], max_depth: u32) -> (u32, u32) {
        let shift = max_depth.saturating_sub(self.level).min(31);
        let res = 1usize << self.level;
        let mask = res - 1;
        let i = (((q[2] >> shift) as usize & mask) * res + ((q[1] >> shift) as usize & mask)) * res
            + ((q[0] >> shift) as usize & mask);
        match (self.words.get(i), self.levels.get(i)) {
            (Some(&w), Some(&l)) => (w, l as u32),
            _ => (0, 0),
        }
    }
}

/// The exit face of a ray with a zero direction component (`+0.0` or `-0.0`): the
/// nearest exit among the axes the ray moves along, ties to the lowest axis. Every
/// walk (scalar, SSE, the eight lanes, both WGSL kernels) decides such rays here and
/// never by the Plücker table.
///
/// # The rule, and why the table cannot serve these rays
/// A ray with `d[k] = ±0` never leaves a cell across a `k` face: its `k` coordinate is
/// `o[k]` all along, so `t_k` is infinite. It belongs to the cell the walk is in even
/// when `o[k]` lies exactly on one of that cell's `k` planes (point location puts a
/// point on a plane in the cell above it; a step puts it on either side, by the
/// median-line signs), since boxes are closed and a triangle through the plane is
/// listed on both sides. Only the moving axes compete, and the nearest exit among them
/// is the face.
///
/// The table cannot say so. Its products with axis `k` are `P = a_i d_k - a_k d_i`,
/// and when the ray lies in the plane of the exit corner (`a_k = 0`: `o[k]` on the low
/// plane with `-0.0`, or on the high plane with `+0.0`), both products with `k` are
/// zero. Both bits then read "not positive", which orders `k` before one of the other
/// axes and after the other: with a third comparison the code can be cyclic, and a
/// cyclic code maps to the octant's x face, which may be the later exit. The walk then
/// skips the cells it should have crossed first, and rays in cell planes leaked
/// through closed meshes (3-49 % of them in y and z planes; x planes were spared
/// because a cyclic code's x face is checked against a zero `d[0]`). Testing the
/// table's face for a zero component is not enough for that reason: the decision for
/// these rays is taken here whatever the table says.
///
/// Rare (a direction component exactly zero): off the hot path.
#[cold]
#[inline(never)]
pub(crate) fn exit_along_moving_axes(off: [f32; 3], d: [f32; 3], inv: [f32; 3]) -> usize {
    let mut best = (f32::INFINITY, 0);
    for a in 0..3 {
        if d[a] != 0.0 {
            let t = off[a] * inv[a];
            if t < best.0 || best.0 == f32::INFINITY {
                best = (t, a);
            }
        }
    }
    2 * best.1 + !d[best.1].is_sign_negative() as usize
}

#[inline(always)]
pub(crate) fn point_at(o: [f32; 3], d: [f32; 3], t: f32) -> [f32; 3] {
    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
}
