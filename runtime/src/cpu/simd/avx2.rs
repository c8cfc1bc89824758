//! The watertight triangle test on eight triangles at once (AVX2): a leaf's
//! triangles, one a lane. Each lane runs the scalar test's operations in its order
//! (`watertight::Shear::intersect`; no fused multiply-adds), so each lane's answer
//! has the scalar answer's bits; the batch then picks the answer a test of one
//! triangle after another would have kept.
//!
//! Only the batch loop and single-ray walk compiled for x86-64-v3 call it (where it
//! is inlined); elsewhere the step tests one triangle at a time.
//!
//! Also here: the transpose of eight records of floats into rows, which the test and
//! the eight-ray begin (`begin8`) read their inputs with.

use std::arch::x86_64::*;

use octrace_format::layout::TRIANGLE_FLOATS;

use crate::cpu::walk::Batch;
use crate::cpu::watertight::{rounded_if_certain, Shear};

/// Triangles a batch.
pub(crate) const LANES: usize = 8;

/// Two triangles' floats `off..off + 4` in one register (`lo` low, `hi` high).
///
/// # Safety
/// AVX must be available (where this is inlined); both reads in bounds.
#[inline(always)]
unsafe fn pair(lo: *const f32, hi: *const f32) -> __m256 {
    // SAFETY: the caller's.
    unsafe { _mm256_set_m128(_mm_loadu_ps(hi), _mm_loadu_ps(lo)) }
}

/// Floats `off..off + 4` of eight triangles, one row of eight a float: a 4 x 4
/// transpose in each half (triangles 0-3 low, 4-7 high).
///
/// # Safety
/// AVX must be available (where this is inlined); the reads in bounds.
#[inline(always)]
pub(super) unsafe fn transpose(p: &[*const f32; LANES], off: usize) -> [__m256; 4] {
    // SAFETY: the caller's.
    unsafe {
        let r0 = pair(p[0].add(off), p[4].add(off));
        let r1 = pair(p[1].add(off), p[5].add(off));
        let r2 = pair(p[2].add(off), p[6].add(off));
        let r3 = pair(p[3].add(off), p[7].add(off));
        let t0 = _mm256_unpacklo_ps(r0, r1);
        let t1 = _mm256_unpackhi_ps(r0, r1);
        let t2 = _mm256_unpacklo_ps(r2, r3);
        let t3 = _mm256_unpackhi_ps(r2, r3);
        [
            _mm256_shuffle_ps::<0b01_00_01_00>(t0, t2),
            _mm256_shuffle_ps::<0b11_10_11_10>(t0, t2),
            _mm256_shuffle_ps::<0b01_00_01_00>(t1, t3),
            _mm256_shuffle_ps::<0b11_10_11_10>(t1, t3),
        ]
    }
}

/// The lanes (of the first `used` bits) where `m` is set.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn lanes(m: __m256, used: u32) -> u32 {
    // SAFETY: the caller's.
    unsafe { _mm256_movemask_ps(m) as u32 & used }
}

/// `a[k] - s * a[kz]`: a sheared coordinate of a vertex, eight lanes.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn shear_axis(a: &[__m256; 3], k: usize, kz: usize, s: __m256) -> __m256 {
    // SAFETY: the caller's.
    unsafe { _mm256_sub_ps(a[k], _mm256_mul_ps(s, a[kz])) }
}

/// Whether any of three lanes' compares holds: `cmp(u) | cmp(v) | cmp(w)`.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn any3<const CMP: i32>(u: __m256, v: __m256, w: __m256, x: __m256) -> __m256 {
    // SAFETY: the caller's.
    unsafe {
        _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps::<CMP>(u, x), _mm256_cmp_ps::<CMP>(v, x)), _mm256_cmp_ps::<CMP>(w, x))
    }
}

/// All ones in the lanes of `b`'s set bits (bit `i` for lane `i`).
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
pub(crate) unsafe fn mask_of(b: u32) -> __m256i {
    // SAFETY: the caller's.
    unsafe {
        let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(b as i32), lane_bits), lane_bits)
    }
}

