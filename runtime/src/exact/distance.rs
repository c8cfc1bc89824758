//! The distance from a point to a triangle as exact arithmetic gives it: the fallback
//! of the closest-point search (`cpu::closest`) wherever its `f64` error bound cannot
//! decide which triangle is nearer or how the distance rounds to `f32`.
//!
//! The squared distance is the least of the three edges' (as segments) and, where the
//! point's projection on the triangle's plane falls in the triangle (closed), the
//! plane's. With `r = v - p` the vertices relative to the point, each is a quotient of
//! polynomials in the `f32` inputs, evaluated here on integers ([`Wider`]: every `f32`
//! is an integer times `2^-149`):
//! * the plane: `(n.r_a)^2 / n.n` with `n = (b - a) x (c - a)`;
//! * an edge from `a` to `b`, `e = b - a`: `|r_a|^2` where `-r_a.e <= 0`, `|r_b|^2` where
//!   `-r_a.e >= e.e`, else `|r_a x e|^2 / e.e`.
//!
//! Every quotient is the squared distance times `2^298`, so any two compare by
//! cross-multiplying: ten factors of at most 279 bits, under [`Wider`]'s 3,072.

use std::cmp::Ordering;

use super::big::Wider;

/// A squared distance times `2^298`, as `num / den` (`den > 0`), and the feature of
/// the triangle it is measured to.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Square {
    num: Wider,
    den: Wider,
    pub feature: Feature,
}

/// Where on a triangle its nearest point lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Feature {
    /// Vertex `i`.
    Vertex(usize),
    /// Strictly inside the edge from vertex `i` to vertex `j`.
    Edge(usize, usize),
    /// Inside the face (closed).
    Face,
}

impl Square {
    /// Compares the distances.
    pub fn cmp(&self, other: &Square) -> Ordering {
        self.num.mul(&other.den).cmp(&other.num.mul(&self.den))
    }

    /// The squared distance, within a few `f64` roundings.
    #[cfg(test)]
    pub fn approx(&self) -> f64 {
        super::big::scaled(self.num.ratio(&self.den), -298)
    }

    /// Whether the distance is zero (the point lies on the triangle).
    pub fn is_zero(&self) -> bool {
        self.num.is_zero()
    }

    /// The distance, correctly rounded to `f32` (ties to even): `f32::INFINITY` past
    /// its range.
    pub fn rounded(&self) -> f32 {
        if self.is_zero() {
            return 0.0;
        }
        // Within a few 2^-52 of the square root: the nearest f32, or one beside it.
        let guess = (self.num.ratio(&self.den).sqrt() * 2f64.powi(-149)) as f32;
        if !guess.is_finite() {
            return f32::INFINITY;
        }
        let mut r = guess;
        // Up while the distance lies past the midpoint above r (or on it, r odd).
        while let Some(above) = self.against_midpoint(r, super::next_up(r)) {
            match above {
                Ordering::Greater => r = super::next_up(r),
                Ordering::Equal if r.to_bits() & 1 == 1 => r = super::next_up(r),
                _ => break,
            }
        }
        // Down while it lies before the midpoint below r (or on it, r odd).
        while r > 0.0 {
            let below = super::next_down(r);
            match self.against_midpoint(below, r) {
                Some(Ordering::Less) => r = below,
                Some(Ordering::Equal) if r.to_bits() & 1 == 1 => r = below,
                _ => break,
            }
        }
        r
    }

    /// The distance against the midpoint of `lo` and `hi` (finite, non-negative), or
    /// `None` past `f32`'s range.
    fn against_midpoint(&self, lo: f32, hi: f32) -> Option<Ordering> {
        if !hi.is_finite() {
            return None;
        }
        // d <= (lo + hi) / 2  <=>  4 num <= ((lo + hi) 2^149)^2 den (both sides >= 0).
        let twice = Wider::of(lo).add(&Wider::of(hi));
        Some(self.num.shl(2).cmp(&twice.mul(&twice).mul(&self.den)))
    }
}

fn of3(v: [f32; 3]) -> [Wider; 3] {
    v.map(Wider::of)
}

fn sub3(a: &[Wider; 3], b: &[Wider; 3]) -> [Wider; 3] {
    [0, 1, 2].map(|i| a[i].sub(&b[i]))
}

