//! An exact oracle: every ray–triangle question answered in rational arithmetic
//! (`num-rational`), by formulas other than the tracer's, so that it can find the
//! tracer's errors rather than share them.
//!
//! The tracer decides a hit by the signs of the edge functions of the ray sheared onto
//! `+z` (Plücker coordinates, in effect). Here the ray's point on the triangle's plane,
//! `p = o + t d` with `t = n.(a - o) / n.d`, is computed as a rational and tested
//! against each edge in the plane: `((q - p0) x (p - p0)).n >= 0` for every edge
//! `p0 -> q` (closed edges). Where a crossing lies exactly on an edge or a vertex, the
//! stated rule decides which triangle owns it (`Shear::intersect_owned`): in the plane
//! the ray is sheared onto, the edge, oriented by the sign of the triangle's sheared
//! area, must point up, or right when level; at a vertex both of its edges. Distances
//! are rounded to `f32` by a search over `f32` values compared exactly.
//!
//! Stated rules the tracer promises and the oracle follows: a ray lying in a
//! triangle's plane meets it nowhere; a hit counts where its distance, rounded to the
//! nearest `f32`, lies in `[tmin, tmax]`; the nearest hit is the exactly nearest, ties
//! (exactly equal distances) to the lowest input index; crossings come in exact order,
//! ties by index.

use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::{Signed, Zero};
use std::cmp::Ordering;

type Q = BigRational;

/// The exact value of an `f32`.
pub fn rational(x: f32) -> Q {
    Q::from_float(x).expect("finite")
}

fn v3(p: [f32; 3]) -> [Q; 3] {
    p.map(rational)
}

fn sub(a: &[Q; 3], b: &[Q; 3]) -> [Q; 3] {
    [&a[0] - &b[0], &a[1] - &b[1], &a[2] - &b[2]]
}

fn cross(a: &[Q; 3], b: &[Q; 3]) -> [Q; 3] {
    [&a[1] * &b[2] - &a[2] * &b[1], &a[2] * &b[0] - &a[0] * &b[2], &a[0] * &b[1] - &a[1] * &b[0]]
}

fn dot(a: &[Q; 3], b: &[Q; 3]) -> Q {
    &a[0] * &b[0] + &a[1] * &b[1] + &a[2] * &b[2]
}

fn sign(q: &Q) -> i32 {
    if q.is_zero() {
        0
    } else if q.is_positive() {
        1
    } else {
        -1
    }
}

/// `x` rounded to the nearest `f32`, ties to even; `None` past `f32::MAX` (where
/// rounding gives an infinity).
pub fn round_f32(x: &Q) -> Option<f32> {
    round_quotient_f32(x.numer(), x.denom())
}

/// The exact value of an `f32` times `2^149`: every finite `f32` is an integer there.
fn int(x: f32) -> BigInt {
    assert!(x.is_finite(), "finite");
    let bits = x.to_bits();
    let (field, fraction) = ((bits >> 23) & 0xFF, bits & 0x7F_FFFF);
    // Subnormals are `fraction * 2^-149`; normals `(2^23 + fraction) * 2^(field - 150)`.
    let magnitude =
        if field == 0 { BigInt::from(fraction) } else { BigInt::from(fraction | 0x80_0000) << (field - 1) as usize };
    if x < 0.0 {
        -magnitude
    } else {
        magnitude
    }
}

fn int3(p: [f32; 3]) -> [BigInt; 3] {
    p.map(int)
}

fn isub(a: &[BigInt; 3], b: &[BigInt; 3]) -> [BigInt; 3] {
    [&a[0] - &b[0], &a[1] - &b[1], &a[2] - &b[2]]
}

fn iadd(a: &[BigInt; 3], b: &[BigInt; 3]) -> [BigInt; 3] {
    [&a[0] + &b[0], &a[1] + &b[1], &a[2] + &b[2]]
}

fn iscale(s: &BigInt, a: &[BigInt; 3]) -> [BigInt; 3] {
    [s * &a[0], s * &a[1], s * &a[2]]
}

fn icross(a: &[BigInt; 3], b: &[BigInt; 3]) -> [BigInt; 3] {
    [&a[1] * &b[2] - &a[2] * &b[1], &a[2] * &b[0] - &a[0] * &b[2], &a[0] * &b[1] - &a[1] * &b[0]]
}