/// All ones in the lanes where `x <= limit`, as unsigned words.
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
pub(crate) unsafe fn at_most(x: __m256i, limit: __m256i) -> __m256i {
    // SAFETY: the caller's.
    unsafe { _mm256_cmpeq_epi32(_mm256_max_epu32(x, limit), limit) }
}

/// Asks for the stored triangles `refs` of `triangles` (the line each starts in),
/// eight references at a time.
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
pub(crate) unsafe fn prefetch_triangles(triangles: &[f32], refs: &[u32]) {
    let base = triangles.as_ptr();
    for chunk in refs.chunks(LANES) {
        // SAFETY: AVX2 is the caller's; the masked load reads `chunk` only, and a
        // prefetch reads nothing architecturally (any address will do: a hostile
        // index only asks for a useless line).
        unsafe {
            let in_use = mask_of((1u32 << chunk.len()) - 1);
            let tri = _mm256_maskload_epi32(chunk.as_ptr().cast(), in_use);
            // Unused lanes ask for triangle 0's line again: cheaper than a branch.
            let floats = _mm256_add_epi32(_mm256_slli_epi32::<3>(tri), tri);
            let at: [u32; LANES] = std::mem::transmute(floats);
            for o in at {
                _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(o as usize).cast());
            }
        }
    }
}

/// Tests the triangles `refs` (1 to [`LANES`]) of `triangles` against the sheared
/// ray. For the nearest hit (`ANY` false), the answer is the last of the nearest
/// hits in `refs` order (a one-by-one test accepts `t <= t_best`, so a later tie
/// wins: the lowest input id, leaves listing triangles in descending input order);
/// for any hit, the first hit in order.
///
/// No `target_feature` attribute, so that it is inlined (`inline(always)`) into the
/// x86-64-v3 step, which has AVX2.
///
/// # Safety
/// The processor must have AVX2.
#[inline(always)]
pub(crate) unsafe fn hit8<const ANY: bool, const EXACT: bool>(
    shear: &Shear,
    triangles: &[f32],
    refs: &[u32],
    tmin: f32,
    tmax: f32,
) -> Batch {
    // SAFETY: the caller's.
    let (inside, det, v, w, p) = match unsafe { accepted8::<EXACT>(shear, triangles, refs) } {
        Accepted::OneByOne => return Batch::OneByOne,
        Accepted::Miss => return Batch::Miss,
        Accepted::Inside { inside, det, v, w, p } => (inside, det, v, w, p),
    };
    // SAFETY: AVX2 is the caller's; each pointer has nine floats to read.
    unsafe {
        // The distances of the triangles the edge functions accept (one or two a batch
        // at most, mostly none), in f64 as the one-by-one test computes them; the
        // answer is the one testing one after the other keeps: for an any-hit query
        // the first in range, else the nearest, of equal ones the last.
        let (o, d) = (wide(shear.origin()), wide(shear.direction()));
        let mut best: Option<(usize, f32)> = None;
        let mut left = inside;
        let lane_of = |x: __m256, lane: usize| -> f32 { std::mem::transmute::<__m256, [f32; LANES]>(x)[lane] };
        while left != 0 {
            let lane = left.trailing_zeros() as usize;
            left &= left - 1;
            let tmax = best.map_or(tmax, |b| b.1);
            let t = if EXACT {
                // Correctly rounded; two hits at one rounded distance are ordered
                // exactly one by one.
                let Some(t) = plane_distance_rounded_facing(shear, o, d, p[lane]).0 else { continue };
                if best.is_some_and(|b| b.1 == t) {
                    return Batch::OneByOne;
                }
                t
            } else {
                plane_distance(o, d, p[lane])
            };
            if t >= tmin && t <= tmax {
                best = Some((lane, t));
                if ANY {
                    break;
                }
            }
        }
        let Some((lane, t)) = best else { return Batch::Miss };
        let det = lane_of(det, lane);
        Batch::Hit(lane, t, lane_of(v, lane) / det, lane_of(w, lane) / det)
    }
}