fn dot(a: &[Wider; 3], b: &[Wider; 3]) -> Wider {
    a[0].mul(&b[0]).add(&a[1].mul(&b[1])).add(&a[2].mul(&b[2]))
}

fn cross(a: &[Wider; 3], b: &[Wider; 3]) -> [Wider; 3] {
    [
        a[1].mul(&b[2]).sub(&a[2].mul(&b[1])),
        a[2].mul(&b[0]).sub(&a[0].mul(&b[2])),
        a[0].mul(&b[1]).sub(&a[1].mul(&b[0])),
    ]
}

/// The squared distance from the point to the segment between the vertices at `ra`
/// and `rb` (relative to the point).
fn segment(r: &[[Wider; 3]; 3], i: usize, j: usize) -> Square {
    let (ra, rb) = (&r[i], &r[j]);
    let one = Wider::from_u64(1);
    let e = sub3(rb, ra);
    let ee = dot(&e, &e);
    // (p - a).e = -r_a.e: the foot's parameter times e.e.
    let along = dot(ra, &e).neg();
    if along.signum() <= 0 || ee.is_zero() {
        return Square { num: dot(ra, ra), den: one, feature: Feature::Vertex(i) };
    }
    if along.cmp(&ee) != Ordering::Less {
        return Square { num: dot(rb, rb), den: one, feature: Feature::Vertex(j) };
    }
    let c = cross(ra, &e);
    Square { num: dot(&c, &c), den: ee, feature: Feature::Edge(i, j) }
}

/// The exact squared distance from `p` to the triangle `t`.
#[cold]
#[inline(never)]
pub(crate) fn squared_distance(p: [f32; 3], t: [[f32; 3]; 3]) -> Square {
    let bp = of3(p);
    let v = t.map(of3);
    let r = [0, 1, 2].map(|i| sub3(&v[i], &bp));
    let mut best = segment(&r, 0, 1);
    for (a, b) in [(1, 2), (2, 0)] {
        let s = segment(&r, a, b);
        if s.cmp(&best) == Ordering::Less {
            best = s;
        }
    }
    let n = cross(&sub3(&v[1], &v[0]), &sub3(&v[2], &v[0]));
    let nn = dot(&n, &n);
    if nn.is_zero() {
        return best;
    }
    // The projection lies in the closed triangle when, for each edge from v_i to
    // v_j, n.(e x (p - v_i)) = -n.(e x r_i) >= 0 (p - proj is along n, which the
    // triple product ignores).
    let inside = [(0, 1), (1, 2), (2, 0)].iter().all(|&(i, j)| {
        let e = sub3(&v[j], &v[i]);
        dot(&n, &cross(&e, &r[i])).signum() <= 0
    });
    if inside {
        let h = dot(&n, &r[0]);
        let plane = Square { num: h.mul(&h), den: nn, feature: Feature::Face };
        if plane.cmp(&best) == Ordering::Less {
            best = plane;
        }
    }
    best
}