fn idot(a: &[BigInt; 3], b: &[BigInt; 3]) -> BigInt {
    &a[0] * &b[0] + &a[1] * &b[1] + &a[2] * &b[2]
}

fn isign(x: &BigInt) -> i32 {
    match x.sign() {
        num_bigint::Sign::Minus => -1,
        num_bigint::Sign::NoSign => 0,
        num_bigint::Sign::Plus => 1,
    }
}

/// The quotient `n / d` (`d` not zero) rounded to the nearest `f32`, ties to even, by
/// integer division at the quotient's binade; `None` past `f32::MAX`.
pub fn round_quotient_f32(n: &BigInt, d: &BigInt) -> Option<f32> {
    assert!(!d.is_zero(), "a quotient");
    if n.is_zero() {
        return Some(0.0);
    }
    let negative = n.is_negative() != d.is_negative();
    let (n, d) = (n.abs(), d.abs());
    // The binade: 2^e <= n / d < 2^(e + 1).
    let (bn, bd) = (n.bits() as i64, d.bits() as i64);
    let e = bn - bd;
    let at_least = if e >= 0 { n >= (&d << e as usize) } else { (&n << (-e) as usize) >= d };
    let e = if at_least { e } else { e - 1 };
    if e >= 128 {
        return None;
    }
    // The quantum there (subnormals share 2^-149), the quotient in quanta and its rest.
    let q = e.max(-126) - 23;
    let (num, den) = if q >= 0 { (n, d << q as usize) } else { (n << (-q) as usize, d) };
    let m = &num / &den;
    let twice: BigInt = (num - &m * &den) << 1usize;
    let mut m = u64::try_from(&m).expect("at most 24 bits");
    if twice > den || (twice == den && m & 1 == 1) {
        m += 1;
    }
    let value = m as f64 * 2f64.powi(q as i32);
    if value > f32::MAX as f64 {
        return None;
    }
    let value = value as f32;
    Some(if negative { -value } else { value })
}

/// A ray, exactly: its coordinates as integers (`f32` values times `2^149`).
pub struct ExactRay {
    o: [BigInt; 3],
    d: [BigInt; 3],
    /// The sheared frame's axes, as the tracer picks them.
    k: [usize; 3],
    tmin: f32,
    tmax: f32,
}

/// One hit of the exact oracle.
#[derive(Clone, Debug)]
pub struct ExactHit {
    /// The exact distance.
    pub t: Q,
    /// The distance rounded to the nearest `f32`.
    pub t32: f32,
    /// Input index.
    pub triangle: u32,
    /// Barycentric weights of the second and third vertices.
    pub u: f64,
    /// See `u`.
    pub v: f64,
    /// Whether the ray arrives on the front (`n.d < 0`).
    pub enters: bool,
}

