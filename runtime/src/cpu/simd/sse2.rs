//! The octree step on SSE2 (every x86-64 processor): the per-axis arithmetic of a
//! step — exit corner, Plücker exit code, median-line sides, next cell — on three
//! lanes at once. Same operations and order as the scalar step, so the same bits.

use std::arch::x86_64::*;

use octrace_format::layout::{links_before, COARSER_SHIFT, LEAF_HEADER_WORDS};

use super::avx2;
use crate::cpu::hw::prefetch;
use crate::cpu::tracer::{Tally, Tracer, TEST_EXACT, TEST_F64, TEST_MOLLER_TRUMBORE, TEST_WATERTIGHT};
use crate::cpu::triangle::{intersect_f64, TriRay};
use crate::cpu::walk::{exit_along_moving_axes, Batch, LeafTest, LeafVisit, RayWalk};
use crate::cpu::watertight::{plane_distance, Shear};
use crate::ray::Hit;

/// A walk in progress, in SSE registers' layout (lane 3 unused, zero).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SseWalk {
    o: __m128,
    d: __m128,
    /// `d` rotated to `(y, z, x)`, for the three Plücker products in one go.
    d_yzx: __m128,
    /// 1.0 where the exit corner is on the cell's high side.
    high: __m128,
    /// The root cube's low corner.
    lo: __m128,
    /// The current cell (integers).
    cell: __m128i,
    /// Scalar direction and inverse, for the exit distance along the chosen axis.
    d_s: [f32; 3],
    inv_s: [f32; 3],
    /// Whether a direction component is zero (then the slab rule decides the exit,
    /// `walk::exit_along_moving_axes`).
    any_zero: bool,
    /// The ray's shear for the watertight test, in three-lane form.
    shear_sse: ShearSse,
    exits: &'static [u8; 8],
    /// The faces the ray can leave a cell by, one an axis (`2k + high[k]`).
    faces: [u32; 3],
    /// Whether each step asks for the records across `faces` before its triangle
    /// tests ([`Tracer::with_read_ahead`]).
    ahead: bool,
    tmin: f32,
    tmax: f32,
    address: u32,
    level: u32,
    /// The nearest hit so far and its distance.
    pub(crate) best: Option<Hit>,
    t_best: f32,
    steps: u32,
}

impl SseWalk {
    /// The SSE form of a scalar walk's starting state, for tracer `t`; `alone` for a
    /// nearest-hit walk with no other in flight (a one-ray call), which reads ahead
    /// where the tracer says so and the ray starts inside the root cube
    /// ([`Tracer::with_read_ahead`]). (No `target_feature`: inlined into the batch loop
    /// in whatever features it is compiled with.)
    #[inline(always)]
    pub(crate) fn from_scalar(t: &Tracer<'_>, w: &RayWalk, alone: bool) -> SseWalk {
        let ((lo, hi), o) = (t.root_box(), w.o());
        let ahead = alone && t.reads_ahead() && (0..3).all(|k| lo[k] <= o[k] && o[k] <= hi[k]);
        // SAFETY: SSE2 is enabled at compile time for this module (`simd/mod.rs`).
        unsafe { Self::from_scalar_sse2(w, lo, ahead) }
    }

    #[inline(always)]
    unsafe fn from_scalar_sse2(w: &RayWalk, root_lo: [f32; 3], ahead: bool) -> SseWalk {
        // SAFETY: the caller's.
        let v3 = |a: [f32; 3]| unsafe { _mm_setr_ps(a[0], a[1], a[2], 0.0) };
        let (o, d) = (w.o(), w.d());
        // SAFETY: the caller's.
        unsafe {
            SseWalk {
                o: v3(o),
                d: v3(d),
                d_yzx: _mm_setr_ps(d[1], d[2], d[0], 0.0),
                high: v3(w.high().map(|h| h as f32)),
                lo: v3(root_lo),
                cell: _mm_setr_epi32(w.cell()[0] as i32, w.cell()[1] as i32, w.cell()[2] as i32, 0),
                d_s: d,
                inv_s: w.inv(),
                any_zero: d.contains(&0.0),
                shear_sse: ShearSse::new(&w.shear()),
                exits: w.exits(),
                faces: [0, 1, 2].map(|k| 2 * k as u32 + w.high()[k]),
                ahead,
                tmin: w.tmin(),
                tmax: w.tmax(),
                address: w.address(),
                level: w.level(),
                best: None,
                t_best: w.t_best(),
                steps: 0,
            }
        }
    }
}

