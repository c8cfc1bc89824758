//! `Tracer::begin` on eight rays at once (AVX2), for the lanes: the clips to the root
//! cube and the mesh box, the interval tests, and the point location of the first
//! leaf (the grid's entry, then the descent, every ray a lane), with the scalar
//! begin's operations in its order, so each ray starts in the same leaf with the same
//! interval. What the eight-lane form leaves to the scalar begin: rays with a zero
//! direction component or that are not traceable (its slab rules and refusals), rays
//! under the exact exit rule (`tables::exit_rule`), rays from origins far outside the
//! root (re-originated), rays
//! entering the root through the cube map (none on the standard sets), and every ray
//! of a tracer without a locate grid.
//!
//! The scalar begin was 281 instructions a walked camera ray on the bunny (callgrind),
//! a sixth of the batch's cost of such a ray (its clips alone were done eight at a
//! time before, for the rays that miss the mesh box). Begun here, the batch's bunny
//! camera rays take 697 -> 670 instructions a ray and its shadow rays 2,227 -> 2,063;
//! in time 1.02-1.03x on the bunny, 1.00-1.02x on the dragon (BENCHMARKS.md).

use std::arch::x86_64::*;

use octrace_format::layout::INTERNAL_BIT;

use super::avx2::{transpose, LANES};
use crate::cpu::tables::{RuleScale, RULE_MAX_PRODUCT, RULE_MIN_EXPONENT, RULE_SPREAD};
use crate::cpu::tracer::{Tracer, BOX_T_SLACK};
use crate::ray::Ray;

/// What [`begin8`] found for a block of eight rays, one lane a ray.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Begun {
    /// Rays that cannot hit (`Tracer::begin` returns `None`): answered without a
    /// walk.
    pub(crate) misses: u32,
    /// Rays begun here; the others (in neither mask) take the scalar begin.
    pub(crate) begun: u32,
    /// The first leaf's record address, level and cell (a begun ray's).
    pub(crate) address: [u32; LANES],
    pub(crate) level: [u32; LANES],
    pub(crate) cell: [[u32; LANES]; 3],
    /// Where the walk stops: the ray's `tmax`, or a little past where it leaves the
    /// mesh box.
    pub(crate) tmax: [f32; LANES],
}

/// The clip of eight rays to the box `lo..hi`, as `hw::clip_sse2` computes it for
/// one (the same divisions, selections, and maxima and minima in the same order):
/// the entry and leaving distances, and where the ray meets the box at all. For rays
/// without a zero direction component (the others are the scalar clip's).
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn clip8(o: &[__m256; 3], d: &[__m256; 3], lo: [f32; 3], hi: [f32; 3]) -> (__m256, __m256, __m256) {
    // SAFETY: the caller's.
    unsafe {
        let mut near = [_mm256_setzero_ps(); 3];
        let mut far = [_mm256_setzero_ps(); 3];
        for k in 0..3 {
            let ta = _mm256_div_ps(_mm256_sub_ps(_mm256_set1_ps(lo[k]), o[k]), d[k]);
            let tb = _mm256_div_ps(_mm256_sub_ps(_mm256_set1_ps(hi[k]), o[k]), d[k]);
            // `if ta < tb { (ta, tb) } else { (tb, ta) }`, lane by lane.
            let m = _mm256_cmp_ps::<_CMP_LT_OQ>(ta, tb);
            near[k] = _mm256_blendv_ps(tb, ta, m);
            far[k] = _mm256_blendv_ps(ta, tb, m);
        }
        // `clip_sse2`'s reductions over lanes (x, y, z, dummy): max(max(x, z),
        // max(y, -inf)), which is max(max(x, z), y); the same for the minimum.
        let t0 = _mm256_max_ps(_mm256_max_ps(near[0], near[2]), near[1]);
        let t1 = _mm256_min_ps(_mm256_min_ps(far[0], far[2]), far[1]);
        (t0, t1, _mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1))
    }
}