/// The nearest point of triangle `t` to `p` on `feature` (as [`squared_distance`]
/// found it) and its barycentrics on the second and third vertices, in `f64` from
/// quantities that are exact or rounded once: stable where the triangle is a sliver.
pub(crate) fn point_on(p: [f32; 3], t: [[f32; 3]; 3], feature: Feature) -> ([f64; 3], f64, f64) {
    let pd = p.map(f64::from);
    let v = t.map(|v| v.map(f64::from));
    let weights = |i: usize, w: f64| match i {
        1 => (w, 0.0),
        2 => (0.0, w),
        _ => (0.0, 0.0),
    };
    match feature {
        Feature::Vertex(i) => {
            let (u, w) = weights(i, 1.0);
            (v[i], u, w)
        }
        Feature::Edge(i, j) => {
            let e = [0, 1, 2].map(|k| v[j][k] - v[i][k]);
            let along = (0..3).map(|k| (pd[k] - v[i][k]) * e[k]).sum::<f64>();
            let s = (along / (0..3).map(|k| e[k] * e[k]).sum::<f64>()).clamp(0.0, 1.0);
            let q = [0, 1, 2].map(|k| v[i][k] + e[k] * s);
            let (ui, wi) = weights(i, 1.0 - s);
            let (uj, wj) = weights(j, s);
            (q, ui + uj, wi + wj)
        }
        Feature::Face => {
            let bp = of3(p);
            let bv = t.map(of3);
            let n = cross(&sub3(&bv[1], &bv[0]), &sub3(&bv[2], &bv[0]));
            let nn = dot(&n, &n);
            let h = dot(&n, &sub3(&bv[0], &bp));
            // n in true units (its integers are 2^298 times it); h / nn is 2^-149 times
            // the true quotient.
            let nf = n.map(|c| {
                let (m, e) = c.scaled_f64();
                super::big::scaled(m, e - 298)
            });
            let s = super::big::scaled(h.ratio(&nn), 149);
            let q = [0, 1, 2].map(|k| pd[k] + nf[k] * s);
            let nf2 = nf.iter().map(|x| x * x).sum::<f64>();
            let d = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|k| a[k] - b[k]);
            let triple = |a: [f64; 3], b: [f64; 3]| {
                let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
                (0..3).map(|k| c[k] * nf[k]).sum::<f64>() / nf2
            };
            (q, triple(d(q, v[0]), d(v[2], v[0])), triple(d(v[1], v[0]), d(q, v[0])))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 4.0, 0.0]];

    #[test]
    fn distances_to_each_feature_are_exact() {
        // Above the face, beside an edge, past a vertex, on the triangle.
        assert_eq!(squared_distance([1.0, 1.0, 3.0], TRI).rounded(), 3.0);
        assert_eq!(squared_distance([2.0, -3.0, 4.0], TRI).rounded(), 5.0);
        assert_eq!(squared_distance([7.0, -4.0, 0.0], TRI).rounded(), 5.0);
        assert_eq!(squared_distance([-3.0, 8.0, 0.0], TRI).rounded(), 5.0);
        assert!(squared_distance([1.0, 1.0, 0.0], TRI).is_zero());
        assert!(squared_distance([2.0, 2.0, 0.0], TRI).is_zero(), "on the hypotenuse");
        assert!(!squared_distance([2.0, 2.0 + f32::EPSILON * 2.0, 0.0], TRI).is_zero());
    }

    #[test]
    fn rounding_is_to_the_nearest_f32() {
        // sqrt(2) and sqrt(3) against f64's correctly rounded roots, rounded once more
        // (both far from an f32 midpoint: a double rounding cannot differ here).
        let d2 = squared_distance([1.0, 1.0, 1.0], [[0.0; 3], [0.0; 3], [0.0; 3]]);
        assert_eq!(d2.rounded(), 3f64.sqrt() as f32);
        let d2 = squared_distance([1.0, 1.0, 0.0], [[0.0; 3], [0.0, 0.0, 1.0], [0.0, 0.0, 2.0]]);
        assert_eq!(d2.rounded(), 2f64.sqrt() as f32);
        // A distance of a subnormal and one near f32::MAX.
        let tiny = f32::from_bits(3);
        assert_eq!(squared_distance([1.0, 1.0, tiny], TRI).rounded(), tiny);
        let far = squared_distance([1.0, 1.0, 3.0e38], TRI);
        assert_eq!(far.rounded(), 3.0e38);
        assert_eq!(squared_distance([-3.0e38, 0.0, 3.0e38], TRI).rounded(), f32::INFINITY);
    }

    #[test]
    fn distances_compare_exactly() {
        // One ulp of 4.0 farther is farther, however it rounds.
        let a = squared_distance([1.0, 1.0, 4.0], TRI);
        let b = squared_distance([1.0, 1.0, 4.0f32.next_up()], TRI);
        assert_eq!(a.cmp(&b), Ordering::Less);
        assert_eq!(a.cmp(&a), Ordering::Equal);
        // The widest inputs multiply without overflow.
        let wide = [
            [f32::MAX, -f32::MAX, f32::MAX],
            [-f32::MAX, f32::MIN_POSITIVE, 0.0],
            [f32::from_bits(1), f32::MAX, -f32::MAX],
        ];
        let s = squared_distance([f32::MAX, f32::from_bits(1), -f32::MAX], wide);
        let t = squared_distance([-f32::MAX, 1.0, f32::MAX], wide);
        assert_eq!(Some(s.cmp(&t)), s.approx().partial_cmp(&t.approx()));
        assert!(s.approx() > 1e76 && t.approx() > 1e76);
    }
}