/// `a x b` on three lanes: `a.yzx * b.zxy - a.zxy * b.yzx`.
#[target_feature(enable = "sse2")]
#[inline]
fn cross(a: __m128, b: __m128) -> __m128 {
    let a_yzx = _mm_shuffle_ps::<0b11_00_10_01>(a, a);
    let b_yzx = _mm_shuffle_ps::<0b11_00_10_01>(b, b);
    let c = _mm_sub_ps(_mm_mul_ps(a, b_yzx), _mm_mul_ps(a_yzx, b));
    _mm_shuffle_ps::<0b11_00_10_01>(c, c)
}

/// `a . b` of three lanes (lane 3 must be zero in one of them), in the scalar order
/// `(x + y) + z`.
#[target_feature(enable = "sse2")]
#[inline]
fn dot(a: __m128, b: __m128) -> f32 {
    let m = _mm_mul_ps(a, b);
    let y = _mm_shuffle_ps::<0b01_01_01_01>(m, m);
    let z = _mm_movehl_ps(m, m);
    _mm_cvtss_f32(_mm_add_ss(_mm_add_ss(m, y), z))
}

/// Möller-Trumbore on three lanes: the scalar `triangle::intersect`, same operations.
#[target_feature(enable = "sse2")]
#[inline]
fn intersect_sse(o: __m128, d: __m128, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let t: &[f32; 9] = t.try_into().ok()?;
    let v0 = _mm_setr_ps(t[0], t[1], t[2], 0.0);
    let e1 = _mm_sub_ps(_mm_setr_ps(t[3], t[4], t[5], 0.0), v0);
    let e2 = _mm_sub_ps(_mm_setr_ps(t[6], t[7], t[8], 0.0), v0);
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = _mm_sub_ps(o, v0);
    let u = dot(s, p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let dist = dot(e2, q) * inv;
    (dist >= tmin && dist <= tmax).then_some((dist, u, v))
}

/// The watertight test (`watertight::Shear`) with one vertex a lane: the same
/// operations in the same order as the scalar test, so the same bits, without the
/// scalar form's indexing by the ray's axes (a trip through the stack) and with the
/// three edge signs decided by two mask compares instead of six branches.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShearSse {
    o: [__m128; 3],
    /// The ray's axes `(kx, ky, kz)`, to pick coordinate vectors.
    k: [u8; 3],
    sx: __m128,
    sy: __m128,
    scalar: Shear,
}

impl ShearSse {
    /// # Safety
    /// SSE2 must be available (it is enabled at compile time for this module).
    #[inline(always)]
    pub(crate) unsafe fn new(shear: &Shear) -> ShearSse {
        let k = shear.axes();
        let [sx, sy, _] = shear.scales();
        let o = shear.origin();
        // SAFETY: the caller's.
        unsafe {
            ShearSse {
                o: [_mm_set1_ps(o[0]), _mm_set1_ps(o[1]), _mm_set1_ps(o[2])],
                k: k.map(|a| a as u8),
                sx: _mm_set1_ps(sx),
                sy: _mm_set1_ps(sy),
                scalar: *shear,
            }
        }
    }