/// `Tracer::grid_coords` of eight points on one axis: `((p - lo) * scale)` in `f64`,
/// clamped to `0..=last` (NaN to 0: `maxpd` answers its second operand), truncated.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn grid_axis(p: __m256, lo: f32, scale: f64, last: f64) -> __m256i {
    // SAFETY: the caller's.
    unsafe {
        let (lo, scale, last) = (_mm256_set1_pd(lo as f64), _mm256_set1_pd(scale), _mm256_set1_pd(last));
        let high = grid_half(_mm256_extractf128_ps::<1>(p), lo, scale, last);
        _mm256_set_m128i(high, grid_half(_mm256_castps256_ps128(p), lo, scale, last))
    }
}

/// [`grid_axis`] on four of the points.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn grid_half(p: __m128, lo: __m256d, scale: __m256d, last: __m256d) -> __m128i {
    // SAFETY: the caller's.
    unsafe {
        let x = _mm256_mul_pd(_mm256_sub_pd(_mm256_cvtps_pd(p), lo), scale);
        _mm256_cvttpd_epi32(_mm256_min_pd(_mm256_max_pd(x, _mm256_setzero_pd()), last))
    }
}

/// Where `|x|` is finite (not NaN, not infinite), as a mask.
///
/// # Safety
/// AVX must be available (where this is inlined).
#[inline(always)]
unsafe fn finite(x: __m256) -> __m256 {
    // SAFETY: the caller's.
    unsafe {
        let magnitude = _mm256_andnot_ps(_mm256_set1_ps(-0.0), x);
        _mm256_cmp_ps::<_CMP_LT_OQ>(magnitude, _mm256_set1_ps(f32::INFINITY))
    }
}

/// `(q >> shift) & 1`, lane by lane.
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
unsafe fn bit_at(q: __m256i, shift: __m256i) -> __m256i {
    // SAFETY: the caller's.
    unsafe { _mm256_and_si256(_mm256_srlv_epi32(q, shift), _mm256_set1_epi32(1)) }
}

