//! Ray/triangle intersection (Möller & Trumbore 1997), `f32`.

/// A ray prepared for triangle tests.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriRay {
    pub o: [f32; 3],
    pub d: [f32; 3],
}

#[inline(always)]
fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline(always)]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Intersects triangle `t` (nine floats) with the ray; returns `(t, u, v)` when the
/// hit lies within `[tmin, tmax]`. A ray in the triangle's plane (zero determinant)
/// misses; edges are inclusive.
#[inline(always)]
pub(crate) fn intersect(r: &TriRay, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let v0 = [t[0], t[1], t[2]];
    let e1 = sub([t[3], t[4], t[5]], v0);
    let e2 = sub([t[6], t[7], t[8]], v0);
    let p = cross(r.d, e2);
    let det = dot(e1, p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = sub(r.o, v0);
    let u = dot(s, p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = cross(s, e1);
    let v = dot(r.d, q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let dist = dot(e2, q) * inv;
    (dist >= tmin && dist <= tmax).then_some((dist, u, v))
}

/// [`intersect`] in `f64`: the oracle's test (`reference::intersect_f64`) on the ray
/// and vertices widened exactly; the distance is compared with `[tmin, tmax]` in
/// `f64`, then rounded (rounding keeps it within, since the bounds are `f32`).
#[inline]
pub(crate) fn intersect_f64(r: &TriRay, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let v = |i: usize| glam::DVec3::new(f64::from(t[i]), f64::from(t[i + 1]), f64::from(t[i + 2]));
    let wide = |a: [f32; 3]| glam::DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
    let (dist, u, v) = crate::reference::intersect_f64(wide(r.o), wide(r.d), &[v(0), v(3), v(6)])?;
    (dist >= f64::from(tmin) && dist <= f64::from(tmax)).then_some((dist as f32, u as f32, v as f32))
}
