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

use octrace_format::layout::{links_before, COARSER_SHIFT, LEAF_HEADER_WORDS, TRIANGLE_FLOATS};
use octrace_format::StoredIndex;

use super::fans;
use super::tables::{exact_exit, exact_side, exit_code, exit_rule, octant, ExitRule, EXIT_FACE};
use super::tracer::{ExitTest, Tally, Tracer, TriangleTest, BOX_T_SLACK};
use super::triangle::TriRay;
use super::watertight::Shear;
use crate::ray::{Hit, Ray};

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
    /// How the exit faces are decided (`tables::exit_rule`): the table; for a zero
    /// component (`+0.0` or `-0.0`) [`exit_along_moving_axes`]; for directions the
    /// `f32` products cannot serve, exactly in `f64` (then only the scalar step walks
    /// the ray).
    rule: ExitRule,
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
    /// For a ray re-originated near the scene ([`Tracer::begin_far`]): the distance
    /// its origin was moved (`f64`), and the ray's own `tmin` and `tmax`.
    shifted: Option<(f64, f32, f32)>,
    /// For such a ray under the exact test: the ray as given, which decides its hits.
    far: Option<Far>,
}

/// A re-originated ray under [`TriangleTest::Exact`]: the walk moves through the cells
/// from the moved origin (whose `f32` coordinates are the scene's size), but the
/// moved ray is not the ray as given (its origin is rounded), so that exact decisions
/// about it would be exact about another ray. Each triangle is decided on the ray as
/// given ([`Shear::intersect_exact`] from its own origin, in its own `[tmin, tmax]`);
/// the walk places the hit at the exact distance less the shift, correctly rounded
/// (`exact::shifted_distance`: as fine as the walk's distances, in the exact order),
/// orders equal ones exactly on the ray as given, and answers its exact distance,
/// correctly rounded.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Far {
    /// The ray as given.
    pub shear: Shear,
    /// The distance the origin was moved, as two `f32` (their sum).
    pub shift: (f32, f32),
    /// The ray's own interval.
    pub tmin: f32,
    pub tmax: f32,
}

impl Far {
    /// The hit of triangle `tri` (edges owned when `owned`) on the ray as given, as
    /// `(t, u, v)` with `t` the walk's distance (from the moved origin) when it lies in
    /// the walk's `[tmin, tmax]`; and the ray's own distance.
    #[inline(always)]
    pub(crate) fn hit(&self, tri: &[f32], owned: bool, tmin: f32, tmax: f32) -> Option<((f32, f32, f32), f32)> {
        let (t, u, v) = match owned {
            true => self.shear.intersect_owned_exact(tri, self.tmin, self.tmax)?,
            false => self.shear.intersect_exact(tri, self.tmin, self.tmax)?,
        };
        let moved = crate::cpu::watertight::shifted_distance_rounded(
            self.shear.origin(),
            self.shear.direction(),
            tri,
            self.shift,
        )?;
        (moved >= tmin && moved <= tmax).then_some(((moved, u, v), t))
    }

    /// The ray's own distance to the plane of `tri` (a triangle it hits), correctly
    /// rounded.
    pub(crate) fn distance(&self, tri: &[f32]) -> Option<f32> {
        crate::cpu::watertight::plane_distance_rounded(self.shear.origin(), self.shear.direction(), tri)
    }
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

    /// How the exact distances to triangles `new` and `kept` compare, where the test
    /// decides ties of rounded distances exactly (`TriangleTest::Exact`); `None`
    /// elsewhere (the later of equal rounded distances is kept).
    #[inline(always)]
    fn nearer(&self, _new: &[f32], _kept: &[f32]) -> Option<std::cmp::Ordering> {
        None
    }

    /// The shear of [`Shear::intersect`], where every triangle is tested with it (so a
    /// fan's hierarchy may choose which: `fans.rs`); `None` for the other tests.
    #[inline(always)]
    fn fan_shear(&self) -> Option<&Shear> {
        None
    }
}