/// `Tracer::begin` for eight rays, as far as it goes without the scalar form (the
/// module's doc says which rays it leaves): which rays miss, and for those begun,
/// their first leaf and stopping distance, each what the scalar begin gives.
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
pub(crate) unsafe fn begin8(t: &Tracer<'_>, rays: &[Ray; LANES]) -> Begun {
    let mut out = Begun::default();
    let (root_lo, root_hi) = t.root_box();
    let (box_lo, box_hi) = t.walked_box();
    let view = t.view();
    // SAFETY: AVX2 is the caller's; a `Ray` is eight `f32` (`repr(C)`, 32 bytes),
    // which the two transposes read. Every gather is masked to lanes whose index is
    // inside its array (the grid's by construction, the nodes' checked).
    unsafe {
        let p: [*const f32; LANES] = std::array::from_fn(|i| std::ptr::from_ref(&rays[i]).cast::<f32>());
        let [ox, oy, oz, tmin] = transpose(&p, 0);
        let [dx, dy, dz, tmax] = transpose(&p, 4);
        let (o, d) = ([ox, oy, oz], [dx, dy, dz]);
        // Rays for the vector clips: traceable (`Ray::is_traceable`: finite, an
        // ordered interval) with no zero direction component.
        let (zero, sign) = (_mm256_setzero_ps(), _mm256_set1_ps(-0.0));
        // Origins far outside the root are re-originated by the scalar begin.
        let mut eligible = _mm256_cmp_ps::<_CMP_LE_OQ>(tmin, tmax);
        let (near_lo, near_hi) = (t.frame.near_lo, t.frame.near_hi);
        for k in 0..3 {
            let moving = _mm256_cmp_ps::<_CMP_NEQ_OQ>(d[k], zero);
            let near = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_set1_ps(near_lo[k]), o[k]),
                _mm256_cmp_ps::<_CMP_LE_OQ>(o[k], _mm256_set1_ps(near_hi[k])),
            );
            eligible = _mm256_and_ps(eligible, _mm256_and_ps(near, _mm256_and_ps(finite(d[k]), moving)));
        }
        let eligible = _mm256_movemask_ps(eligible) as u32 & table_rule(&o, &d, t.frame.rule_scale);
        if eligible == 0 {
            return out;
        }
        // The clips and interval tests of `begin`. Where a value may be NaN (the
        // stopping distance of a ray leaving the box at -inf: -inf + inf), `maxps` and
        // `minps` take it first: they answer their second operand when either is NaN,
        // as `f32::max` and `min` answer the other one; the second operands (the ray's
        // interval, `t_start`) are never NaN in these lanes.
        let (t_enter, t_leave, in_root) = clip8(&o, &d, root_lo, root_hi);
        let (box_enter, box_leave, in_box) = clip8(&o, &d, box_lo, box_hi);
        let t_start = _mm256_max_ps(t_enter, tmin);
        let slack = _mm256_mul_ps(_mm256_andnot_ps(sign, box_leave), _mm256_set1_ps(BOX_T_SLACK));
        let box_stop = _mm256_add_ps(box_leave, slack);
        let t_stop = _mm256_min_ps(box_stop, tmax);
        // Not against tmax (`begin_near` says why).
        let hits = _mm256_andnot_ps(
            _mm256_or_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(t_start, t_leave),
                _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_max_ps(box_enter, t_start), box_stop),
            ),
            _mm256_and_ps(in_root, in_box),
        );
        let hits = _mm256_movemask_ps(hits) as u32;
        // A ray that meets the mesh box but not, after rounding, the root cube (it
        // grazes the root's edge where the box reaches the root's faces) is left to
        // the scalar begin, which starts it where it enters the box.
        let grazes = _mm256_movemask_ps(_mm256_andnot_ps(in_root, in_box)) as u32;
        out.misses = eligible & !hits & !grazes;
        // Where the walk begins: at the mesh box when it is entered after the walk's
        // start; through the cube map when the ray enters the root after its `tmin`
        // (left to the scalar begin); else at the walk's start.
        let at_box = _mm256_cmp_ps::<_CMP_GT_OQ>(box_enter, t_start);
        let cube_map = _mm256_andnot_ps(at_box, _mm256_cmp_ps::<_CMP_GT_OQ>(t_enter, tmin));
        let Some(grid) = t.grid else { return out };
        let nodes = view.nodes;
        if nodes.len() > i32::MAX as usize {
            return out;
        }
        out.begun = eligible & hits & !(_mm256_movemask_ps(cube_map) as u32);
        if out.begun == 0 {
            return out;
        }
        let t_at = _mm256_blendv_ps(t_start, box_enter, at_box);
        // `point_at`: o + t * d, no fused multiply-add.
        let (last, scale, max_depth) = (t.grid_last(), t.frame.grid_scale, t.frame.max_depth);
        let mut q = [_mm256_setzero_si256(); 3];
        for k in 0..3 {
            q[k] = grid_axis(_mm256_add_ps(o[k], _mm256_mul_ps(t_at, d[k])), root_lo[k], scale, last);
        }
        // The grid's cell (`LocateGrid::entry`), its word and level.
        let begun = _mm256_castps_si256(mask8(out.begun));
        let shift = _mm_cvtsi32_si128(max_depth.saturating_sub(grid.level()).min(31) as i32);
        let res = _mm256_set1_epi32(1 << grid.level());
        let mask = _mm256_set1_epi32((1 << grid.level()) - 1);
        let mut cell = [_mm256_setzero_si256(); 3];
        for k in 0..3 {
            cell[k] = _mm256_and_si256(_mm256_srl_epi32(q[k], shift), mask);
        }
        let index = _mm256_add_epi32(
            _mm256_mullo_epi32(_mm256_add_epi32(_mm256_mullo_epi32(cell[2], res), cell[1]), res),
            cell[0],
        );
        let zi = _mm256_setzero_si256();
        let mut word = _mm256_mask_i32gather_epi32::<4>(zi, grid.words().as_ptr().cast(), index, begun);
        let levels = _mm256_mask_i32gather_epi32::<1>(zi, grid.padded_levels().as_ptr().cast(), index, begun);
        let mut level = _mm256_and_si256(levels, _mm256_set1_epi32(0xFF));
        // The descent (`descend_to`) to the leaf, every lane at once: at most
        // `max_depth` rounds, a lane leaving the loop at a leaf or the depth.
        let (one, depth) = (_mm256_set1_epi32(1), _mm256_set1_epi32(max_depth as i32));
        let internal_bit = _mm256_set1_epi32(INTERNAL_BIT as i32);
        let node_count = _mm256_set1_epi32(nodes.len() as i32);
        loop {
            let internal = _mm256_cmpeq_epi32(_mm256_and_si256(word, internal_bit), internal_bit);
            let down = _mm256_and_si256(_mm256_and_si256(internal, _mm256_cmpgt_epi32(depth, level)), begun);
            if _mm256_testz_si256(down, down) != 0 {
                break;
            }
            let shift = _mm256_sub_epi32(_mm256_sub_epi32(depth, level), one);
            let child = _mm256_or_si256(
                _mm256_or_si256(bit_at(q[0], shift), _mm256_slli_epi32::<1>(bit_at(q[1], shift))),
                _mm256_slli_epi32::<2>(bit_at(q[2], shift)),
            );
            // `nodes.get(8 * i + child)`, zero past the array: an index below 2^28
            // (so `8 * i + 7` fits the lane) and inside it.
            let i = _mm256_andnot_si256(internal_bit, word);
            let small = _mm256_cmpeq_epi32(_mm256_srli_epi32::<28>(i), zi);
            let at = _mm256_add_epi32(_mm256_slli_epi32::<3>(i), child);
            let inside = _mm256_and_si256(small, _mm256_cmpgt_epi32(node_count, at));
            let next = _mm256_mask_i32gather_epi32::<4>(zi, nodes.as_ptr().cast(), at, _mm256_and_si256(down, inside));
            word = _mm256_blendv_epi8(word, next, down);
            level = _mm256_sub_epi32(level, down); // a mask is -1: one level down
        }
        _mm256_storeu_si256(out.address.as_mut_ptr().cast(), word);
        _mm256_storeu_si256(out.level.as_mut_ptr().cast(), level);
        let to_cell = _mm256_sub_epi32(depth, level);
        for k in 0..3 {
            _mm256_storeu_si256(out.cell[k].as_mut_ptr().cast(), _mm256_srlv_epi32(q[k], to_cell));
        }
        _mm256_storeu_ps(out.tmax.as_mut_ptr(), t_stop);
    }
    out
}