    /// As `Shear::intersect`, bit for bit. (No `target_feature` attribute: SSE2 is
    /// enabled for the whole build, which this module requires, and the attribute
    /// would forbid `inline(always)`: the step calls this for every triangle.)
    #[inline(always)]
    pub(crate) fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        // SAFETY: SSE2 is enabled at compile time for this module (`simd/mod.rs`).
        unsafe {
            let t: &[f32; 9] = t.try_into().ok()?;
            // Vertices relative to the origin, one a lane: (a, b, c) for x, y and z.
            let rx = _mm_sub_ps(_mm_setr_ps(t[0], t[3], t[6], 0.0), self.o[0]);
            let ry = _mm_sub_ps(_mm_setr_ps(t[1], t[4], t[7], 0.0), self.o[1]);
            let rz = _mm_sub_ps(_mm_setr_ps(t[2], t[5], t[8], 0.0), self.o[2]);
            let r = [rx, ry, rz];
            let (px, py, pz) = (r[self.k[0] as usize], r[self.k[1] as usize], r[self.k[2] as usize]);
            // Sheared x and y: a[kx] - sx * a[kz], a[ky] - sy * a[kz].
            let x = _mm_sub_ps(px, _mm_mul_ps(self.sx, pz));
            let y = _mm_sub_ps(py, _mm_mul_ps(self.sy, pz));
            // Edge functions (u, v, w) = (cx*by - cy*bx, ax*cy - ay*cx, bx*ay - by*ax):
            // lanes rotated to (b, c, a) and (c, a, b).
            let x1 = _mm_shuffle_ps::<0b11_00_10_01>(x, x);
            let y1 = _mm_shuffle_ps::<0b11_00_10_01>(y, y);
            let x2 = _mm_shuffle_ps::<0b11_01_00_10>(x, x);
            let y2 = _mm_shuffle_ps::<0b11_01_00_10>(y, y);
            let e = _mm_sub_ps(_mm_mul_ps(x2, y1), _mm_mul_ps(y2, x1));
            let zero = _mm_setzero_ps();
            if _mm_movemask_ps(_mm_cmpeq_ps(e, zero)) & 7 != 0 {
                // An edge function rounded to zero: the scalar test decides it in f64.
                return self.scalar.intersect(t, tmin, tmax);
            }
            let negative = _mm_movemask_ps(_mm_cmplt_ps(e, zero)) & 7;
            let positive = _mm_movemask_ps(_mm_cmpgt_ps(e, zero)) & 7;
            if negative != 0 && positive != 0 {
                return None;
            }
            let u = _mm_cvtss_f32(e);
            let v = _mm_cvtss_f32(_mm_shuffle_ps::<0b01_01_01_01>(e, e));
            let w = _mm_cvtss_f32(_mm_movehl_ps(e, e));
            let det = u + v + w;
            if det == 0.0 {
                return None;
            }
            let dist = plane_distance(self.scalar.origin(), self.scalar.direction(), t);
            (dist >= tmin && dist <= tmax).then_some((dist, v / det, w / det))
        }
    }
}

/// The watertight test of one triangle, in either form: [`ShearSse`] (the SSE step's)
/// or the scalar [`Shear`] (the lanes', whose triangles go eight at a time through
/// `avx2::hit8` and only the rare leftovers one by one). Both give the same bits.
pub(crate) trait WatertightTest {
    /// The hit `(t, u, v)` of the triangle (nine floats) within `[tmin, tmax]`.
    fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)>;
    /// The ray's shear, for the eight-wide test.
    fn scalar(&self) -> &Shear;
}

impl WatertightTest for ShearSse {
    #[inline(always)]
    fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        ShearSse::intersect(self, t, tmin, tmax)
    }
    #[inline(always)]
    fn scalar(&self) -> &Shear {
        &self.scalar
    }
}

impl WatertightTest for Shear {
    #[inline(always)]
    fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        Shear::intersect(self, t, tmin, tmax)
    }
    #[inline(always)]
    fn scalar(&self) -> &Shear {
        self
    }
}

/// The SSE step's triangle test, `TEST` fixed at compile time.
pub(crate) struct SseTest<'w, const TEST: u8, S: WatertightTest = ShearSse> {
    /// Borrowed from the walk: a copy cost 29 instructions a step (callgrind), 3-7 %
    /// of the time.
    pub(crate) shear: &'w S,
    pub(crate) o: __m128,
    pub(crate) d: __m128,
    pub(crate) d_s: [f32; 3],
    /// Whether the watertight test runs eight triangles at once (`avx2::hit8`):
    /// where the walk runs its x86-64-v3 build.
    pub(crate) wide: bool,
}