/// What a batch of triangles tested at once answered ([`LeafTest::batch`]). Only the
/// SIMD test (`simd::avx2::hit8`) answers `Miss` or `Hit`; without it every batch is
/// `OneByOne`.
#[cfg_attr(not(all(target_arch = "x86_64", target_feature = "sse2")), allow(dead_code))]
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

/// The scalar step's test: the tracer's (the watertight test in `f64` for a ray under
/// the exact exit rule: `Shear::intersect_f64`; the ray as given for a re-originated
/// one under the exact test: [`Far`]).
struct ScalarTest<'t, 'a> {
    tracer: &'t Tracer<'a>,
    shear: Shear,
    tri: TriRay,
    exact: bool,
    far: Option<Far>,
}

impl LeafTest for ScalarTest<'_, '_> {
    #[inline(always)]
    fn hit(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        if let Some(far) = &self.far {
            return far.hit(t, false, tmin, tmax).map(|(hit, _)| hit);
        }
        if self.exact && self.tracer.triangle_test() == TriangleTest::Watertight {
            return self.shear.intersect_f64(t, tmin, tmax);
        }
        self.tracer.hit_triangle(&self.shear, &self.tri, t, tmin, tmax)
    }

    #[inline(always)]
    fn nearer(&self, new: &[f32], kept: &[f32]) -> Option<std::cmp::Ordering> {
        let shear = self.far.as_ref().map_or(&self.shear, |f| &f.shear);
        (self.tracer.triangle_test() == TriangleTest::Exact).then(|| shear.compare_distances(new, kept))
    }