/// What the edge functions of a batch of eight say ([`accepted8`]).
enum Accepted {
    /// Test these one by one (an index out of range, an edge function of exactly zero).
    OneByOne,
    /// No triangle holds the ray.
    Miss,
    /// The lanes whose triangle holds the ray (`inside`), their `det` and the edge
    /// functions `v` and `w` (barycentrics `v / det`, `w / det`), and each lane's
    /// triangle.
    Inside { inside: u32, det: __m256, v: __m256, w: __m256, p: [*const f32; LANES] },
}

/// The edge functions of the triangles `refs` (1 to [`LANES`]) against the sheared ray,
/// as the scalar test computes them: what [`hit8`] and [`crossings8`] start from.
///
/// # Safety
/// The processor must have AVX2.
#[inline(always)]
unsafe fn accepted8<const EXACT: bool>(shear: &Shear, triangles: &[f32], refs: &[u32]) -> Accepted {
    debug_assert!((1..=LANES).contains(&refs.len()));
    let stored = triangles.len() / TRIANGLE_FLOATS;
    let Some(limit) = stored.checked_sub(1) else { return Accepted::OneByOne };
    // SAFETY: AVX2 is the caller's; the masked load reads `refs` only.
    let full: [u32; LANES] = unsafe {
        // The references, unused lanes (a batch of fewer than eight) repeating the
        // last (and masked out below), then all checked at once, the check off the
        // loads' path (the loads depend on it by a predicted branch, not by their
        // addresses): 6 % fewer instructions on the dragon's shadow rays than a
        // compare and a branch a lane, and 7 % fewer on the bunny's camera rays for
        // short batches than a loop over the lanes.
        let n = refs.len();
        let tri = if n == LANES {
            _mm256_loadu_si256(refs.as_ptr().cast())
        } else {
            let used = _mm256_cmpgt_epi32(_mm256_set1_epi32(n as i32), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
            let last = _mm256_set1_epi32(refs[n - 1] as i32);
            _mm256_blendv_epi8(last, _mm256_maskload_epi32(refs.as_ptr().cast(), used), used)
        };
        let limit = _mm256_set1_epi32(limit.min(u32::MAX as usize) as i32);
        if _mm256_movemask_epi8(at_most(tri, limit)) != -1 {
            return Accepted::OneByOne;
        }
        std::mem::transmute::<__m256i, [u32; LANES]>(tri)
    };
    let at = |lane: usize| {
        // SAFETY: every `tri <= limit`, so `tri * 9 + 9 <= triangles.len()`.
        unsafe { triangles.as_ptr().add(full[lane] as usize * TRIANGLE_FLOATS) }
    };
    let p = [at(0), at(1), at(2), at(3), at(4), at(5), at(6), at(7)];
    // SAFETY: AVX2 is the caller's; each pointer has nine floats to read.
    unsafe {
        // Vertex coordinates, one row of eight a coordinate.
        let [x0, y0, z0, x1] = transpose(&p, 0);
        let [y1, z1, x2, y2] = transpose(&p, 4);
        let z2 = _mm256_setr_ps(
            *p[0].add(8),
            *p[1].add(8),
            *p[2].add(8),
            *p[3].add(8),
            *p[4].add(8),
            *p[5].add(8),
            *p[6].add(8),
            *p[7].add(8),
        );
        // Relative to the origin, then sheared along the ray's axes.
        let o = shear.origin();
        let (ox, oy, oz) = (_mm256_set1_ps(o[0]), _mm256_set1_ps(o[1]), _mm256_set1_ps(o[2]));
        let a = [_mm256_sub_ps(x0, ox), _mm256_sub_ps(y0, oy), _mm256_sub_ps(z0, oz)];
        let b = [_mm256_sub_ps(x1, ox), _mm256_sub_ps(y1, oy), _mm256_sub_ps(z1, oz)];
        let c = [_mm256_sub_ps(x2, ox), _mm256_sub_ps(y2, oy), _mm256_sub_ps(z2, oz)];
        let [kx, ky, kz] = shear.axes();
        let [sx, sy, _] = shear.scales();
        let (sx, sy) = (_mm256_set1_ps(sx), _mm256_set1_ps(sy));
        let (ax, ay) = (shear_axis(&a, kx, kz, sx), shear_axis(&a, ky, kz, sy));
        let (bx, by) = (shear_axis(&b, kx, kz, sx), shear_axis(&b, ky, kz, sy));
        let (cx, cy) = (shear_axis(&c, kx, kz, sx), shear_axis(&c, ky, kz, sy));
        // Edge functions, as the scalar test.
        let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
        let v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
        let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
        let used = (1u32 << refs.len()) - 1;
        let zero = _mm256_setzero_ps();
        if EXACT {
            // `watertight::edge_error_bound`, lane by lane, with the largest `|r|`
            // bounded by the sheared sizes instead: `|r[kx]| <= |x| + |r[kz]|` (the
            // shear's factor is at most 1), so `m <= (max |r[kz]| + T) (1 + 2^-23)`,
            // `T` the largest `|x| + |y|`; taken as `(1 + 2^-20)` for the sums'
            // rounding. A bound at least the scalar one: a lane decided here is decided
            // there, with the same `f32` functions (the same answer, bit for bit); a
            // lane whose signs it leaves in doubt (and that two decided signs do not
            // rule out) sends the batch one by one, to the scalar exact test.
            let abs = |x: __m256| _mm256_andnot_ps(_mm256_set1_ps(-0.0), x);
            let size = |x: __m256, y: __m256| _mm256_add_ps(abs(x), abs(y));
            let raw = _mm256_max_ps(_mm256_max_ps(size(ax, ay), size(bx, by)), size(cx, cy));
            let far = _mm256_max_ps(_mm256_max_ps(abs(a[kz]), abs(b[kz])), abs(c[kz]));
            let m = _mm256_mul_ps(_mm256_add_ps(far, raw), _mm256_set1_ps(1.0 + 1.0 / (1u32 << 20) as f32));
            let tiny = _mm256_set1_ps(f32::from_bits(4));
            let e = _mm256_add_ps(_mm256_mul_ps(m, _mm256_set1_ps(1.0 / (1u32 << 21) as f32)), tiny);
            let big = _mm256_add_ps(raw, e);
            let inner =
                _mm256_add_ps(_mm256_add_ps(e, e), _mm256_mul_ps(big, _mm256_set1_ps(1.0 / (1u32 << 22) as f32)));
            let bound = _mm256_mul_ps(_mm256_mul_ps(big, inner), _mm256_set1_ps(1.0 + 1.0 / (1u32 << 16) as f32));
            let bound = _mm256_add_ps(bound, tiny);
            let doubt = lanes(any3::<_CMP_NGT_UQ>(abs(u), abs(v), abs(w), bound), used);
            if doubt != 0 {
                // Rare: the lanes that two decided signs rule out stay misses.
                let pos = any3::<_CMP_GT_OQ>(u, v, w, bound);
                let neg = any3::<_CMP_LT_OQ>(u, v, w, _mm256_sub_ps(zero, bound));
                if doubt & !lanes(_mm256_and_ps(pos, neg), used) != 0 {
                    return Accepted::OneByOne;
                }
            }
        } else if lanes(any3::<_CMP_EQ_OQ>(u, v, w, zero), used) != 0 {
            return Accepted::OneByOne;
        }
        let mixed = _mm256_and_ps(any3::<_CMP_LT_OQ>(u, v, w, zero), any3::<_CMP_GT_OQ>(u, v, w, zero));
        let inside = used & !lanes(mixed, used);
        if inside == 0 {
            return Accepted::Miss;
        }
        let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
        let inside = inside & !lanes(_mm256_cmp_ps::<_CMP_EQ_OQ>(det, zero), used);
        if inside == 0 {
            return Accepted::Miss;
        }
        Accepted::Inside { inside, det, v, w, p }
    }
}

/// Every triangle of `refs` (1 to [`LANES`]) that the ray crosses within
/// `[tmin, tmax]`, with the edge ownership of `Shear::intersect_owned`: `found(index
/// in the batch, t, u, v, enters)` for each, in batch order. False where the batch must
/// go one by one (an edge function of exactly zero, whose ownership the scalar test
/// decides; an index out of range): then nothing was reported. `enters` is the sign of
/// `d . n` from the plane distance's own sum (`crossings::arrives_on_front`'s bits).
///
/// With `EXACT`, the exact test's filter (`Shear::intersect_owned_exact`): a lane whose
/// signs its bound leaves in doubt sends the batch one by one, and each crossing's
/// distance is correctly rounded (`plane_distance_rounded`), as that test's.
///
/// # Safety
/// The processor must have AVX2.
#[inline(always)]
pub(crate) unsafe fn crossings8<const EXACT: bool>(
    shear: &Shear,
    triangles: &[f32],
    refs: &[u32],
    tmin: f32,
    tmax: f32,
    mut found: impl FnMut(usize, f32, f32, f32, bool),
) -> bool {
    // SAFETY: the caller's.
    let (inside, det, v, w, p) = match unsafe { accepted8::<EXACT>(shear, triangles, refs) } {
        Accepted::OneByOne => return false,
        Accepted::Miss => return true,
        Accepted::Inside { inside, det, v, w, p } => (inside, det, v, w, p),
    };
    // SAFETY: AVX2 is the caller's; each pointer has nine floats to read.
    unsafe {
        let (o, d) = (wide(shear.origin()), wide(shear.direction()));
        let lane_of = |x: __m256, lane: usize| -> f32 { std::mem::transmute::<__m256, [f32; LANES]>(x)[lane] };
        let mut left = inside;
        while left != 0 {
            let lane = left.trailing_zeros() as usize;
            left &= left - 1;
            let (t, enters) = if EXACT {
                let (t, enters) = plane_distance_rounded_facing(shear, o, d, p[lane]);
                let Some(t) = t else { continue };
                (t, enters)
            } else {
                plane_distance_facing(o, d, p[lane])
            };
            if t >= tmin && t <= tmax {
                let det = lane_of(det, lane);
                found(lane, t, lane_of(v, lane) / det, lane_of(w, lane) / det, enters);
            }
        }
    }
    true
}

/// `(x, y, z, 0)` in `f64` lanes.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn wide(v: [f32; 3]) -> __m256d {
    // SAFETY: the caller's.
    unsafe { _mm256_setr_pd(v[0] as f64, v[1] as f64, v[2] as f64, 0.0) }
}