impl<const TEST: u8, S: WatertightTest> LeafTest for SseTest<'_, TEST, S> {
    #[inline(always)]
    fn hit(&self, tri: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        match TEST {
            // SAFETY: SSE2 is enabled at compile time for this module.
            TEST_MOLLER_TRUMBORE => unsafe { intersect_sse(self.o, self.d, tri, tmin, tmax) },
            TEST_F64 => {
                let o: [f32; 4] = bytemuck::cast(self.o);
                intersect_f64(&TriRay { o: [o[0], o[1], o[2]], d: self.d_s }, tri, tmin, tmax)
            }
            TEST_EXACT => self.shear.scalar().intersect_exact(tri, tmin, tmax),
            _ => self.shear.intersect(tri, tmin, tmax),
        }
    }

    #[inline(always)]
    fn batch_size(&self) -> usize {
        if (TEST == TEST_WATERTIGHT || TEST == TEST_EXACT) && self.wide {
            avx2::LANES
        } else {
            0
        }
    }

    #[inline(always)]
    fn batch<const ANY: bool>(&self, triangles: &[f32], refs: &[u32], tmin: f32, tmax: f32) -> Batch {
        // SAFETY: `wide` is set only where the processor has AVX2 (the tracer's
        // x86-64-v3 walk); `batch_size` is 0 otherwise and the step does not call this.
        unsafe {
            if TEST == TEST_EXACT {
                avx2::hit8::<ANY, true>(self.shear.scalar(), triangles, refs, tmin, tmax)
            } else {
                avx2::hit8::<ANY, false>(self.shear.scalar(), triangles, refs, tmin, tmax)
            }
        }
    }

    #[inline(always)]
    fn nearer(&self, new: &[f32], kept: &[f32]) -> Option<std::cmp::Ordering> {
        (TEST == TEST_EXACT).then(|| self.shear.scalar().compare_distances(new, kept))
    }

    #[inline(always)]
    fn fan_shear(&self) -> Option<&Shear> {
        (TEST == TEST_WATERTIGHT).then(|| self.shear.scalar())
    }
}

/// The lanes equal to `axis`, all ones.
#[target_feature(enable = "sse2")]
fn axis_mask(axis: usize) -> __m128i {
    _mm_cmpeq_epi32(_mm_set1_epi32(axis as i32), _mm_setr_epi32(0, 1, 2, 3))
}

/// Lane `axis` of `v` in every lane (the others are masked to zero and summed away).
#[target_feature(enable = "sse2")]
fn broadcast_lane(v: __m128, mask: __m128i) -> __m128 {
    let m = _mm_and_ps(v, _mm_castsi128_ps(mask));
    let s = _mm_add_ps(m, _mm_shuffle_ps::<0b10_11_00_01>(m, m));
    _mm_add_ps(s, _mm_shuffle_ps::<0b01_00_11_10>(s, s))
}

