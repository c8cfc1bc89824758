//! The ray–triangle test as exact arithmetic decides it: the fallback of the
//! floating-point tests wherever their error bound cannot decide.
//!
//! The watertight test (`cpu::watertight`) shears the ray onto `+z` and takes the
//! signs of the triangle's three edge functions in the sheared plane. Multiplied by
//! `d[kz]^2`, which is positive, each function is a polynomial in the `f32` inputs:
//! with `r = p - o` a vertex relative to the origin, its sheared coordinates times
//! `d[kz]` are `X = r[kx] d[kz] - d[kx] r[kz]` and `Y = r[ky] d[kz] - d[ky] r[kz]`, and
//! the function of the edge from `p` to `q` is `X_q Y_p - Y_q X_p`. Here each is
//! evaluated on integers ([`big::Big`]: every `f32` is an integer times `2^-149`), so
//! its sign is the true one; so are the edge rule's coordinate differences
//! ([`crate::cpu::watertight::Shear::intersect_owned`]), and the distance
//! `t = n.(a - o) / n.d` is rounded to the nearest `f32` (ties to even) from the exact
//! quotient.

pub(crate) mod big;
pub(crate) mod distance;

use big::Big;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Calls of the integer stage ([`hit`], [`distance`], [`compare_distances`]) in this
/// process.
static INTEGER_STAGE: AtomicU64 = AtomicU64::new(0);

/// How many times, in this process, a ray–triangle question under
/// [`TriangleTest::Exact`](crate::TriangleTest::Exact) was one the floating-point
/// filter could not decide, so that exact integer arithmetic answered it (whether the
/// ray meets the triangle, its correctly rounded distance, or which of two distances is
/// nearer): a diagnostic of how often exactness costs more than the filter, which
/// `octrace bench` reports per ray set. The count only grows; read it before and after a
/// batch.
///
/// # Example
/// ```
/// let before = octrace_runtime::exact_stage_runs();
/// // ... trace ...
/// assert!(octrace_runtime::exact_stage_runs() >= before);
/// ```
pub fn exact_stage_runs() -> u64 {
    INTEGER_STAGE.load(Relaxed)
}

/// The exact form of [`crate::cpu::watertight::Shear`]'s test: `(t, u, v)` of the
/// triangle `t` (nine floats) for the ray `o + t d` sheared along the axes `k`, when
/// the three edge functions agree in sign (zeros allowed; with `owned`, a zero function
/// only where the triangle owns that edge) and the correctly rounded distance lies in
/// `[tmin, tmax]`. `u` and `v` weigh the second and third vertices (rounded from their
/// exact quotients).
#[cold]
#[inline(never)]
pub(crate) fn hit(
    o: [f32; 3],
    d: [f32; 3],
    k: [usize; 3],
    t: &[f32],
    tmin: f32,
    tmax: f32,
    owned: bool,
) -> Option<(f32, f32, f32)> {
    INTEGER_STAGE.fetch_add(1, Relaxed);
    // A non-finite coordinate (a hostile file's triangle) meets nothing, as in the
    // floating-point tests, whose comparisons with NaN fail.
    if !all_finite(&[&o, &d, t]) {
        return None;
    }
    let [kx, ky, kz] = k;
    let bo = o.map(Big::of);
    let bd = d.map(Big::of);
    let [va, vb, vc] = vertices(t);
    let rel = |v: &[Big; 3]| [0, 1, 2].map(|c| v[c].sub(&bo[c]));
    let (ra, rb, rc) = (rel(&va), rel(&vb), rel(&vc));
    // Sheared coordinates, times d[kz].
    let sheared =
        |r: &[Big; 3]| (r[kx].mul(&bd[kz]).sub(&bd[kx].mul(&r[kz])), r[ky].mul(&bd[kz]).sub(&bd[ky].mul(&r[kz])));
    let (a, b, c) = (sheared(&ra), sheared(&rb), sheared(&rc));
    let edge = |p: &(Big, Big), q: &(Big, Big)| q.0.mul(&p.1).sub(&q.1.mul(&p.0));
    // The functions of the edges B->C, C->A, A->B, as in the floating-point test.
    let (u, v, w) = (edge(&b, &c), edge(&c, &a), edge(&a, &b));
    let signs = [u.signum(), v.signum(), w.signum()];
    if signs.contains(&-1) && signs.contains(&1) {
        return None;
    }
    let det = u.add(&v).add(&w);
    if det.is_zero() {
        return None; // the ray lies in the triangle's plane
    }
    if owned {
        let flip = det.is_negative() != bd[kz].is_negative();
        let owns = |f: &Big, from: &(Big, Big), to: &(Big, Big)| {
            if !f.is_zero() {
                return true;
            }
            let ex = to.0.sub(&from.0).negate_if(flip).signum();
            let ey = to.1.sub(&from.1).negate_if(flip).signum();
            ey > 0 || (ey == 0 && ex > 0)
        };
        if !(owns(&u, &b, &c) && owns(&v, &c, &a) && owns(&w, &a, &b)) {
            return None;
        }
    }
    let (num, den) = distance_terms(&bo, &bd, [&va, &vb, &vc]);
    let dist = rounded_quotient(&num, &den)?;
    (dist >= tmin && dist <= tmax).then(|| (dist, v.ratio(&det) as f32, w.ratio(&det) as f32))
}