/// `watertight::plane_distance` with the three axes in the lanes of `f64` vectors: the
/// same operations in the same order, so the same bits, in about a third of the
/// instructions. `o` and `d` come from [`wide`]; `tri` points at nine floats.
///
/// # Safety
/// AVX2 must be available (where this is inlined), and `tri` readable for nine floats.
#[inline(always)]
unsafe fn plane_distance(o: __m256d, d: __m256d, tri: *const f32) -> f32 {
    // SAFETY: the caller's.
    unsafe { plane_distance_facing(o, d, tri).0 }
}

/// [`plane_distance`] and whether `d . n < 0` (the ray arrives on the triangle's
/// front), from the same sums.
///
/// # Safety
/// As [`plane_distance`].
#[inline(always)]
unsafe fn plane_distance_facing(o: __m256d, d: __m256d, tri: *const f32) -> (f32, bool) {
    // SAFETY: the caller's.
    unsafe {
        let (a, terms) = plane_terms(tri);
        let (num, den) = dot_pair(_mm256_sub_pd(a, o), d, _mm256_sub_pd(terms.0, terms.1));
        let t = (num / den) as f32;
        (if t.abs() < f32::INFINITY { t } else { f32::NAN }, den < 0.0)
    }
}

/// `watertight::plane_distance_rounded` with the axes in `f64` lanes, and whether the
/// ray arrives on the triangle's front ([`plane_distance_facing`]'s sums, with the
/// error bound's beside them): the same correctly rounded distance (the bound decides
/// where the `f64` quotient rounds to one `f32`; elsewhere exact arithmetic does).
///
/// # Safety
/// As [`plane_distance`].
#[inline(always)]
unsafe fn plane_distance_rounded_facing(shear: &Shear, o: __m256d, d: __m256d, tri: *const f32) -> (Option<f32>, bool) {
    // SAFETY: the caller's.
    unsafe {
        let (a, (p, q)) = plane_terms(tri);
        let ao = _mm256_sub_pd(a, o);
        let (num, den) = dot_pair(ao, d, _mm256_sub_pd(p, q));
        let abs = |v: __m256d| _mm256_andnot_pd(_mm256_set1_pd(-0.0), v);
        let (spread_num, spread_den) = dot_pair(abs(ao), abs(d), _mm256_add_pd(abs(p), abs(q)));
        let t = rounded_if_certain(num, den, spread_num, spread_den).or_else(|| {
            crate::exact::distance(shear.origin(), shear.direction(), std::slice::from_raw_parts(tri, TRIANGLE_FLOATS))
        });
        (t, den < 0.0)
    }
}