/// Visits the walk's current leaf and moves to the next; returns whether the walk is
/// over (its answer is then in `w.best`). The scalar `Tracer::step` documents each
/// stage; this is the same computation, three lanes at a time.
///
/// `TEST` is the triangle test (`TEST_*` of `tracer`) and `SLAB` the slab exit-face
/// test, fixed at compile time so the default's step carries no test of either.
///
/// No `target_feature` attribute, so that it is inlined (`inline(always)`) into the
/// batch loop, which `cpu` compiles twice: for the x86-64 baseline, and with AVX2
/// where the processor has it (same operations, VEX encodings and more registers).
///
/// # Safety
/// SSE2 must be available: it is enabled at compile time for this module
/// (`simd/mod.rs`).
#[inline(always)]
pub(crate) unsafe fn step<const ANY: bool, const TEST: u8, const SLAB: bool>(
    t: &Tracer<'_>,
    w: &mut SseWalk,
    stats: &mut impl Tally,
) -> bool {
    // SAFETY: SSE2 is enabled at compile time for this module (the caller's contract).
    unsafe {
        let v = t.view();
        let a = w.address as usize;
        // 0. A walk that reads ahead (a one-ray nearest-hit walk from inside the root
        //    cube) asks now for the next record on every face the ray can leave by, so
        //    that its load overlaps the triangle tests and the exit below (a lone walk
        //    has nothing else to overlap it with).
        if w.ahead {
            read_ahead(v.octree, a, &w.faces);
        }
        // 1. Triangles.
        let test = SseTest::<TEST> { shear: &w.shear_sse, o: w.o, d: w.d, d_s: w.d_s, wide: t.uses_x86_64_v3() };
        let mut visit = LeafVisit { tmin: w.tmin, t_best: &mut w.t_best, best: &mut w.best };
        let Some((_, ncount)) = t.visit_leaf::<ANY>(w.address, &mut w.steps, &mut visit, stats, &test) else {
            return true;
        };
        // 2. Exit corner `lo + (cell + high) * size - o`, and the Plücker exit code.
        let size = _mm_set1_ps(t.cell_size(w.level));
        let lo = w.lo;
        let cellf = _mm_cvtepi32_ps(w.cell);
        let off = _mm_sub_ps(_mm_add_ps(_mm_mul_ps(_mm_add_ps(cellf, w.high), size), lo), w.o);
        let off_yzx = _mm_shuffle_ps::<0b11_00_10_01>(off, off);
        let p = _mm_sub_ps(_mm_mul_ps(off, w.d_yzx), _mm_mul_ps(off_yzx, w.d));
        let code = (_mm_movemask_ps(_mm_cmpgt_ps(p, _mm_setzero_ps())) & 7) as usize;
        let mut face = w.exits[code] as usize;
        if w.any_zero || SLAB {
            let off_s: [f32; 4] = bytemuck::cast(off);
            face = exit_along_moving_axes([off_s[0], off_s[1], off_s[2]], w.d_s, w.inv_s);
        }
        let axis = face >> 1;
        let mask = axis_mask(axis);
        let off_a = broadcast_lane(off, mask);
        // 3. Stop when the best hit is inside this leaf, or past tmax.
        let t_exit = _mm_cvtss_f32(off_a) * w.inv_s[axis];
        if (w.best.is_some() && w.t_best <= t_exit) || t_exit >= w.tmax {
            return true;
        }
        // 4. The neighbour.
        let n = (ncount >> (4 * face)) & 0xF;
        if n == 0 {
            return true;
        }
        let d_a = broadcast_lane(w.d, mask);
        let half = _mm_mul_ps(_mm_set1_ps(0.5), size);
        let mid = _mm_add_ps(_mm_mul_ps(_mm_add_ps(_mm_add_ps(cellf, cellf), _mm_set1_ps(1.0)), half), lo);
        let ps = _mm_sub_ps(_mm_mul_ps(off_a, w.d), _mm_mul_ps(_mm_sub_ps(mid, w.o), d_a));
        let negative_a = face & 1 == 0;
        let sides = ((_mm_movemask_ps(_mm_cmpgt_ps(ps, _mm_setzero_ps())) as u32) ^ if negative_a { 7 } else { 0 }) & 7;
        let quadrant = (sides & ((1 << axis) - 1)) | ((sides >> (axis + 1)) << axis);
        let link = a + LEAF_HEADER_WORDS + (links_before(ncount, face) + (n >> 2) * quadrant) as usize;
        // A link past the array (a hostile file on the trusted path) ends the walk.
        let Some(&next) = v.octree.get(link) else { return true };
        w.address = next;
        // The next record is this ray's next load, after the other rays in flight have
        // stepped: ask for it now.
        // A record is 16 to 112 bytes; its links spill onto the next cache line when
        // it starts late in one: ask for the line 60 bytes on too (dragon incoherent
        // rays 6 % faster, the other sets unchanged).
        prefetch(v.octree, w.address);
        prefetch(v.octree, w.address.wrapping_add(15));
        // 5. The next cell: ((across << 1) | child bits) >> (1 + coarser - finer).
        let coarser = (ncount >> (COARSER_SHIFT as usize + face)) & 1;
        let finer = n >> 2;
        let up = if negative_a { -1 } else { 1 };
        let across = _mm_add_epi32(w.cell, _mm_and_si128(mask, _mm_set1_epi32(up)));
        let child_bits = (sides & !(1 << axis)) | ((negative_a as u32) << axis);
        let lane_bits = _mm_setr_epi32(1, 2, 4, 8);
        let bits = _mm_srli_epi32::<31>(_mm_cmpeq_epi32(
            _mm_and_si128(_mm_set1_epi32(child_bits as i32), lane_bits),
            lane_bits,
        ));
        let shifted = _mm_or_si128(_mm_slli_epi32::<1>(across), bits);
        // A hostile file's counts (on the trusted path) may make the shift 32 or more:
        // the lanes then hold zero, a cell the step bound or a miss soon ends.
        w.cell = _mm_srl_epi32(shifted, _mm_cvtsi32_si128((1 + coarser).wrapping_sub(finer) as i32));
        w.level = w.level.wrapping_add(finer).wrapping_sub(coarser);
        false
    }
}