    #[inline(always)]
    fn fan_shear(&self) -> Option<&Shear> {
        (!self.exact && self.tracer.triangle_test() == TriangleTest::Watertight).then_some(&self.shear)
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
    pub(crate) fn far(&self) -> Option<Far> {
        self.far
    }
    pub(crate) fn rule(&self) -> ExitRule {
        self.rule
    }
    /// Whether only the scalar step may walk this ray: under the exact exit rule, or
    /// re-originated (its answer's distance shifted back by `walk_scalar`).
    pub(crate) fn scalar_only(&self) -> bool {
        self.rule == ExitRule::Exact || self.shifted.is_some()
    }
    /// A finished walk's hit, its distance measured from the ray's own origin (for
    /// [`Far`], the ray's own exact distance to the hit's triangle in `triangles`).
    pub(crate) fn unshift(&self, hit: Option<Hit>, triangles: &[f32]) -> Option<Hit> {
        let h = hit?;
        if let Some(far) = &self.far {
            let tri = triangles.get(h.prim.0 as usize * TRIANGLE_FLOATS..)?.get(..TRIANGLE_FLOATS)?;
            return Some(Hit { t: far.distance(tri)?, ..h });
        }
        Some(Hit { t: self.unshift_distance(h.t), ..h })
    }
    /// A distance of this walk measured from the ray's own origin: shifted back by the
    /// distance a far origin was moved (rounded once, clamped into the ray's interval).
    pub(crate) fn unshift_distance(&self, t: f32) -> f32 {
        match self.shifted {
            Some((shift, tmin, tmax)) => ((shift + t as f64) as f32).clamp(tmin, tmax),
            None => t,
        }
    }
}

/// The walk's `tmax` for an origin moved `shift` along the ray: the largest distance
/// `t` from the moved origin whose distance from the ray's own,
/// `(shift + t) as f32` ([`RayWalk::unshift_distance`]), is at most `tmax`. So the
/// walk accepts exactly the hits the ray's closed interval does: `tmax - shift`
/// rounded to nearest can fall below a hit whose distance shifts back to `tmax`
/// itself, several of the moved distance's ulps apart (a segment ending exactly at
/// its nearest hit then missed it). A binary search over the `f32` in order (the
/// shifted-back distance grows with `t`): 32 steps, on the far origins' cold path; the
/// GPU kernel runs the same search (`moved_tmax` in trace.wgsl).
pub(crate) fn moved_tmax(tmax: f32, shift: f64) -> f32 {
    if tmax == f32::INFINITY {
        return tmax;
    }
    let back = |t: f32| (shift + t as f64) as f32;
    // The f32 in order as u32 (-inf lowest, +inf highest), and back.
    let key = |x: f32| {
        let b = x.to_bits();
        if b >> 31 == 1 {
            !b
        } else {
            b | 0x8000_0000
        }
    };
    let value = |k: u32| f32::from_bits(if k >> 31 == 1 { k & 0x7FFF_FFFF } else { !k });
    // back(-inf) <= tmax and back(+inf) > tmax (tmax is finite): the answer is between.
    let (mut lo, mut hi) = (key(f32::NEG_INFINITY), key(f32::INFINITY));
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if back(value(mid)) <= tmax {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    value(lo)
}

impl Tracer<'_> {
    /// Prepares a ray's walk: clips it to the root cube and finds its first leaf, or
    /// returns `None` for a ray that cannot hit (no memory touched).
    #[inline(always)]
    pub(crate) fn begin(&self, ray: &Ray) -> Option<RayWalk> {
        if !ray.is_traceable() {
            return None;
        }
        let o = ray.origin.to_array();
        if (0..3).any(|k| !(self.frame.near_lo[k] <= o[k] && o[k] <= self.frame.near_hi[k])) {
            return self.begin_far(ray);
        }
        self.begin_near(ray)
    }

    /// [`Tracer::begin`] for an origin far outside the root cube ([`TreeFrame`]'s near
    /// box): re-originated where the ray enters the cube, in `f64` (rounded once to
    /// `f32`), so that the walk and the triangle tests work with coordinates of the
    /// scene's size rather than the origin's: from 1e7 away, `f32` rounds a unit
    /// scene's vertices relative to the origin by a whole unit, and 8 % of the rays at
    /// a unit sphere missed it (98 % from 1e8). The walk's distances are then from the
    /// new origin; [`Tracer::walk_scalar`], which alone walks such rays, adds the shift
    /// back (one rounding, the distance clamped into `[tmin, tmax]`).
    #[cold]
    #[inline(never)]
    fn begin_far(&self, ray: &Ray) -> Option<RayWalk> {
        let (o, d) = (ray.origin.to_array(), ray.dir.to_array());
        // The entry into the root cube in f64: an f32 distance of 1e9 is off by 64,
        // which would move the origin past a unit scene.
        let (mut t_enter, mut t_leave) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (lo, hi) = (self.frame.root_lo[k] as f64, self.frame.root_hi[k] as f64);
            let (ok, dk) = (o[k] as f64, d[k] as f64);
            if dk == 0.0 {
                if ok < lo || ok > hi {
                    return None;
                }
                continue;
            }
            let (ta, tb) = ((lo - ok) / dk, (hi - ok) / dk);
            t_enter = t_enter.max(ta.min(tb));
            t_leave = t_leave.min(ta.max(tb));
        }
        let entry = t_enter.max(ray.tmin as f64);
        // Not against tmax: see `begin_near`.
        if entry > t_leave || entry.is_nan() || entry >= f32::MAX as f64 {
            return None;
        }
        // The shift as two f32 (so that the kernels, which keep it so, add the same
        // bits): their sum is exact in f64, within 2^-48 of the entry.
        let hi = entry as f32;
        let shift = hi as f64 + (entry - hi as f64) as f32 as f64;
        let moved = [0, 1, 2].map(|k| (o[k] as f64 + shift * d[k] as f64) as f32);
        let (mut tmin, mut tmax) = ((ray.tmin as f64 - shift) as f32, moved_tmax(ray.tmax, shift));
        let exact = self.triangle_test() == TriangleTest::Exact;
        if exact {
            // The ray's own interval decides (`Far`); the walk's, a little wider, must
            // hold the walk's distance of every hit in it (a rounding either side).
            let ulp = |x: f32| (x.abs() * f32::EPSILON) as f64;
            tmin = (ray.tmin as f64 - 2.0 * ulp(ray.tmin) - shift) as f32;
            tmax = moved_tmax(ray.tmax + (2.0 * ulp(ray.tmax)) as f32, shift);
        }
        let near = Ray::segment(moved.into(), ray.dir, tmin, tmax);
        let mut w = self.begin_near(&near)?;
        w.shifted = Some((shift, ray.tmin, ray.tmax));
        if exact {
            let shear = Shear::new(o, d);
            w.far = Some(Far { shear, shift: (hi, (shift - hi as f64) as f32), tmin: ray.tmin, tmax: ray.tmax });
        }
        Some(w)
    }