/// Triangle `tri`'s first vertex and the two terms of its normal's components,
/// `e1.yzx * e2.zxy` and `e1.zxy * e2.yzx` (the normal is their difference, the
/// scalar cross product lane by lane), in `f64` lanes (lane 3 junk).
///
/// # Safety
/// As [`plane_distance`].
#[inline(always)]
unsafe fn plane_terms(tri: *const f32) -> (__m256d, (__m256d, __m256d)) {
    // SAFETY: the caller's: nine floats from `tri` (the loads read floats 0-3, 3-6
    // and 5-8).
    unsafe {
        let a = _mm256_cvtps_pd(_mm_loadu_ps(tri));
        let b = _mm256_cvtps_pd(_mm_loadu_ps(tri.add(3)));
        // (b.z, c.x, c.y, c.z) turned to (c.x, c.y, c.z, c.z).
        let c = _mm256_cvtps_pd(_mm_permute_ps::<0b11_11_10_01>(_mm_loadu_ps(tri.add(5))));
        let (e1, e2) = (_mm256_sub_pd(b, a), _mm256_sub_pd(c, a));
        let yzx = |v: __m256d| _mm256_permute4x64_pd::<0b11_00_10_01>(v);
        let zxy = |v: __m256d| _mm256_permute4x64_pd::<0b11_01_00_10>(v);
        (a, (_mm256_mul_pd(yzx(e1), zxy(e2)), _mm256_mul_pd(zxy(e1), yzx(e2))))
    }
}