/// The exact distance `n.(a - o) / n.d` from the origin to the plane of the triangle
/// `v`, as its numerator and denominator.
fn distance_terms(o: &[Big; 3], d: &[Big; 3], v: [&[Big; 3]; 3]) -> (Big, Big) {
    let e1 = [0, 1, 2].map(|i| v[1][i].sub(&v[0][i]));
    let e2 = [0, 1, 2].map(|i| v[2][i].sub(&v[0][i]));
    let n = [
        e1[1].mul(&e2[2]).sub(&e1[2].mul(&e2[1])),
        e1[2].mul(&e2[0]).sub(&e1[0].mul(&e2[2])),
        e1[0].mul(&e2[1]).sub(&e1[1].mul(&e2[0])),
    ];
    let dot = |p: &[Big; 3]| n[0].mul(&p[0]).add(&n[1].mul(&p[1])).add(&n[2].mul(&p[2]));
    let ao = [0, 1, 2].map(|i| v[0][i].sub(&o[i]));
    (dot(&ao), dot(d))
}

/// Whether every value of `parts` is finite (what [`Big::of`] takes).
fn all_finite(parts: &[&[f32]]) -> bool {
    parts.iter().all(|p| p.iter().all(|x| x.is_finite()))
}

fn vertices(t: &[f32]) -> [[Big; 3]; 3] {
    [0, 1, 2].map(|i| [0, 1, 2].map(|c| Big::of(t[3 * i + c])))
}

/// The distance from `o` along `d` to the plane of triangle `t` (nine floats), exact,
/// correctly rounded to `f32`; `None` where the ray is parallel to the plane or the
/// distance is past `f32`'s range.
#[cold]
#[inline(never)]
pub(crate) fn distance(o: [f32; 3], d: [f32; 3], t: &[f32]) -> Option<f32> {
    INTEGER_STAGE.fetch_add(1, Relaxed);
    if !all_finite(&[&o, &d, t]) {
        return None;
    }
    let [a, b, c] = vertices(t);
    let (num, den) = distance_terms(&o.map(Big::of), &d.map(Big::of), [&a, &b, &c]);
    if den.is_zero() {
        return None;
    }
    rounded_quotient(&num, &den)
}

/// The exact distance from `o` along `d` to the plane of triangle `t`, less `shift`
/// (the sum of two `f32`: `shift.0 + shift.1`), correctly rounded to `f32`; `None` where
/// the ray is parallel to the plane or the result is past `f32`'s range. What a walk
/// re-originated `shift` along the ray measures a hit of the ray as given by, under the
/// exact test: in the order of the exact distances, and as fine as the walk's own.
#[cold]
#[inline(never)]
pub(crate) fn shifted_distance(o: [f32; 3], d: [f32; 3], t: &[f32], shift: (f32, f32)) -> Option<f32> {
    INTEGER_STAGE.fetch_add(1, Relaxed);
    if !all_finite(&[&o, &d, t, &[shift.0, shift.1]]) {
        return None;
    }
    let [a, b, c] = vertices(t);
    let (num, den) = distance_terms(&o.map(Big::of), &d.map(Big::of), [&a, &b, &c]);
    if den.is_zero() {
        return None;
    }
    // num / den - s = (num 2^149 - S den) / (den 2^149), with S = s 2^149 an integer.
    let s = Big::of(shift.0).add(&Big::of(shift.1));
    rounded_quotient(&num.shl(149).sub(&s.mul(&den)), &den.shl(149))
}

/// Compares the exact distances along the ray to the planes of triangles `a` and `b`
/// (neither parallel to the ray; `Equal` where a coordinate is not finite).
#[cold]
#[inline(never)]
pub(crate) fn compare_distances(o: [f32; 3], d: [f32; 3], a: &[f32], b: &[f32]) -> std::cmp::Ordering {
    INTEGER_STAGE.fetch_add(1, Relaxed);
    if !all_finite(&[&o, &d, a, b]) {
        return std::cmp::Ordering::Equal;
    }
    let (bo, bd) = (o.map(Big::of), d.map(Big::of));
    let [a0, a1, a2] = vertices(a);
    let [b0, b1, b2] = vertices(b);
    let (na, da) = distance_terms(&bo, &bd, [&a0, &a1, &a2]);
    let (nb, db) = distance_terms(&bo, &bd, [&b0, &b1, &b2]);
    // na / da against nb / db: na db against nb da, turned by the sign of da db.
    let flip = da.is_negative() != db.is_negative();
    let ord = na.mul(&db).cmp(&nb.mul(&da));
    if flip {
        ord.reverse()
    } else {
        ord
    }
}