    /// [`Tracer::begin`] for an origin near the scene (or moved there by
    /// [`Tracer::begin_far`]).
    #[inline(always)]
    fn begin_near(&self, ray: &Ray) -> Option<RayWalk> {
        let o = ray.origin.to_array();
        let d = ray.dir.to_array();
        // Beyond the (enlarged) mesh box there is nothing to hit: a ray that misses it
        // costs nothing more, and a walk stops where the ray leaves it (a little later:
        // a relative slack for the rounding of distances far from the origin).
        let (box_enter, box_leave, _) = clip(o, d, self.frame.box_lo, self.frame.box_hi)?;
        // A mesh whose box reaches the root cube's faces (the root is the box made a
        // cube) can be touched by a ray that grazes the root's edge, which the clip's
        // rounding may call a miss: such a ray starts in the leaf where it enters the
        // enlarged box (point location clamps into the root).
        let (t_enter, t_leave, entry_axis, grazes) = match clip(o, d, self.frame.root_lo, self.frame.root_hi) {
            Some((enter, leave, axis)) => (enter, leave, axis, false),
            None => (box_enter, box_leave, 0, true),
        };
        let t_start = t_enter.max(ray.tmin);
        let box_stop = box_leave + box_leave.abs() * BOX_T_SLACK;
        let t_stop = ray.tmax.min(box_stop);
        // A ray that ends before it enters is walked all the same (its first leaf
        // only: the walk stops past tmax): a hit on the root's or the box's face can
        // lie a rounding before the clip's entry, and a segment that ends exactly
        // there must still hit it, as the same ray without an end does.
        if t_start > t_leave || t_start.max(box_enter) > box_stop {
            return None; // misses the root cube or the mesh box
        }
        // A ray so slow that it reaches the cube past f32's range (a tiny direction
        // from far away) has no hit at a representable distance.
        if t_start.max(box_enter) == f32::INFINITY {
            return None;
        }
        // The entry leaf, and its cell: with the cell, every box along the walk is
        // computed rather than loaded (the paper's own suggestion, section 6).
        let (address, level, cell) = if grazes {
            self.locate_cell(point_at(o, d, t_start))
        } else if box_enter > t_start {
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
            rule: exit_rule(o, d, self.frame.rule_scale),
            shear: Shear::new(o, d),
            tmin: ray.tmin,
            tmax: t_stop,
            address,
            level,
            cell,
            best: None,
            t_best: ray.tmax,
            steps: 0,
            shifted: None,
            far: None,
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
        stats: &mut impl Tally,
        test: &impl LeafTest,
    ) -> Option<(u32, u32)> {
        let v = &self.view;
        stats.leaf();
        *steps += 1;
        if *steps > self.frame.max_steps {
            stats.bound();
            return None;
        }
        let a = address as usize;
        // A valid file's links are record starts; a hostile one on the trusted path
        // ends the walk here.
        let rec = v.octree.get(a..a + LEAF_HEADER_WORDS)?;
        let (count, offset, box_index, ncount) = (rec[0], rec[1], rec[2], rec[3]);
        let (answered, tested) = self.test_leaf_counted::<ANY>(count, offset, box_index, walk, test);
        stats.tests(tested);
        (!answered).then_some((box_index, ncount))
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
        self.test_leaf_counted::<ANY>(count, offset, box_index, walk, test).0
    }

    /// [`Tracer::test_leaf`], and how many triangles it tested: in a fan's leaf, those
    /// its hierarchy picked (`fans.rs`), else all `count`.
    #[inline(always)]
    fn test_leaf_counted<const ANY: bool>(
        &self,
        count: u32,
        offset: u32,
        box_index: u32,
        walk: &mut LeafVisit<'_>,
        test: &impl LeafTest,
    ) -> (bool, u32) {
        // References past the array (a hostile file on the trusted path): none.
        let refs = self.view.tri_refs.get(offset as usize..offset as usize + count as usize).unwrap_or_default();
        // A crowded leaf: through its fan's hierarchy, when it has one and the test
        // allows (`fans.rs`), the same answer as testing them all. (One call of
        // `test_refs` either way: a second copy inlined into the lanes' step cost
        // incoherent batches 10 %.)
        let mut room = fans::candidates_room();
        let (refs, tested) = match self.fan_refs((box_index, offset, refs), || test.fan_shear(), false, &mut room) {
            Some(picked) => (picked, picked.len() as u32),
            None => (refs, count),
        };
        (self.test_refs::<ANY>(refs, box_index, walk, test), tested)
    }

    /// Tests the stored triangles `refs` in their order (eight at a time where the
    /// test can), keeping the nearest hit; returns whether an any-hit query is answered.
    #[inline(always)]
    fn test_refs<const ANY: bool>(
        &self,
        refs: &[u32],
        box_index: u32,
        walk: &mut LeafVisit<'_>,
        test: &impl LeafTest,
    ) -> bool {
        let v = &self.view;
        let size = test.batch_size();
        if size == 0 {
            return self.one_by_one::<ANY>(refs, box_index, walk, test);
        }
        for chunk in refs.chunks(size) {
            match test.batch::<ANY>(v.triangles, chunk, walk.tmin, *walk.t_best) {
                Batch::Miss => {}
                Batch::Hit(i, t, u, vv) => {
                    if t == *walk.t_best {
                        let data = &v.triangles[chunk[i] as usize * TRIANGLE_FLOATS..][..TRIANGLE_FLOATS];
                        if !self.replaces(test, chunk[i], data, walk.best.as_ref()) {
                            continue;
                        }
                    }
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
                if hit.0 == *walk.t_best && !self.replaces(test, tri, data, walk.best.as_ref()) {
                    continue;
                }
                self.keep(walk, tri, box_index, hit);
                if ANY {
                    return true;
                }
            }
        }
        false
    }

    /// Whether stored triangle `tri` (`data`), hit at the rounded distance of the
    /// walk's best, replaces it: the later one does, unless the test decides ties
    /// exactly ([`LeafTest::nearer`]): then the exactly nearer, and of exactly equal
    /// distances the lower input index.
    #[inline(always)]
    fn replaces(&self, test: &impl LeafTest, tri: u32, data: &[f32], kept: Option<&Hit>) -> bool {
        let Some(kept) = kept else { return true };
        if kept.prim.0 == tri {
            return false; // the same triangle, met again in a later leaf
        }
        let v = &self.view;
        let Some(kept_data) =
            v.triangles.get(kept.prim.0 as usize * TRIANGLE_FLOATS..).and_then(|t| t.get(..TRIANGLE_FLOATS))
        else {
            return true;
        };
        match test.nearer(data, kept_data) {
            None | Some(std::cmp::Ordering::Less) => true,
            Some(std::cmp::Ordering::Greater) => false,
            Some(std::cmp::Ordering::Equal) => v.input_index(StoredIndex(tri)) < v.input_index(kept.prim),
        }
    }

    /// Makes stored triangle `tri`'s hit `(t, u, v)` the walk's best (its `triangle`
    /// is set by [`Tracer::answer`]). The tests accept `t <= t_best`, so of hits at the
    /// same distance the last tested is kept: a leaf lists its triangles in descending
    /// input order (the format requires it), and the leaf that holds a hit's point
    /// lists every triangle through it, so the walk answers the lowest input id among
    /// them, on every path and on the GPU, as the oracle's ties go.
    #[inline(always)]
    fn keep(&self, walk: &mut LeafVisit<'_>, tri: u32, box_index: u32, (t, u, v): (f32, f32, f32)) {
        *walk.t_best = t;
        // The input id is looked up when the walk ends (`answer`): a later hit may
        // replace this one, and an any-hit query needs none. Ask for it now.
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        super::hw::prefetch(self.view.triangle_ids, tri);
        *walk.best = Some(Hit { t, triangle: u32::MAX, u, v, leaf: box_index, prim: StoredIndex(tri) });
    }

    /// A finished walk's answer, its triangle named by its input id.
    #[inline(always)]
    pub(crate) fn answer(&self, best: Option<Hit>) -> Option<Hit> {
        // A stored triangle without an id (a hostile file on the trusted path): a miss.
        best.and_then(|h| Some(Hit { triangle: self.view.input_index(h.prim)?, ..h }))
    }

    /// Visits the walk's current leaf and moves to the next; returns whether the walk
    /// is over (its answer is then in `w.best`).
    #[inline(always)]
    pub(crate) fn step<const ANY: bool>(&self, w: &mut RayWalk, stats: &mut impl Tally) -> bool {
        // 1. The leaf's triangles: keep the nearest in [tmin, t_best].
        let exact = w.rule == ExitRule::Exact;
        let test = ScalarTest { tracer: self, shear: w.shear, tri: TriRay { o: w.o, d: w.d }, exact, far: w.far };
        let mut visit = LeafVisit { tmin: w.tmin, t_best: &mut w.t_best, best: &mut w.best };
        let Some((_, ncount)) = self.visit_leaf::<ANY>(w.address, &mut w.steps, &mut visit, stats, &test) else {
            return true;
        };
        // 2. Where the ray leaves the leaf.
        let exit = self.exit_of(w);
        // 3. A candidate inside this leaf is the nearest: nothing after the exit can
        //    be nearer. Past tmax, nothing more can count.
        if w.best.is_some_and(|h| h.t <= exit.t) || exit.t >= w.tmax {
            return true;
        }
        // 4-5. The neighbour.
        !self.follow(w, &exit, ncount)
    }

    /// Where the walk leaves its current leaf: the exit corner from the cell (the same
    /// bits as the stored box: an integer times a power of two is exact, and one
    /// rounding follows), then the exit face from the signs of three Plücker products
    /// (or the slab rule, or exact decisions: `tables::exit_rule`), and the distance.
    #[inline(always)]
    pub(crate) fn exit_of(&self, w: &RayWalk) -> Exit {
        let lo = self.frame.root_lo;
        let (cell, level) = (w.cell, w.level);
        let size = self.frame.sizes[level as usize & 31];
        let corner = |k: usize| (lo[k] + (cell[k] + w.high[k]) as f32 * size) - w.o[k];
        // (Closures called three times: `[0, 1, 2].map` is not inlined in this loop.)
        // (In a valid file this is the leaf's stored box; a hostile one on the trusted
        // path may disagree, and the walk goes on with the cell it computed.)
        let off = [corner(0), corner(1), corner(2)];
        // (A ray with a zero direction component leaves by the slab rule, and one the
        // f32 products cannot serve by exact decisions: `tables::exit_rule`.)
        let mut face = w.exits[exit_code(off, w.d)] as usize;
        let mut t_exact = None;
        if w.rule != ExitRule::Table || self.exit == ExitTest::Slab {
            (face, t_exact) = self.careful_exit(w, off);
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
        let t = t_exact.unwrap_or_else(|| off_a * pick(w.inv));
        Exit { face, t, off_a, d_a }
    }

    /// Moves the walk across `exit`'s face of its leaf (record word `ncount`) to the
    /// neighbour there; false where there is none (the root's boundary, or a link past
    /// the array in a hostile file on the trusted path).
    #[inline(always)]
    pub(crate) fn follow(&self, w: &mut RayWalk, exit: &Exit, ncount: u32) -> bool {
        let v = &self.view;
        let lo = self.frame.root_lo;
        let a = w.address as usize;
        let (cell, level) = (w.cell, w.level);
        let size = self.frame.sizes[level as usize & 31];
        let Exit { face, off_a, d_a, .. } = *exit;
        let axis = face >> 1;
        // The neighbour across the face: none at the root's boundary, else one, or one
        // of four picked by the sides of the face's median lines (the Plücker products
        // with the lines through the face's centre).
        let n = (ncount >> (4 * face)) & 0xF;
        if n == 0 {
            return false;
        }
        let half = 0.5 * size;
        let negative_a = face & 1 == 0;
        // The face centre's offset from the origin along `k`.
        let mid = |k: usize| (lo[k] + (2 * cell[k] + 1) as f32 * half) - w.o[k];
        let side = |k: usize| {
            let p = off_a * w.d[k] - mid(k) * d_a;
            ((p > 0.0) ^ negative_a) as u32
        };
        let sides = if w.rule == ExitRule::Exact {
            [0, 1, 2].map(|k| exact_side(off_a, d_a, mid(k), w.d[k], negative_a))
        } else {
            [side(0), side(1), side(2)]
        };
        // The quadrant: the side bits of the two other axes, in increasing order.
        let side_bits = sides[0] | sides[1] << 1 | sides[2] << 2;
        let quadrant = (side_bits & ((1 << axis) - 1)) | ((side_bits >> (axis + 1)) << axis);
        let link = a + LEAF_HEADER_WORDS + (links_before(ncount, face) + (n >> 2) * quadrant) as usize;
        // A link past the array (a hostile file on the trusted path) ends the walk.
        let Some(&next) = v.octree.get(link) else { return false };
        w.address = next;
        // The neighbour's cell: across the face at this level, then one level finer
        // (four neighbours: the quadrant's child on our side), the same, or one coarser
        // (the flag in nCount), without a branch: cell' = ((across << 1) | child bits)
        // >> (1 - d).
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
        true
    }
}

/// Where a walk leaves its leaf ([`Tracer::exit_of`]): the face, the distance, and the
/// exit axis's corner offset and direction component (for the median-line sides).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Exit {
    pub face: usize,
    pub t: f32,
    off_a: f32,
    d_a: f32,
}

impl Tracer<'_> {
    /// The exit face of a walk that does not follow the table (`tables::exit_rule`),
    /// and its exit distance where the rule computes one: exactly for
    /// [`ExitRule::Exact`]; by the slab rule for [`ExitRule::Flat`] and the slab knob
    /// (the distance is then the step's own `offset * inverse`).
    #[cold]
    #[inline(never)]
    fn careful_exit(&self, w: &RayWalk, off: [f32; 3]) -> (usize, Option<f32>) {
        if w.rule == ExitRule::Exact {
            let (face, t) = exact_exit(off, w.d);
            return (face, Some(t));
        }
        (exit_along_moving_axes(off, w.d, w.inv), None)
    }
}

/// The ray's parameter interval inside the box `lo..hi` and the axis it enters by (the
/// first of equal ones), or `None` if it misses. Zero components are handled
/// explicitly: `0 * inf` never happens. On SSE2 the six divisions are two (8 % faster
/// primary rays), with the same answer.
#[inline(always)]
pub(crate) fn clip(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> Option<(f32, f32, usize)> {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    if !d.contains(&0.0) {
        return super::hw::clip_sse2(o, d, lo, hi);
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