impl ExactRay {
    /// The ray `o + t d`, `t` in `[tmin, tmax]` (`d` not zero).
    pub fn new(o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> ExactRay {
        let a = d.map(f32::abs);
        let kz = if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        ExactRay { o: int3(o), d: int3(d), k: [kx, ky, kz], tmin, tmax }
    }

    /// The signs of a vector's sheared-plane coordinates (a difference of points),
    /// `e[kx] - e[kz] d[kx] / d[kz]` and the same for `ky`: the signs of those times
    /// `d[kz]`, times the sign of `d[kz]`.
    fn sheared(&self, e: &[BigInt; 3]) -> (BigInt, BigInt) {
        let [kx, ky, kz] = self.k;
        let dz = &self.d[kz];
        let s = if dz.is_negative() { -1 } else { 1 };
        ((&e[kx] * dz - &self.d[kx] * &e[kz]) * BigInt::from(s), (&e[ky] * dz - &self.d[ky] * &e[kz]) * BigInt::from(s))
    }

    /// The hit of triangle `tri`, whose input index is `id`: edges closed, or owned by
    /// the rule when `owned`.
    ///
    /// In integers: with `n` the normal, `t = N / D` for `N = n.(a - o)` and `D = n.d`,
    /// and `D (p - a) = D (o - a) + N d` for the ray's point `p` on the plane, so each
    /// edge's side of `p` is a sign of integers times the sign of `D`.
    pub fn hit(&self, tri: &[[f32; 3]; 3], id: u32, owned: bool) -> Option<ExactHit> {
        let v = tri.map(int3);
        let e1 = isub(&v[1], &v[0]);
        let e2 = isub(&v[2], &v[0]);
        let n = icross(&e1, &e2);
        let den = idot(&n, &self.d);
        if den.is_zero() {
            return None;
        }
        let num = idot(&n, &isub(&v[0], &self.o));
        // D (p - a).
        let pa = iadd(&iscale(&den, &isub(&self.o, &v[0])), &iscale(&num, &self.d));
        let dp = |i: usize| iadd(&pa, &iscale(&den, &isub(&v[0], &v[i])));
        let dps = [dp(0), dp(1), dp(2)];
        let ds = isign(&den);
        // Which side of each edge p lies, in the plane (positive inside): edges 0->1,
        // 1->2, 2->0.
        let side = |i: usize| {
            let j = (i + 1) % 3;
            ds * isign(&idot(&icross(&isub(&v[j], &v[i]), &dps[i]), &n))
        };
        let s = [side(0), side(1), side(2)];
        if s.contains(&-1) {
            return None;
        }
        if owned && s.contains(&0) {
            // The sign the tracer's test gives the sheared area (its edge functions
            // sum to minus the 2D cross product of the sheared edges).
            let (ax, ay) = self.sheared(&e1);
            let (bx, by) = self.sheared(&e2);
            let area = -isign(&(&ax * &by - &ay * &bx));
            for i in 0..3 {
                if s[i] != 0 {
                    continue;
                }
                let (ex, ey) = self.sheared(&isub(&v[(i + 1) % 3], &v[i]));
                let (ex, ey) = (area * isign(&ex), area * isign(&ey));
                if !(ey > 0 || (ey == 0 && ex > 0)) {
                    return None;
                }
            }
        }
        let t32 = round_quotient_f32(&num, &den)?;
        if !(t32 >= self.tmin && t32 <= self.tmax) {
            return None;
        }
        // Barycentrics: areas of the sub-triangles against the whole, along n, from
        // D (b - p) = D (b - a) - D (p - a).
        let nn = idot(&n, &n);
        let whole = &den * &den * &nn;
        let weight = |i: usize| {
            let (a, b) = ((i + 1) % 3, (i + 2) % 3);
            // (b - p) x (c - p) = (p - b) x (p - c).
            let w = idot(&icross(&dps[a], &dps[b]), &n);
            num_traits::ToPrimitive::to_f64(&Q::new_raw(w, whole.clone())).unwrap_or(f64::NAN)
        };
        let t = if den.is_negative() { Q::new_raw(-num, -den.clone()) } else { Q::new_raw(num, den.clone()) };
        Some(ExactHit { t, t32, triangle: id, u: weight(1), v: weight(2), enters: den.is_negative() })
    }
}

/// The exact oracle over a triangle list (input indices are positions), with a
/// bounding-box tree of its own to find the triangles a line comes near.
pub struct ExactOracle<'m> {
    triangles: &'m [[[f32; 3]; 3]],
    screen: Screen,
}