/// Asks for the first neighbour's record across each of `faces` of the leaf record at
/// `a` (a hint: a record or link past the array asks for nothing).
#[inline(always)]
fn read_ahead(octree: &[u32], a: usize, faces: &[u32; 3]) {
    let Some(&ncount) = octree.get(a + 3) else { return };
    for &face in faces {
        if (ncount >> (4 * face)) & 0xF != 0 {
            if let Some(&next) = octree.get(a + LEAF_HEADER_WORDS + links_before(ncount, face as usize) as usize) {
                prefetch(octree, next);
            }
        }
    }
}

/// Walks one ray to its end.
///
/// Where the processor has x86-64-v3's features, the walk compiled for them runs (as
/// the batch loop in `cpu` does).
pub(crate) fn walk<const ANY: bool, const TEST: u8, const SLAB: bool>(
    t: &Tracer<'_>,
    start: &RayWalk,
    stats: &mut impl Tally,
) -> Option<Hit> {
    if t.uses_x86_64_v3() {
        // SAFETY: the processor has the features (`uses_x86_64_v3` is never true
        // where it does not).
        return unsafe { walk_v3::<ANY, TEST, SLAB>(t, start, stats) };
    }
    walk_loop::<ANY, TEST, SLAB>(t, start, stats)
}

/// [`walk`] compiled for x86-64-v3 (the batch loop's features in `cpu`).
///
/// # Safety
/// The processor must have the features.
#[target_feature(enable = "avx2,bmi1,bmi2,fma,lzcnt,popcnt")]
unsafe fn walk_v3<const ANY: bool, const TEST: u8, const SLAB: bool>(
    t: &Tracer<'_>,
    start: &RayWalk,
    stats: &mut impl Tally,
) -> Option<Hit> {
    walk_loop::<ANY, TEST, SLAB>(t, start, stats)
}

#[inline(always)]
fn walk_loop<const ANY: bool, const TEST: u8, const SLAB: bool>(
    t: &Tracer<'_>,
    start: &RayWalk,
    stats: &mut impl Tally,
) -> Option<Hit> {
    // SAFETY: SSE2 is enabled at compile time for this module
    // (`cfg(target_feature = "sse2")` in `simd/mod.rs`), so the target-feature
    // functions run on a processor that has it.
    unsafe {
        // Nearest-hit walks only: occlusion queries lost 2-5 % reading ahead (shadow
        // rays toward one light find the records of the ray before them in the cache).
        let mut w = SseWalk::from_scalar(t, start, !ANY);
        while !step::<ANY, TEST, SLAB>(t, &mut w, stats) {}
        t.answer(w.best)
    }
}

/// Starts a walk in SSE form for a batch (and asks for its first leaf's record). Its
/// steps do not read ahead: the batch keeps other walks in flight instead.
#[inline(always)]
pub(crate) fn begin(t: &Tracer<'_>, start: &RayWalk) -> SseWalk {
    let w = SseWalk::from_scalar(t, start, false);
    prefetch(t.view().octree, w.address);
    w
}

/// One step in SSE form.
#[inline(always)]
pub(crate) fn step_safe<const ANY: bool, const TEST: u8, const SLAB: bool>(
    t: &Tracer<'_>,
    w: &mut SseWalk,
    stats: &mut impl Tally,
) -> bool {
    // SAFETY: as in `walk`: SSE2 is enabled at compile time for this module.
    unsafe { step::<ANY, TEST, SLAB>(t, w, stats) }
}
