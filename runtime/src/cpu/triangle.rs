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