impl<'m> ExactOracle<'m> {
    /// The oracle of `triangles`.
    pub fn new(triangles: &'m [[[f32; 3]; 3]]) -> ExactOracle<'m> {
        ExactOracle { triangles, screen: Screen::new(triangles) }
    }

    /// Every hit of `ray` (edges closed or owned), in no order. Only the triangles
    /// whose boxes the ray's line comes near are tested exactly.
    pub fn hits(&self, ray: &ExactRay, o: [f32; 3], d: [f32; 3], owned: bool) -> Vec<ExactHit> {
        let mut near = Vec::new();
        self.screen.near_line(o, d, &mut near);
        near.sort_unstable();
        near.into_iter().filter_map(|i| ray.hit(&self.triangles[i as usize], i, owned)).collect()
    }

    /// The nearest hit in `[tmin, tmax]` (edges closed), exactly nearest, ties to the
    /// lowest index.
    pub fn nearest(&self, o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> Option<ExactHit> {
        let ray = ExactRay::new(o, d, tmin, tmax);
        self.hits(&ray, o, d, false).into_iter().min_by(|a, b| a.t.cmp(&b.t).then(a.triangle.cmp(&b.triangle)))
    }

    /// Every crossing in `[tmin, tmax]` (edges owned), in exact order, ties by index.
    pub fn crossings(&self, o: [f32; 3], d: [f32; 3], tmin: f32, tmax: f32) -> Vec<ExactHit> {
        let ray = ExactRay::new(o, d, tmin, tmax);
        let mut hits = self.hits(&ray, o, d, true);
        hits.sort_by(|a, b| a.t.cmp(&b.t).then(a.triangle.cmp(&b.triangle)));
        hits
    }
}

/// A box in `f64`, widened so that the slab test below never misses a line that
/// touches what it holds.
#[derive(Clone, Copy)]
struct Bounds {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Bounds {
    const EMPTY: Bounds = Bounds { lo: [f64::INFINITY; 3], hi: [f64::NEG_INFINITY; 3] };

    fn of(t: &[[f32; 3]; 3]) -> Bounds {
        let lo = [0, 1, 2].map(|k| t.iter().map(|v| v[k] as f64).fold(f64::INFINITY, f64::min));
        let hi = [0, 1, 2].map(|k| t.iter().map(|v| v[k] as f64).fold(f64::NEG_INFINITY, f64::max));
        Bounds { lo, hi }
    }

    fn join(self, b: Bounds) -> Bounds {
        Bounds { lo: [0, 1, 2].map(|k| self.lo[k].min(b.lo[k])), hi: [0, 1, 2].map(|k| self.hi[k].max(b.hi[k])) }
    }

    /// Whether the line `o + t d` passes within a generous margin of the box (a
    /// prefilter in `f64`: it never drops a box the line touches).
    fn near_line(&self, o: [f32; 3], d: [f32; 3]) -> bool {
        let (lo, hi) = (self.lo, self.hi);
        let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        let scale = (0..3).map(|k| lo[k].abs().max(hi[k].abs()).max((o[k] as f64).abs())).fold(0.0, f64::max);
        let margin = 1e-6 * (size + scale) + 1e-300;
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (lo, hi) = (lo[k] - margin, hi[k] + margin);
            let (ok, dk) = (o[k] as f64, d[k] as f64);
            if dk == 0.0 {
                if ok < lo || ok > hi {
                    return false;
                }
                continue;
            }
            let (a, b) = ((lo - ok) / dk, (hi - ok) / dk);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        // Loose: the slab distances carry rounding; widen by a relative hair.
        t0 <= t1 + 1e-9 * (t0.abs() + t1.abs()) || !t0.is_finite() || !t1.is_finite()
    }
}

/// A bounding-box tree over the triangles (median splits, four to a leaf): the
/// oracle's screen. A node's box holds its triangles' boxes, so a line near a triangle's
/// box is near every box above it, and the screen keeps every triangle the plain
/// all-triangle screen keeps.
struct Screen {
    /// `(bounds, first, count)`: a leaf holds `order[first..first + count]`; an inner
    /// node (`count == 0`) has children `first` and `first + 1`.
    nodes: Vec<(Bounds, u32, u32)>,
    order: Vec<u32>,
    boxes: Vec<Bounds>,
}

impl Screen {
    fn new(triangles: &[[[f32; 3]; 3]]) -> Screen {
        let boxes: Vec<Bounds> = triangles.iter().map(Bounds::of).collect();
        let mut screen =
            Screen { nodes: vec![(Bounds::EMPTY, 0, 0)], order: (0..triangles.len() as u32).collect(), boxes };
        screen.split(0, 0, triangles.len());
        screen
    }

    fn split(&mut self, node: usize, first: usize, end: usize) {
        let bounds = self.order[first..end].iter().fold(Bounds::EMPTY, |b, &i| b.join(self.boxes[i as usize]));
        if end - first <= 4 {
            self.nodes[node] = (bounds, first as u32, (end - first) as u32);
            return;
        }
        let axis =
            (0..3).max_by(|&a, &b| (bounds.hi[a] - bounds.lo[a]).total_cmp(&(bounds.hi[b] - bounds.lo[b]))).unwrap();
        let mid = (first + end) / 2;
        let boxes = &self.boxes;
        let centre = |i: &u32| boxes[*i as usize].lo[axis] + boxes[*i as usize].hi[axis];
        self.order[first..end].select_nth_unstable_by(mid - first, |a, b| centre(a).total_cmp(&centre(b)));
        let children = self.nodes.len();
        self.nodes.push((Bounds::EMPTY, 0, 0));
        self.nodes.push((Bounds::EMPTY, 0, 0));
        self.nodes[node] = (bounds, children as u32, 0);
        self.split(children, first, mid);
        self.split(children + 1, mid, end);
    }

    /// The triangles whose boxes the line `o + t d` comes near, in no order.
    fn near_line(&self, o: [f32; 3], d: [f32; 3], out: &mut Vec<u32>) {
        if self.order.is_empty() {
            return;
        }
        let mut stack = vec![0usize];
        while let Some(node) = stack.pop() {
            let (bounds, first, count) = self.nodes[node];
            if !bounds.near_line(o, d) {
                continue;
            }
            if count == 0 {
                stack.extend([first as usize, first as usize + 1]);
                continue;
            }
            for &i in &self.order[first as usize..(first + count) as usize] {
                if self.boxes[i as usize].near_line(o, d) {
                    out.push(i);
                }
            }
        }
    }
}

/// Whether `p` is inside the closed mesh, exactly, by the tracer's stated rule for
/// points on the surface (answered as the points just beside them along `dir`): the
/// parity of the owned crossings of the ray from `p` along `dir` at exact distances
/// above zero.
pub fn exact_inside(oracle: &ExactOracle<'_>, p: [f32; 3], dir: [f32; 3]) -> bool {
    let ray = ExactRay::new(p, dir, f32::NEG_INFINITY, f32::INFINITY);
    let hits = oracle.hits(&ray, p, dir, true);
    hits.iter().filter(|h| h.t.is_positive()).count() % 2 == 1
}

/// Generators of the rays and points exact arithmetic is needed for.
pub mod hard {
    use octrace_bake::procedural::SplitMix;

    /// The procedural meshes' generator (SplitMix64), drawing in `f64`.
    pub struct Rng(pub SplitMix);

    impl Rng {
        /// The generator seeded with `seed`.
        pub fn new(seed: u64) -> Rng {
            Rng(SplitMix(seed))
        }

        /// The next 64 random bits.
        pub fn next_u64(&mut self) -> u64 {
            self.0.next_u64()
        }

        /// Uniform in `[0, 1)`.
        pub fn unit(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }

        /// Uniform in `0..n`.
        pub fn below(&mut self, n: usize) -> usize {
            (self.next_u64() % n as u64) as usize
        }

        /// A uniform direction.
        pub fn direction(&mut self) -> [f64; 3] {
            let z = 1.0 - 2.0 * self.unit();
            let phi = std::f64::consts::TAU * self.unit();
            let r = (1.0 - z * z).max(0.0).sqrt();
            [r * phi.cos(), r * phi.sin(), z]
        }
    }

    /// `x` moved by `k` representable steps (negative: down).
    pub fn ulps(x: f32, k: i32) -> f32 {
        let mut x = x;
        for _ in 0..k.unsigned_abs() {
            x = if k > 0 { next_up(x) } else { -next_up(-x) };
        }
        x
    }

    fn next_up(x: f32) -> f32 {
        if x == 0.0 {
            return f32::from_bits(1);
        }
        let b = x.to_bits();
        f32::from_bits(if x > 0.0 { b + 1 } else { b - 1 })
    }

    /// Each coordinate moved by -2..=2 ulps at random.
    pub fn jitter(p: [f32; 3], rng: &mut Rng) -> [f32; 3] {
        p.map(|c| ulps(c, rng.below(5) as i32 - 2))
    }

    fn to32(p: [f64; 3]) -> [f32; 3] {
        p.map(|c| c as f32)
    }

    /// The kinds of hard rays, by name.
    pub const RAY_KINDS: [&str; 7] =
        ["near-vertex", "near-edge", "through-vertex", "grazing", "along-edge", "axis-plane", "far-vertex"];

    /// `n` rays of kind `kind` at `triangles`, as `(origin, direction)`.
    pub fn rays(triangles: &[[[f32; 3]; 3]], kind: &str, n: usize, seed: u64) -> Vec<([f32; 3], [f32; 3])> {
        let mut rng = Rng::new(seed);
        let lo = [0, 1, 2].map(|k| triangles.iter().flatten().map(|v| v[k]).fold(f32::INFINITY, f32::min));
        let hi = [0, 1, 2].map(|k| triangles.iter().flatten().map(|v| v[k]).fold(f32::NEG_INFINITY, f32::max));
        let size = (0..3).map(|k| (hi[k] - lo[k]) as f64).fold(0.0, f64::max);
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let tri = triangles[rng.below(triangles.len())];
            let i = rng.below(3);
            let (a, b) = (tri[i].map(f64::from), tri[(i + 1) % 3].map(f64::from));
            let dir = rng.direction();
            // A point of the ray, and how far back its origin stands.
            let back = size * (0.2 + rng.unit());
            let (target, d): ([f64; 3], [f64; 3]) = match kind {
                "near-vertex" | "through-vertex" | "far-vertex" => (a, dir),
                "near-edge" => {
                    let s = rng.unit();
                    ([0, 1, 2].map(|k| a[k] + s * (b[k] - a[k])), dir)
                }
                "grazing" => {
                    // Along the triangle's plane, tilted off it by about 2^-20.
                    let c = tri[(i + 2) % 3].map(f64::from);
                    let e = [0, 1, 2].map(|k| b[k] - a[k]);
                    let f = [0, 1, 2].map(|k| c[k] - a[k]);
                    let n = [e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0]];
                    let (ln, le) = (norm(n), norm(e));
                    let tilt = (rng.unit() - 0.5) * 2f64.powi(-19);
                    let s = rng.unit();
                    let d = [0, 1, 2].map(|k| e[k] / le + (f[k] / norm(f)) * (rng.unit() - 0.5) + tilt * n[k] / ln);
                    ([0, 1, 2].map(|k| a[k] + s * f[k] * 0.5), d)
                }
                "along-edge" => {
                    let e = [0, 1, 2].map(|k| b[k] - a[k]);
                    (a, e)
                }
                "axis-plane" => {
                    let mut d = dir;
                    d[rng.below(3)] = 0.0;
                    (a, d)
                }
                other => panic!("no ray kind {other}"),
            };
            let l = norm(d);
            if l == 0.0 {
                continue;
            }
            let d = d.map(|c| c / l);
            let back = if kind == "far-vertex" { size * 1e4 } else { back };
            let o = to32([0, 1, 2].map(|k| target[k] - back * d[k]));
            let d32 = to32(d);
            let (o, d32) = match kind {
                // Exactly through the vertex in f32: the direction is the difference.
                "through-vertex" => (o, to32([0, 1, 2].map(|k| a[k] - o[k] as f64))),
                "along-edge" | "axis-plane" => (o, d32),
                _ => (jitter(o, &mut rng), d32),
            };
            if d32 != [0.0; 3] && d32.iter().all(|c| c.is_finite()) {
                out.push((o, d32));
            }
        }
        out
    }

    /// The kinds of hard points, by name.
    pub const POINT_KINDS: [&str; 4] = ["at-vertex", "near-vertex", "near-edge", "subnormal"];

    /// `n` points of kind `kind` at `triangles`.
    pub fn points(triangles: &[[[f32; 3]; 3]], kind: &str, n: usize, seed: u64) -> Vec<[f32; 3]> {
        let mut rng = Rng::new(seed);
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let tri = triangles[rng.below(triangles.len())];
            let i = rng.below(3);
            let (a, b) = (tri[i], tri[(i + 1) % 3]);
            let p = match kind {
                "at-vertex" => a,
                "near-vertex" => jitter(a, &mut rng),
                "near-edge" => {
                    let s = rng.unit();
                    jitter([0, 1, 2].map(|k| (a[k] as f64 + s * (b[k] as f64 - a[k] as f64)) as f32), &mut rng)
                }
                "subnormal" => {
                    // A vertex's zero coordinates (or its smallest one) moved to a
                    // subnormal either side.
                    let mut p = a;
                    let k = (0..3).min_by(|&x, &y| p[x].abs().total_cmp(&p[y].abs())).unwrap();
                    let tiny = f32::from_bits(1 + rng.below(4) as u32);
                    p[k] = if rng.below(2) == 0 { tiny } else { -tiny };
                    if a[k] != 0.0 {
                        p[k] += a[k];
                    }
                    p
                }
                other => panic!("no point kind {other}"),
            };
            out.push(p);
        }
        out
    }

