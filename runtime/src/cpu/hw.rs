//! What the processor offers beneath the walks: whether it has x86-64-v3, cache hints,
//! the size of its largest cache, and the SSE2 clip and grid coordinates every x86-64
//! processor runs.
//! Below both the scalar walk and the SIMD steps (`simd/`), which use these and
//! nothing of each other's here.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use std::arch::x86_64::*;

/// Whether the processor has x86-64-v3's features (AVX2 and friends).
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) fn x86_64_v3() -> bool {
    use std::arch::is_x86_feature_detected as has;
    has!("avx2") && has!("bmi1") && has!("bmi2") && has!("fma") && has!("lzcnt") && has!("popcnt")
}

/// The processor's largest cache in bytes, from Linux's sysfs (the first processor's
/// `cache/index*/size`), asked once; 32 MiB where it cannot be read.
pub(crate) fn last_level_cache() -> u64 {
    static SIZE: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *SIZE.get_or_init(|| {
        let sizes = std::fs::read_dir("/sys/devices/system/cpu/cpu0/cache").into_iter().flatten().filter_map(|e| {
            let text = std::fs::read_to_string(e.ok()?.path().join("size")).ok()?;
            let text = text.trim();
            let (digits, unit) = text.split_at(text.find(|c: char| !c.is_ascii_digit()).unwrap_or(text.len()));
            let scale = match unit {
                "K" => 1 << 10,
                "M" => 1 << 20,
                "G" => 1 << 30,
                "" => 1,
                _ => return None,
            };
            digits.parse::<u64>().ok().map(|n| n * scale)
        });
        sizes.max().unwrap_or(32 << 20)
    })
}

/// Asks for the cache line of `words[at]`, if `at` is in range (a hint: no load, no
/// fault).
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
#[inline(always)]
pub(crate) fn prefetch(words: &[u32], at: u32) {
    if let Some(word) = words.get(at as usize) {
        // SAFETY: a prefetch reads nothing architecturally; the address is that of a
        // live element, and SSE (which has PREFETCHT0) is part of every x86-64
        // target this is compiled for.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(std::ptr::from_ref(word).cast::<i8>()) };
    }
}

/// `walk::clip` on three lanes for a direction with no zero component: the six
/// divisions as two, the same answer (lane 3 is a dummy slab from -inf to +inf).
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
#[inline(always)]
pub(crate) fn clip_sse2(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> Option<(f32, f32, usize)> {
    debug_assert!(!d.contains(&0.0));
    // SAFETY: SSE2 is part of every x86-64 target this is compiled for.
    unsafe {
        let o4 = _mm_setr_ps(o[0], o[1], o[2], 0.0);
        let d4 = _mm_setr_ps(d[0], d[1], d[2], 1.0);
        let ta = _mm_div_ps(_mm_sub_ps(_mm_setr_ps(lo[0], lo[1], lo[2], f32::NEG_INFINITY), o4), d4);
        let tb = _mm_div_ps(_mm_sub_ps(_mm_setr_ps(hi[0], hi[1], hi[2], f32::INFINITY), o4), d4);
        // `if ta < tb { (ta, tb) } else { (tb, ta) }`, lane by lane.
        let m = _mm_cmplt_ps(ta, tb);
        let near = _mm_or_ps(_mm_and_ps(m, ta), _mm_andnot_ps(m, tb));
        let far = _mm_or_ps(_mm_and_ps(m, tb), _mm_andnot_ps(m, ta));
        // The largest near, the first lane holding it, and the smallest far (no NaN:
        // a traceable ray's origin is finite, and no component of `d` is zero).
        let mx = _mm_max_ps(near, _mm_shuffle_ps::<0b01_00_11_10>(near, near));
        let mx = _mm_max_ps(mx, _mm_shuffle_ps::<0b10_11_00_01>(mx, mx));
        let mn = _mm_min_ps(far, _mm_shuffle_ps::<0b01_00_11_10>(far, far));
        let mn = _mm_min_ps(mn, _mm_shuffle_ps::<0b10_11_00_01>(mn, mn));
        let axis = (_mm_movemask_ps(_mm_cmpeq_ps(near, mx)) as u32 & 7).trailing_zeros() as usize & 3;
        let (t0, t1) = (_mm_cvtss_f32(mx), _mm_cvtss_f32(mn));
        (t0 <= t1).then_some((t0, t1, axis))
    }
}

/// `Tracer::grid_coords` (finest-grid coordinates of point `p`, clamped into the
/// root) in SSE2's two-lane `f64`: the same operations in the same order, so the
/// same cells. `scale` is the frame's `grid_scale`, `last` the last cell's index. A
/// NaN coordinate clamps to 0 as in the scalar form: `maxpd(x, 0)` answers its second
/// operand when either is NaN. About 60 fewer instructions a walk than the scalar
/// form, whose `f64::max` and `min` each take a NaN check.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
#[inline(always)]
pub(crate) fn grid_coords_sse2(p: [f32; 3], lo: [f32; 3], scale: f64, last: f64) -> [u32; 3] {
    // SAFETY: SSE2 is part of every x86-64 target this is compiled for.
    unsafe {
        let (p4, lo4) = (_mm_setr_ps(p[0], p[1], p[2], 0.0), _mm_setr_ps(lo[0], lo[1], lo[2], 0.0));
        let (scale, zero, last) = (_mm_set1_pd(scale), _mm_setzero_pd(), _mm_set1_pd(last));
        // `((p - lo) * scale).max(0.0).min(last)`, then truncated (in 0..=last, so
        // the truncation is `as u32`'s).
        let q = |p: __m128, lo: __m128| {
            let x = _mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(p), _mm_cvtps_pd(lo)), scale);
            _mm_cvttpd_epi32(_mm_min_pd(_mm_max_pd(x, zero), last))
        };
        let xy = q(p4, lo4);
        let z = q(_mm_movehl_ps(p4, p4), _mm_movehl_ps(lo4, lo4));
        [_mm_cvtsi128_si32(xy) as u32, _mm_cvtsi128_si32(_mm_srli_si128::<4>(xy)) as u32, _mm_cvtsi128_si32(z) as u32]
    }
}