/// `num / den` rounded to the nearest `f32`, ties to even (`den` not zero); `None`
/// past `f32`'s range (rounded to an infinity). A negative quotient that rounds to
/// zero is `-0.0`.
pub(crate) fn rounded_quotient(num: &Big, den: &Big) -> Option<f32> {
    // num / den against x (an integer times 2^-150 here: a midpoint of two f32s):
    // the sign of num * 2^150 - x * 2^150 * den, turned by the sign of den.
    let scaled_num = num.shl(150).negate_if(den.is_negative());
    let den_abs = den.negate_if(den.is_negative());
    // Compares the quotient with (p + q) / 2 for f32 neighbours p, q (finite, or
    // 2^128 in magnitude for the virtual neighbour of MAX).
    let against_midpoint = |p: f32, q: f32| {
        let midpoint = Big::of_or_limit(p).add(&Big::of_or_limit(q)); // (p + q) / 2 * 2^150
        scaled_num.cmp(&midpoint.mul(&den_abs))
    };
    let approx = num.ratio(den);
    let mut c = approx as f32;
    if c.is_infinite() {
        c = f32::MAX.copysign(c);
    }
    if c == 0.0 {
        c = 0.0;
    }
    loop {
        let (below, above) = (next_down(c), next_up(c));
        let low = against_midpoint(below, c);
        let high = against_midpoint(c, above);
        use std::cmp::Ordering::*;
        let even = c.to_bits() & 1 == 0;
        if low == Less || (low == Equal && !even) {
            if below.is_infinite() {
                return None;
            }
            c = below;
        } else if high == Greater || (high == Equal && !even) {
            if above.is_infinite() {
                return None;
            }
            c = above;
        } else {
            return Some(if c == 0.0 && scaled_num.is_negative() { -0.0 } else { c });
        }
    }
}

impl Big {
    /// [`Big::of`], with the infinities standing for `2^128` (the neighbour of
    /// `f32::MAX` that rounding to nearest measures midpoints against).
    fn of_or_limit(x: f32) -> Big {
        if x.is_infinite() {
            Big::from_u64(1).shl(128 + 149).negate_if(x < 0.0)
        } else {
            Big::of(x)
        }
    }
}

/// The next `f32` above `x` (finite; zeros alike); `inf` above `MAX`.
fn next_up(x: f32) -> f32 {
    if x == 0.0 {
        return f32::from_bits(1);
    }
    let b = x.to_bits();
    f32::from_bits(if x > 0.0 { b + 1 } else { b - 1 })
}

/// The next `f32` below `x`.
fn next_down(x: f32) -> f32 {
    -next_up(-x)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(num: f64, den: f64) -> Option<f32> {
        // Integers to 2^53, exactly.
        let big = |x: f64| {
            let b = Big::from_u64(x.abs() as u64);
            b.negate_if(x < 0.0)
        };
        rounded_quotient(&big(num), &big(den))
    }

    #[test]
    fn quotients_round_to_nearest_even() {
        assert_eq!(q(1.0, 3.0), Some(1.0f32 / 3.0));
        assert_eq!(q(-2.0, 3.0), Some(-2.0f32 / 3.0));
        assert_eq!(q(2.0, -3.0), Some(-2.0f32 / 3.0));
        assert_eq!(q(0.0, 5.0), Some(0.0));
        // 2^24 + 1 lies halfway between 2^24 and 2^24 + 2: ties go to the even one.
        assert_eq!(q(16_777_217.0, 1.0), Some(16_777_216.0));
        assert_eq!(q(16_777_219.0, 1.0), Some(16_777_220.0));
        // Just off the tie, either way: (2^25 + 2 ± 1) / 2 against 2^24 + 1.
        let two = 2.0;
        assert_eq!(q(33_554_433.0 + 1.0 + 1.0, two), Some(16_777_218.0));
        // Against f64's own rounding over many quotients.
        let mut s = 7u64;
        for _ in 0..20_000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let a = (s >> 11) as f64;
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let b = ((s >> 40) + 1) as f64;
            // a / b in f64 is within half an f64 ulp; rounding that to f32 is right
            // unless it lands on an f32 midpoint, which these quotients never do
            // exactly (checked by the exact answer agreeing or the f64 being a tie).
            let want = (a / b) as f32;
            assert_eq!(q(a, b), Some(want), "{a} / {b}");
        }
    }

    #[test]
    fn quotients_past_f32_are_none_and_tiny_ones_subnormal() {
        let max = Big::of(f32::MAX);
        let one = Big::of(1.0);
        assert_eq!(rounded_quotient(&max, &one), Some(f32::MAX));
        assert_eq!(rounded_quotient(&max.shl(1), &one), None);
        assert_eq!(rounded_quotient(&max.shl(1).neg(), &one), None);
        let tiny = Big::of(f32::from_bits(3));
        assert_eq!(rounded_quotient(&tiny, &Big::of(2.0)), Some(f32::from_bits(2)));
        assert_eq!(rounded_quotient(&tiny.neg(), &Big::of(8.0)), Some(-0.0));
        assert!(rounded_quotient(&tiny.neg(), &Big::of(8.0)).unwrap().is_sign_negative());
    }
}