    fn norm(v: [f64; 3]) -> f64 {
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
    }
}

/// The exact squared distance from `p` to the triangle `t`, by construction: the foot
/// of the perpendicular on the plane where it lies in the closed triangle, else the
/// nearest of the edges' clamped feet (not the tracer's formulas: its foot is never
/// formed).
pub fn squared_distance(p: [f32; 3], t: [[f32; 3]; 3]) -> Q {
    let p = v3(p);
    let v = t.map(v3);
    let n = cross(&sub(&v[1], &v[0]), &sub(&v[2], &v[0]));
    let nn = dot(&n, &n);
    if !nn.is_zero() {
        let s = dot(&n, &sub(&p, &v[0])) / &nn;
        let foot = [0, 1, 2].map(|k| &p[k] - &n[k] * &s);
        let inside = (0..3).all(|i| {
            let (a, b) = (&v[i], &v[(i + 1) % 3]);
            sign(&dot(&cross(&sub(b, a), &sub(&foot, a)), &n)) >= 0
        });
        if inside {
            let d = sub(&foot, &p);
            return dot(&d, &d);
        }
    }
    (0..3)
        .map(|i| {
            let (a, b) = (&v[i], &v[(i + 1) % 3]);
            let e = sub(b, a);
            let ee = dot(&e, &e);
            let s = if ee.is_zero() {
                Q::zero()
            } else {
                (dot(&sub(&p, a), &e) / &ee).clamp(Q::zero(), Q::from_integer(1.into()))
            };
            let d = sub(&[0, 1, 2].map(|k| &a[k] + &e[k] * &s), &p);
            dot(&d, &d)
        })
        .min()
        .expect("three edges")
}