/// The lanes whose ray, if it has no zero direction component, follows the exit
/// table (`tables::exit_rule`, from the same integer exponents): the others follow
/// the exact rule, which only the scalar step walks, and take the scalar begin.
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
unsafe fn table_rule(o: &[__m256; 3], d: &[__m256; 3], scale: RuleScale) -> u32 {
    // SAFETY: the caller's.
    unsafe {
        let exponent = |x: __m256| {
            let biased = _mm256_and_si256(_mm256_srli_epi32::<23>(_mm256_castps_si256(x)), _mm256_set1_epi32(0xFF));
            _mm256_sub_epi32(biased, _mm256_set1_epi32(127))
        };
        let e = [exponent(d[0]), exponent(d[1]), exponent(d[2])];
        let e_min = _mm256_min_epi32(_mm256_min_epi32(e[0], e[1]), e[2]);
        let e_max = _mm256_max_epi32(_mm256_max_epi32(e[0], e[1]), e[2]);
        let e_origin = _mm256_max_epi32(_mm256_max_epi32(exponent(o[0]), exponent(o[1])), exponent(o[2]));
        let reach = _mm256_max_epi32(e_origin, _mm256_set1_epi32(scale.reach));
        // e_min >= MIN, 2 e_min + root >= e_max - SPREAD, e_max + reach <= MAX_PRODUCT.
        let small = _mm256_cmpgt_epi32(_mm256_set1_epi32(RULE_MIN_EXPONENT), e_min);
        let spread = _mm256_cmpgt_epi32(
            _mm256_sub_epi32(e_max, _mm256_set1_epi32(RULE_SPREAD)),
            _mm256_add_epi32(_mm256_add_epi32(e_min, e_min), _mm256_set1_epi32(scale.root)),
        );
        let large = _mm256_cmpgt_epi32(_mm256_add_epi32(e_max, reach), _mm256_set1_epi32(RULE_MAX_PRODUCT));
        let refused = _mm256_or_si256(_mm256_or_si256(small, spread), large);
        !(_mm256_movemask_ps(_mm256_castsi256_ps(refused)) as u32) & 0xFF
    }
}

/// The lanes of `bits` as a mask.
///
/// # Safety
/// AVX2 must be available (where this is inlined).
#[inline(always)]
pub(super) unsafe fn mask8(bits: u32) -> __m256 {
    // SAFETY: the caller's.
    unsafe {
        let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bits);
        _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bits))
    }
}