/// `(x . n, y . n)` over lanes 0-2, each summed `(x + y) + z` as the scalar sums are.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn dot_pair(x: __m256d, y: __m256d, n: __m256d) -> (f64, f64) {
    // SAFETY: the caller's.
    unsafe {
        // Lane 3 holds junk: set to -0.0, which adds nothing below (x + -0.0 is x,
        // the sign of a zero included).
        let clear = |v: __m256d| _mm256_blend_pd::<0b1000>(v, _mm256_set1_pd(-0.0));
        let (p, q) = (clear(_mm256_mul_pd(x, n)), clear(_mm256_mul_pd(y, n)));
        // (p.x + p.y, q.x + q.y, p.z + -0, q.z + -0), then (x + y) + z for both.
        let h = _mm256_hadd_pd(p, q);
        let sums = _mm_add_pd(_mm256_castpd256_pd128(h), _mm256_extractf128_pd::<1>(h));
        (_mm_cvtsd_f64(sums), _mm_cvtsd_f64(_mm_unpackhi_pd(sums, sums)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What testing `refs` one after another keeps: `(index, t, u, v)`.
    fn one_by_one(
        shear: &Shear,
        tris: &[f32],
        refs: &[u32],
        any: bool,
        tmin: f32,
        tmax: f32,
    ) -> Option<(usize, f32, f32, f32)> {
        let mut best = None;
        let mut t_best = tmax;
        for (i, &r) in refs.iter().enumerate() {
            if let Some((t, u, v)) = shear.intersect(&tris[r as usize * 9..][..9], tmin, t_best) {
                best = Some((i, t, u, v));
                t_best = t;
                if any {
                    break;
                }
            }
        }
        best
    }

    /// A little xorshift, enough for test data.
    fn rng(seed: &mut u64) -> f32 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        (*seed >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn eight_at_once_keeps_what_one_after_another_keeps() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 here: the batch test never runs on this processor");
            return;
        }
        // Triangles on an integer grid in the plane z = 2 (two a square, sharing
        // edges and vertices), copies of some of them (exact ties), and random ones.
        let mut tris: Vec<f32> = Vec::new();
        for y in 0..4 {
            for x in 0..4 {
                let (x, y) = (x as f32, y as f32);
                tris.extend([x, y, 2.0, x + 1.0, y, 2.0, x + 1.0, y + 1.0, 2.0]);
                tris.extend([x, y, 2.0, x + 1.0, y + 1.0, 2.0, x, y + 1.0, 2.0]);
            }
        }
        let copies = tris[..9 * 8].to_vec();
        tris.extend(copies);
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..64 {
            for _ in 0..9 {
                tris.push(rng(&mut seed) * 4.0);
            }
        }
        let count = tris.len() / 9;
        let (mut batches, mut hits, mut ties, mut fallbacks) = (0, 0, 0, 0);
        for ray in 0..3000 {
            // Rays through grid vertices and edges (edge functions of exactly zero)
            // and through random points, in random directions.
            let target = if ray % 3 == 0 {
                [(ray % 5) as f32, (ray / 5 % 5) as f32, 2.0]
            } else if ray % 3 == 1 {
                [(ray % 5) as f32 + 0.5, (ray / 5 % 5) as f32, 2.0]
            } else {
                [rng(&mut seed) * 4.0, rng(&mut seed) * 4.0, 2.0 + rng(&mut seed)]
            };
            let d = [rng(&mut seed) - 0.5, rng(&mut seed) - 0.5, if ray % 2 == 0 { 1.0 } else { -1.0 }];
            let o = [target[0] - 3.0 * d[0], target[1] - 3.0 * d[1], target[2] - 3.0 * d[2]];
            let shear = Shear::new(o, d);
            for _ in 0..4 {
                let n = 1 + (rng(&mut seed) * LANES as f32) as usize;
                let mut refs: Vec<u32> =
                    (0..n).map(|_| (rng(&mut seed) * count as f32) as u32 % count as u32).collect();
                if ray % 2 == 0 {
                    refs[n / 2] = refs[0]; // a triangle twice: an exact tie
                }
                let tmax = if ray % 7 == 0 { 2.5 } else { f32::INFINITY };
                for any in [false, true] {
                    let expect = one_by_one(&shear, &tris, &refs, any, 0.0, tmax);
                    // SAFETY: the processor has AVX2 (checked above).
                    let got = unsafe {
                        if any {
                            hit8::<true, false>(&shear, &tris, &refs, 0.0, tmax)
                        } else {
                            hit8::<false, false>(&shear, &tris, &refs, 0.0, tmax)
                        }
                    };
                    batches += 1;
                    match got {
                        Batch::Miss => assert_eq!(expect, None, "ray {ray}, refs {refs:?}"),
                        Batch::Hit(i, t, u, v) => {
                            assert_eq!(Some((i, t, u, v)), expect, "ray {ray}, refs {refs:?}, any {any}");
                            hits += 1;
                            ties += refs
                                .iter()
                                .enumerate()
                                .filter(|&(j, _)| {
                                    j != i
                                        && shear
                                            .intersect(&tris[refs[j] as usize * 9..][..9], 0.0, tmax)
                                            .is_some_and(|h| h.0 == t)
                                })
                                .count()
                                .min(1);
                        }
                        Batch::OneByOne => fallbacks += 1,
                    }
                }
            }
        }
        // The cases that matter were met: hits, exact ties, zero edge functions.
        assert!(
            hits > 1000 && ties > 100 && fallbacks > 100,
            "{batches} batches: {hits} hits, {ties} ties, {fallbacks} one by one"
        );
        // An index past the triangles is left to the one-by-one path.
        // SAFETY: the processor has AVX2.
        let past = unsafe {
            hit8::<false, false>(&Shear::new([0.0; 3], [0.0, 0.0, 1.0]), &tris, &[0, count as u32], 0.0, 1.0)
        };
        assert!(matches!(past, Batch::OneByOne));
        // So is one in a full batch of eight (checked all at once), wherever it is.
        for at in 0..LANES {
            let mut refs = [0, 1, 2, 3, 4, 5, 6, 7];
            refs[at] = if at % 2 == 0 { count as u32 } else { u32::MAX };
            let shear = Shear::new([0.5, 0.5, 0.0], [0.0, 0.0, 1.0]);
            // SAFETY: the processor has AVX2.
            let past = unsafe { hit8::<false, false>(&shear, &tris, &refs, 0.0, 10.0) };
            assert!(matches!(past, Batch::OneByOne), "index past the end in lane {at}");
        }
    }

    /// The vector plane distance gives the scalar one's bits (`watertight::
    /// plane_distance`, the reference): random triangles, slivers and caps, origins on
    /// their planes (zero numerators of either sign), rays parallel to them.
    #[test]
    fn the_vector_plane_distances_are_the_scalar_ones() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 here: the vector plane distance never runs on this processor");
            return;
        }
        let mut seed = 0x005E_ED0F_u64;
        let mut checked = 0;
        for i in 0..200_000 {
            let mut r = || rng(&mut seed) * 8.0 - 4.0;
            let a = [r(), r(), r()];
            let mut tri = [a[0], a[1], a[2], r(), r(), r(), r(), r(), r()];
            match i % 4 {
                // A sliver: the third vertex next to the first edge's middle.
                1 => (0..3).for_each(|k| tri[6 + k] = 0.5 * (tri[k] + tri[3 + k]) + 1e-4 * r()),
                // Axis-aligned, in the plane z = 1.
                2 => [2, 5, 8].iter().for_each(|&k| tri[k] = 1.0),
                _ => {}
            }
            let o = if i % 5 == 0 { [tri[0], tri[1], tri[2]] } else { [r(), r(), r()] };
            let mut d = [r(), r(), r()];
            if i % 7 == 0 {
                d[2] = 0.0; // parallel to the z = 1 triangles
            }
            let want = crate::cpu::watertight::plane_distance(o, d, &tri);
            // SAFETY: the processor has AVX2; `tri` holds nine floats.
            let got = unsafe { plane_distance(wide(o), wide(d), tri.as_ptr()) };
            assert!(
                want.to_bits() == got.to_bits() || (want.is_nan() && got.is_nan()),
                "{tri:?} {o:?} {d:?}: {want} {got}"
            );
            checked += want.is_finite() as u32;
            // The correctly rounded distance (the exact test's), and the side.
            let shear = Shear::new(o, d);
            let want = (
                crate::cpu::watertight::plane_distance_rounded(o, d, &tri),
                crate::cpu::crossings::arrives_on_front(d, &tri),
            );
            // SAFETY: as above.
            let got = unsafe { plane_distance_rounded_facing(&shear, wide(o), wide(d), tri.as_ptr()) };
            assert_eq!(want, got, "rounded: {tri:?} {o:?} {d:?}");
        }
        assert!(checked > 150_000);
    }
}