/// `sqrt(x)` (`x >= 0`) rounded to the nearest `f32`, ties to even, infinity past
/// `f32::MAX`: the largest `f32` whose square is at most `x`, by bisection over the
/// ordered bit patterns, then the midpoint above it compared by squares.
pub fn round_sqrt_f32(x: &Q) -> f32 {
    let (mut lo, mut hi) = (0u32, 0x7F80_0000u32);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        let r = rational(f32::from_bits(mid));
        if &r * &r <= *x {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let below = rational(f32::from_bits(lo));
    if &below * &below == *x {
        return f32::from_bits(lo);
    }
    let above =
        if lo + 1 == 0x7F80_0000 { Q::from_integer(BigInt::from(1) << 128) } else { rational(f32::from_bits(lo + 1)) };
    let mid = (below + above) / Q::from_integer(2.into());
    let up = match x.cmp(&(&mid * &mid)) {
        Ordering::Less => false,
        Ordering::Greater => true,
        Ordering::Equal => lo & 1 == 1,
    };
    match (up, lo + 1 == 0x7F80_0000) {
        (false, _) => f32::from_bits(lo),
        (true, true) => f32::INFINITY,
        (true, false) => f32::from_bits(lo + 1),
    }
}

/// The exact closest of `triangles` (input indices `ids`) to `p` and the distance
/// rounded to `f32`: the least exact squared distance, ties to the lowest index. Exact arithmetic runs on the triangles an `f64` screen cannot rule out
/// (within `1e-7` of the box's size of the `f64` least).
pub fn closest(p: [f32; 3], triangles: &[[[f32; 3]; 3]], ids: &[u32]) -> Option<(f32, u32)> {
    let pd = p.map(f64::from);
    let size = triangles.iter().flatten().flatten().fold(0f64, |m, &x| m.max((x as f64).abs())).max(1.0);
    let screen: Vec<f64> = triangles
        .iter()
        .map(|t| {
            let t = t.map(|v| glam::DVec3::from(v.map(f64::from)));
            (octrace_runtime::reference::nearest_on_triangle(pd.into(), &t) - glam::DVec3::from(pd)).length()
        })
        .collect();
    let least = screen.iter().copied().fold(f64::INFINITY, f64::min);
    let slack = 1e-7 * (least + size);
    let mut best: Option<(Q, u32)> = None;
    for (i, t) in triangles.iter().enumerate() {
        if screen[i] > least + slack {
            continue;
        }
        let d2 = squared_distance(p, *t);
        let id = ids[i];
        if best.as_ref().is_none_or(|(b, j)| d2 < *b || (d2 == *b && id < *j)) {
            best = Some((d2, id));
        }
    }
    best.map(|(d2, i)| (round_sqrt_f32(&d2), i))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The nearest `f32` to `x` by bisection over the ordered bit patterns and exact
    /// comparisons with the midpoints (slow, plainly right).
    fn round_by_bisection(x: &Q) -> Option<f32> {
        if x.is_negative() {
            return round_by_bisection(&-x).map(|r| -r);
        }
        let (mut lo, mut hi) = (0u32, 0x7F80_0000u32);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if rational(f32::from_bits(mid)) <= *x {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let below = rational(f32::from_bits(lo));
        let above = if lo + 1 == 0x7F80_0000 {
            Q::from_integer(BigInt::from(1) << 128)
        } else {
            rational(f32::from_bits(lo + 1))
        };
        let mid = (&below + &above) / Q::from_integer(2.into());
        let up = match x.cmp(&mid) {
            Ordering::Less => false,
            Ordering::Greater => true,
            Ordering::Equal => lo & 1 == 1 && below != *x,
        };
        match (up, lo + 1 == 0x7F80_0000) {
            (false, _) => Some(f32::from_bits(lo)),
            (true, true) => None,
            (true, false) => Some(f32::from_bits(lo + 1)),
        }
    }

    /// Quotients rounded by integer division are the bisection's, over every binade
    /// (subnormals and the overflow boundary included), exact values, midpoints
    /// (ties to even) and a hair either side of them.
    #[test]
    fn quotients_round_to_the_nearest_f32_ties_to_even() {
        let mut rng = hard::Rng::new(7);
        let mut cases: Vec<Q> = Vec::new();
        for _ in 0..3000 {
            let bits = (rng.next_u64() % 0x7F80_0000) as u32;
            let x = rational(f32::from_bits(bits));
            let next = if bits + 1 == 0x7F80_0000 {
                Q::from_integer(BigInt::from(1) << 128)
            } else {
                rational(f32::from_bits(bits + 1))
            };
            let mid = (&x + &next) / Q::from_integer(2.into());
            let hair = (&next - &x) / Q::from_integer(BigInt::from(1) << 40);
            cases.extend([x.clone(), mid.clone(), &mid + &hair, &mid - &hair]);
            // A quotient of odd integers near x.
            let den = BigInt::from(rng.next_u64() | 1);
            let num = (&x * Q::from_integer(den.clone())).round().to_integer();
            cases.push(Q::new(num, den));
        }
        for x in cases {
            for x in [x.clone(), -x] {
                assert_eq!(round_f32(&x), round_by_bisection(&x), "{x}");
            }
        }
        assert_eq!(round_quotient_f32(&BigInt::from(1), &(BigInt::from(1) << 200)), Some(0.0));
        // 0.75 and 1.5 of the least subnormal: up to it, and the tie to even.
        assert_eq!(round_quotient_f32(&BigInt::from(3), &(BigInt::from(1) << 151)), Some(f32::from_bits(1)));
        assert_eq!(round_quotient_f32(&BigInt::from(3), &(BigInt::from(1) << 150)), Some(f32::from_bits(2)));
    }

    /// The integers are the floats' exact values times `2^149`.
    #[test]
    fn floats_are_integers_at_two_to_the_149() {
        for x in
            [0.0f32, -0.0, 1.0, -1.5, f32::MAX, f32::MIN_POSITIVE, f32::from_bits(1), -f32::from_bits(0x7F_FFFF), 3e-39]
        {
            assert_eq!(Q::new(int(x), BigInt::from(1) << 149), rational(x), "{x}");
        }
    }
}
