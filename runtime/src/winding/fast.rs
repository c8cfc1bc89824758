//! Barill et al.'s fast rule eight clusters at a time, in `f32`.
//!
//! A node's children are one [`Group`]: each child's expansion as the coefficients of
//! polynomials in `y = c - p` (the dipole's three, the first correction's trace and
//! quadratic form, the second's linear and cubic forms), stored lane by lane, so that
//! a query evaluates all eight children in one vector loop and opens only the near
//! ones. The centres are kept as two `f32`s, `c ~ hi + lo` (`lo` the rounded rest,
//! some 48 bits in all: a scene far from the origin loses nothing), and `y` is
//! `(hi - p) + lo` for the `f32` point `p`: where `p` is near `hi`, the difference is
//! exact (Sterbenz), elsewhere it and the sum round once each, so `y` is within a
//! few `f32` roundings of its own length (as `c - p` in `f64` rounded once, in a
//! third of the instructions); everything after it is `f32`, which the
//! bound covers: each term is at most `A / R^2` times a small constant (`|N| <= A`,
//! `|M| <= A r`, `|T| <= A r^2`, `r < R`), and the arithmetic's rounding is a few
//! hundred `f32` epsilons of that, far inside the `2048 eps A / R^2` added to the
//! truncation bound.
//!
//! Near leaves' triangles are [`Block`]s of eight, their solid angles (Van Oosterom
//! and Strackee's formula, as [`solid_angle`]) in `f32` with an `atan2` of our own
//! (a polynomial, so that the eight lanes are one loop) and a bound each: the
//! formula's `det` and `den` are off by at most `64 eps |a||b||c|`, so the angle by at
//! most that over `max(|det|, |den|)`, plus the `atan2`'s own error. A triangle whose
//! bound is past [`EXACT_PAST`] (a point within rounding of its plane and its edges)
//! is summed in `f64` instead.
//!
//! Used where the tree's scale keeps every coefficient a normal `f32`
//! ([`Groups::of`] says `None` elsewhere, and queries take the `f64` path).

use super::{solid_angle, wide, Cluster, Sum, WindingTree};

/// Lanes a group: a node has at most eight children.
pub(super) const LANES: usize = 8;

/// A lane's child is a leaf: its first block below this bit, `count` triangles.
const LEAF_BIT: u32 = 1 << 31;
/// A lane with no child.
const EMPTY: u32 = u32::MAX;

/// A triangle's solid angle whose `f32` bound is past this (radians) is measured again
/// in `f64`.
const EXACT_PAST: f32 = 1e-5;

/// `atan(t) ~ t P(t^2)` on `[0, 1]`: fitted here (weighted least squares towards the
/// minimax), its largest error measured on 10^7 points 6.9e-8 with these `f32`
/// coefficients in `f64`, 1.5e-7 evaluated in `f32`.
const ATAN: [f32; 8] = [
    0.999_999_34,
    -0.333_298_6,
    0.199_465_66,
    -0.139_086_3,
    0.096_422_02,
    -0.055_912_38,
    0.021_862_997,
    -0.004_054_578,
];

/// The largest error of [`atan2`] in radians: the polynomial's, and the rounding of
/// the reduction (a quotient, a difference with `pi / 2` or `pi`), with room.
const ATAN2_ERROR: f32 = 2e-6;

/// `a b + c`: fused where `FUSED` (the batch compiled for x86-64-v3, whose
/// processors do it in one instruction and one rounding), a product and a sum where a
/// fused one could be a library call. Either is within the bounds, which count two
/// roundings a term.
#[inline(always)]
fn fma<const FUSED: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FUSED {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// `a . b`, [`fma`]'s way.
#[inline(always)]
fn dot3<const FUSED: bool>(a: [f32; 3], b: [f32; 3]) -> f32 {
    fma::<FUSED>(a[0], b[0], fma::<FUSED>(a[1], b[1], a[2] * b[2]))
}

/// `atan2(y, x)` in `f32` within [`ATAN2_ERROR`], branch-free (eight lanes in one
/// loop); 0 at the origin.
#[inline(always)]
fn atan2<const FUSED: bool>(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = if ay > ax { (ax, ay) } else { (ay, ax) };
    let t = if hi > 0.0 { lo / hi } else { 0.0 };
    let s = t * t;
    // Horner's rule written out: a loop here would keep the lanes' loop scalar.
    let c = &ATAN;
    let f = fma::<FUSED>;
    let r = f(f(f(f(f(f(f(c[7], s, c[6]), s, c[5]), s, c[4]), s, c[3]), s, c[2]), s, c[1]), s, c[0]);
    let mut r = r * t;
    r = if ay > ax { std::f32::consts::FRAC_PI_2 - r } else { r };
    r = if x < 0.0 { std::f32::consts::PI - r } else { r };
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// Lane `l`'s flag as bit `l`.
#[inline(always)]
fn bit_mask(flags: [bool; LANES]) -> u32 {
    // One byte a flag, 0 or 1: the multiply gathers bit 8 l into bit 56 + l.
    let bytes = u64::from_le_bytes(flags.map(u8::from));
    (bytes.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32
}

/// Lanes' values and bounds added up in `f64`, lane by lane (a horizontal sum a
/// group would sit on the walk's path from one group to the next).
#[derive(Clone, Copy, Debug, Default)]
struct Lanes {
    values: [f64; LANES],
    bounds: [f64; LANES],
}

impl Lanes {
    /// Adds the `f32` lanes: each sum in `f64` is exact to some `1e-16` of itself, far
    /// inside the lanes' bounds.
    #[inline(always)]
    fn add(&mut self, values: [f32; LANES], bounds: [f32; LANES]) {
        for l in 0..LANES {
            self.values[l] += values[l] as f64;
            self.bounds[l] += bounds[l] as f64;
        }
    }

    /// The lanes summed.
    fn total(&self) -> Sum {
        Sum { value: self.values.iter().sum(), bound: self.bounds.iter().sum() }
    }
}

/// Eight triangles of a leaf, `v[vertex][coordinate][lane]`: triangles `first..` of
/// the tree's, the lanes past a leaf's count zero.
#[derive(Clone, Copy, Debug)]
pub(super) struct Block {
    v: [[[f32; LANES]; 3]; 3],
    first: u32,
}

impl Block {
    /// The block of up to eight `triangles`, the tree's from `first` on.
    fn of(triangles: &[[[f32; 3]; 3]], first: u32) -> Block {
        let mut b = Block { v: [[[0.0; LANES]; 3]; 3], first };
        for (l, t) in triangles.iter().take(LANES).enumerate() {
            for (v, vertex) in t.iter().enumerate() {
                for c in 0..3 {
                    b.v[v][c][l] = vertex[c];
                }
            }
        }
        b
    }

    /// The solid angles at `p` of the block's first `count` triangles, added with
    /// their bounds to `sum`, and a mask of those to measure in `f64` instead.
    #[inline(always)]
    fn solid_angles<const FUSED: bool>(&self, p: [f32; 3], count: usize, sum: &mut Lanes) -> u32 {
        // The vertices from `p`, `d[vertex][coordinate][lane]`.
        let mut d = [[[0.0f32; LANES]; 3]; 3];
        for v in 0..3 {
            for c in 0..3 {
                for l in 0..LANES {
                    d[v][c][l] = self.v[v][c][l] - p[c];
                }
            }
        }
        let (mut values, mut bounds, mut again) = ([0.0f32; LANES], [0.0f32; LANES], [false; LANES]);
        for l in 0..LANES {
            let a = [d[0][0][l], d[0][1][l], d[0][2][l]];
            let b = [d[1][0][l], d[1][1][l], d[1][2][l]];
            let c = [d[2][0][l], d[2][1][l], d[2][2][l]];
            let (f, dot) = (fma::<FUSED>, dot3::<FUSED>);
            let (la, lb, lc) = (dot(a, a).sqrt(), dot(b, b).sqrt(), dot(c, c).sqrt());
            let cross = [f(b[1], c[2], -(b[2] * c[1])), f(b[2], c[0], -(b[0] * c[2])), f(b[0], c[1], -(b[1] * c[0]))];
            let det = dot(a, cross);
            let product = la * lb * lc;
            let den = f(dot(a, b), lc, f(dot(b, c), la, f(dot(c, a), lb, product)));
            let (adet, aden) = (det.abs(), den.abs());
            let off = 64.0 * f32::EPSILON * product / if adet > aden { adet } else { aden } + ATAN2_ERROR;
            // Past the limit (or NaN, at a vertex): in f64.
            let fine = off <= EXACT_PAST;
            again[l] = !fine;
            values[l] = if fine { 2.0 * atan2::<FUSED>(det, den) } else { 0.0 };
            bounds[l] = if fine { 2.0 * off } else { 0.0 };
        }
        let live = if count >= LANES { 0xff } else { (1u32 << count) - 1 };
        for l in 0..LANES {
            // Lanes past the count hold zeros (NaN where `p` is at the origin).
            values[l] = if l < count { values[l] } else { 0.0 };
            bounds[l] = if l < count { bounds[l] } else { 0.0 };
        }
        sum.add(values, bounds);
        bit_mask(again) & live
    }
}

/// The children of one node, coefficient by coefficient (see the module's text).
#[derive(Clone, Copy, Debug)]
pub(super) struct Group {
    /// The centres' `f32` parts, `hi`.
    centre: [[f32; LANES]; 3],
    /// What `hi` leaves of each centre, rounded: `lo`.
    rest: [[f32; LANES]; 3],
    /// Radii rounded up to `f32`.
    radius: [f32; LANES],
    area: [f32; LANES],
    /// `N`, the dipole's vector.
    n: [[f32; LANES]; 3],
    /// `tr M`.
    trace: [f32; LANES],
    /// `y^T M y` as `xx yy zz xy xz yz` coefficients.
    quad: [[f32; LANES]; 6],
    /// `2 u + v` of [`Cluster::far`]'s second correction, against `y`.
    linear: [[f32; LANES]; 3],
    /// `sum T_ijk y_i y_j y_k` as `xxx yyy zzz xxy xxz yyx yyz zzx zzy xyz` coefficients.
    cubic: [[f32; LANES]; 10],
    /// A group's index, `LEAF_BIT | first block`, or [`EMPTY`].
    child: [u32; LANES],
    /// A leaf's triangles.
    count: [u8; LANES],
    /// Bit `l` set where lane `l` has a child.
    live: u8,
}

/// Every node's group, the root's first, and the leaves' triangles in blocks.
#[derive(Clone, Debug, Default)]
pub(super) struct Groups {
    groups: Vec<Group>,
    blocks: Vec<Block>,
}

/// `x` in `f32`, rounded up.
fn up(x: f64) -> f32 {
    let y = x as f32;
    if (y as f64) < x {
        y.next_up()
    } else {
        y
    }
}

impl Group {
    fn empty() -> Group {
        Group {
            centre: [[0.0; LANES]; 3],
            rest: [[0.0; LANES]; 3],
            // Never far, never opened.
            radius: [f32::INFINITY; LANES],
            area: [0.0; LANES],
            n: [[0.0; LANES]; 3],
            trace: [0.0; LANES],
            quad: [[0.0; LANES]; 6],
            linear: [[0.0; LANES]; 3],
            cubic: [[0.0; LANES]; 10],
            child: [EMPTY; LANES],
            count: [0; LANES],
            live: 0,
        }
    }

    /// Lane `l` from cluster `c`'s moments.
    fn set(&mut self, l: usize, c: &Cluster) {
        let (m, t) = (&c.m, &c.t);
        for k in 0..3 {
            let hi = c.centre[k] as f32;
            self.centre[k][l] = hi;
            self.rest[k][l] = (c.centre[k] - hi as f64) as f32;
            self.n[k][l] = c.n[k] as f32;
        }
        self.radius[l] = up(c.radius);
        self.area[l] = up(c.area);
        self.trace[l] = (m[0][0] + m[1][1] + m[2][2]) as f32;
        let quad = [m[0][0], m[1][1], m[2][2], m[0][1] + m[1][0], m[0][2] + m[2][0], m[1][2] + m[2][1]];
        let u = [t[0][0] + t[1][3] + t[2][4], t[0][3] + t[1][1] + t[2][5], t[0][4] + t[1][5] + t[2][2]];
        let v = [0, 1, 2].map(|i| t[i][0] + t[i][1] + t[i][2]);
        let cubic = [
            t[0][0],
            t[1][1],
            t[2][2],
            2.0 * t[0][3] + t[1][0],
            2.0 * t[0][4] + t[2][0],
            2.0 * t[1][3] + t[0][1],
            2.0 * t[1][5] + t[2][1],
            2.0 * t[2][4] + t[0][2],
            2.0 * t[2][5] + t[1][2],
            2.0 * (t[0][5] + t[1][4] + t[2][3]),
        ];
        for k in 0..6 {
            self.quad[k][l] = quad[k] as f32;
        }
        for k in 0..3 {
            self.linear[k][l] = (2.0 * u[k] + v[k]) as f32;
        }
        for k in 0..10 {
            self.cubic[k][l] = cubic[k] as f32;
        }
    }

    /// Every coefficient a normal `f32` or zero, every radius finite.
    fn representable(&self) -> bool {
        let fine = |x: f32| x == 0.0 || x.is_normal() && x.abs() < 1e30;
        (0..LANES).all(|l| self.child[l] == EMPTY || self.radius[l] < 1e30)
            && self.area.iter().chain(&self.trace).copied().all(fine)
            && self.n.iter().chain(&self.linear).flatten().copied().all(fine)
            && self.quad.iter().flatten().chain(self.cubic.iter().flatten()).copied().all(fine)
    }

    /// The far children's expansions at `p` added with their bounds to `sum`, and a
    /// mask of the near ones (within `beta` times their radius, to be opened).
    ///
    /// The mask is found from squared distances (no square root on the walk's path
    /// from one group to the next): far is past `beta >= 1` radii and the squared
    /// distance past the radius's by a margin that keeps `gap` positive.
    #[inline(always)]
    fn evaluate<const FUSED: bool>(&self, p: [f32; 3], beta: f32, sum: &mut Lanes) -> u32 {
        let mut y = [[0.0f32; LANES]; 3];
        for k in 0..3 {
            for l in 0..LANES {
                y[k][l] = (self.centre[k][l] - p[k]) + self.rest[k][l];
            }
        }
        let (mut values, mut bounds, mut far) = ([0.0f32; LANES], [0.0f32; LANES], [false; LANES]);
        let (f, dot) = (fma::<FUSED>, dot3::<FUSED>);
        for l in 0..LANES {
            let (x, yy, z) = (y[0][l], y[1][l], y[2][l]);
            let r2 = dot([x, yy, z], [x, yy, z]);
            let radius = self.radius[l];
            let reach = beta * radius;
            // `r2 (1 - 4e-6) > radius^2` leaves `dist (1 - 1e-6) > radius` whatever
            // the roundings (each some 1e-7).
            let near = !(r2 > reach * reach && r2 * (1.0 - 4e-6) > radius * radius);
            let dist = r2.sqrt();
            let gap = dist * (1.0 - 1e-6) - radius;
            let inv1 = 1.0 / dist;
            let inv2 = inv1 * inv1;
            let inv3 = inv2 * inv1;
            let inv5 = inv3 * inv2;
            let inv7 = inv5 * inv2;
            let n = [self.n[0][l], self.n[1][l], self.n[2][l]];
            let dipole = dot(n, [x, yy, z]) * inv3;
            // `xx yy zz xy xz yz` as x (xx x + xy y + xz z) + y (yy y + yz z) + zz z z.
            let q = &self.quad;
            let quad =
                f(x, dot([q[0][l], q[3][l], q[4][l]], [x, yy, z]), f(yy, f(q[1][l], yy, q[5][l] * z), q[2][l] * z * z));
            let first = f(-3.0 * quad, inv5, self.trace[l] * inv3);
            // `xxx yyy zzz xxy xxz yyx yyz zzx zzy xyz`, by the factor each term
            // takes first: x (x (xxx x + xxy y + xxz z) + xyz y z) + y y (yyy y + yyx
            // x + yyz z) + z z (zzz z + zzx x + zzy y).
            let c = &self.cubic;
            let xs = f(x, dot([c[0][l], c[3][l], c[4][l]], [x, yy, z]), c[9][l] * yy * z);
            let ys = yy * dot([c[1][l], c[5][l], c[6][l]], [yy, x, z]);
            let zs = z * dot([c[2][l], c[7][l], c[8][l]], [z, x, yy]);
            let cubic = f(x, xs, f(yy, ys, z * zs));
            let linear = dot([self.linear[0][l], self.linear[1][l], self.linear[2][l]], [x, yy, z]);
            let second = f(-1.5 * linear, inv5, 7.5 * cubic * inv7);
            let area = self.area[l];
            let over = 1.0 / gap;
            let ratio = radius * over;
            let truncation = 4.0 * area * over * over * ratio * ratio * ratio;
            let rounding = 2048.0 * f32::EPSILON * area * inv2;
            far[l] = !near;
            values[l] = if near { 0.0 } else { dipole + first + second };
            bounds[l] = if near { 0.0 } else { truncation + rounding };
        }
        sum.add(values, bounds);
        !bit_mask(far) & self.live as u32
    }
}

impl Groups {
    /// The groups of `tree`'s nodes, or `None` where a coefficient is not a normal
    /// `f32` (a scene so small or so large that `f32` would lose it).
    pub(super) fn of(tree: &WindingTree) -> Option<Groups> {
        let root = tree.root.as_ref()?;
        if root.leaf || tree.triangles.len() >= LEAF_BIT as usize {
            return None;
        }
        let mut groups = Groups::default();
        groups.add(tree, root)?;
        Some(groups)
    }

    /// The group of `node`'s children (pushed with its descendants'): its index.
    fn add(&mut self, tree: &WindingTree, node: &Cluster) -> Option<u32> {
        let at = self.groups.len();
        self.groups.push(Group::empty());
        let mut group = Group::empty();
        let (first, count) = (node.first as usize, node.count as usize);
        if count > LANES {
            return None;
        }
        for (l, child) in tree.nodes[first..first + count].iter().enumerate() {
            group.set(l, child);
            group.live |= 1 << l;
            group.child[l] = if child.leaf {
                group.count[l] = child.count as u8;
                let block = LEAF_BIT | self.blocks.len() as u32;
                let (first, count) = (child.first as usize, child.count as usize);
                for (k, eight) in tree.triangles[first..first + count].chunks(LANES).enumerate() {
                    self.blocks.push(Block::of(eight, (first + k * LANES) as u32));
                }
                block
            } else {
                self.add(tree, child)?
            };
        }
        if !group.representable() {
            return None;
        }
        self.groups[at] = group;
        Some(at as u32)
    }

    /// The bytes the groups take.
    pub(super) fn bytes(&self) -> usize {
        self.groups.len() * std::mem::size_of::<Group>() + self.blocks.len() * std::mem::size_of::<Block>()
    }

    /// Barill's rule at each of `K` points over the root's descendants (the root
    /// itself is near): the far clusters' expansions and the near leaves' triangles,
    /// summed.
    ///
    /// The points' walks take turns, a group each: one walk's next group hangs on the
    /// group before it (the mask that says which children to open, some 60 cycles
    /// from the group's first load), so the processor works on the other walks'
    /// groups meanwhile. A walk takes its groups first in, first out (the next group's
    /// index was written long before), and its answer does not depend on the others'
    /// (its sums in its own order).
    #[inline(always)]
    pub(super) fn sum<const K: usize, const FUSED: bool>(
        &self,
        tree: &WindingTree,
        queues: &mut [Vec<u32>; K],
        points: [[f32; 3]; K],
        beta: f32,
    ) -> [Sum; K] {
        let (mut lanes, mut exact, mut next) = ([Lanes::default(); K], [0.0; K], [0; K]);
        for queue in queues.iter_mut() {
            queue.clear();
            queue.push(0);
        }
        let mut busy = true;
        while busy {
            busy = false;
            for k in 0..K {
                let Some(&g) = queues[k].get(next[k]) else { continue };
                busy = true;
                next[k] += 1;
                exact[k] += self.open::<FUSED>(tree, g, &mut queues[k], points[k], beta, &mut lanes[k]);
            }
        }
        std::array::from_fn(|k| {
            let mut sum = lanes[k].total();
            sum.value += exact[k];
            sum
        })
    }

    /// Group `g` at `p`: its far children's expansions and its near leaves' blocks
    /// added to `lanes`, its near nodes' groups queued; the solid angles measured in
    /// `f64`, summed.
    #[inline(always)]
    fn open<const FUSED: bool>(
        &self,
        tree: &WindingTree,
        g: u32,
        queue: &mut Vec<u32>,
        p: [f32; 3],
        beta: f32,
        lanes: &mut Lanes,
    ) -> f64 {
        let group = &self.groups[g as usize];
        let mut near = group.evaluate::<FUSED>(p, beta, lanes);
        let mut exact = 0.0;
        while near != 0 {
            let l = near.trailing_zeros() as usize;
            near &= near - 1;
            let child = group.child[l];
            if child & LEAF_BIT == 0 {
                queue.push(child);
                continue;
            }
            let first = (child & !LEAF_BIT) as usize;
            let count = group.count[l] as usize;
            for (k, block) in self.blocks[first..first + count.div_ceil(LANES)].iter().enumerate() {
                let mut again = block.solid_angles::<FUSED>(p, count - k * LANES, lanes);
                while again != 0 {
                    let t = block.first as usize + again.trailing_zeros() as usize;
                    again &= again - 1;
                    exact += solid_angle(wide(p), &tree.triangles[t]);
                }
            }
        }
        exact
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use octrace_bake::procedural::SplitMix;

    /// A lane's `f32` expansion agrees with [`Cluster::far`]'s `f64` one within the
    /// rounding term of its bound, far from the origin too.
    #[test]
    fn a_lane_is_the_clusters_expansion() {
        let mut rng = SplitMix(7);
        let mut unit = move || rng.unit();
        for offset in [0.0f32, 1e5] {
            let triangles: Vec<[[f32; 3]; 3]> =
                (0..200).map(|_| [0; 3].map(|_| [offset + unit(), unit(), unit()])).collect();
            let tree = WindingTree::new(triangles).unwrap();
            assert!(Groups::of(&tree).is_some());
            let root = tree.root.unwrap();
            let parents = std::iter::once(&root).chain(&tree.nodes).filter(|c| !c.leaf);
            for parent in parents {
                let children = &tree.nodes[parent.first as usize..(parent.first + parent.count) as usize];
                let mut group = Group::empty();
                for (l, c) in children.iter().enumerate() {
                    group.set(l, c);
                    group.child[l] = 0;
                    group.live |= 1 << l;
                }
                for _ in 0..50 {
                    let p32 = [offset + 4.0 * unit() - 1.5, 4.0 * unit() - 1.5, 4.0 * unit() - 1.5];
                    let p = wide(p32);
                    let (mut lanes, mut fused) = (Lanes::default(), Lanes::default());
                    let near = group.evaluate::<false>(p32, 1.0, &mut lanes);
                    assert_eq!(group.evaluate::<true>(p32, 1.0, &mut fused), near);
                    let (mut want, mut rounding) = (0.0, 0.0);
                    for (l, c) in children.iter().enumerate() {
                        if near >> l & 1 == 0 {
                            let y = crate::cpu::sub(c.centre, p);
                            want += c.far(p).0;
                            rounding += 2048.0 * f32::EPSILON as f64 * c.area / crate::cpu::dot(y, y);
                        }
                    }
                    for sum in [lanes.total(), fused.total()] {
                        assert!((sum.value - want).abs() <= rounding, "{p:?}: {sum:?} against {want}");
                        assert!(sum.bound >= rounding);
                    }
                }
            }
        }
    }

    /// The polynomial `atan2` within its stated error of the library's, in every
    /// quadrant, on the axes and at the origin.
    #[test]
    fn atan2_is_within_its_error() {
        let mut rng = SplitMix(11);
        let mut unit = move || rng.unit() * 2.0 - 1.0;
        let mut cases: Vec<(f32, f32)> = (0..200_000).map(|_| (unit() * 1e3, unit() * 1e-2)).collect();
        cases.extend((0..200_000).map(|_| (unit(), unit())));
        cases.extend([(0.0, 1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (1.0, 1.0), (-1.0, -1.0), (0.0, 0.0)]);
        for (y, x) in cases {
            let want = if x == 0.0 && y == 0.0 { 0.0 } else { (y as f64).atan2(x as f64) };
            for got in [atan2::<false>(y, x) as f64, atan2::<true>(y, x) as f64] {
                assert!((got - want).abs() <= ATAN2_ERROR as f64, "atan2({y}, {x}): {got} against {want}");
            }
        }
    }

    /// A block's `f32` solid angles within their bounds of the `f64` formula's, the
    /// lanes it cannot answer flagged: points near the triangles' planes, edges and
    /// vertices, and far from the origin.
    #[test]
    fn a_blocks_solid_angles_hold_their_bounds() {
        let mut rng = SplitMix(5);
        let mut unit = move || rng.unit();
        let (mut flagged, mut answered) = (0, 0);
        for offset in [0.0f32, 1e4] {
            let triangles: Vec<[[f32; 3]; 3]> =
                (0..8).map(|_| [0; 3].map(|_| [offset + unit(), unit(), unit() * 0.1])).collect();
            let block = Block::of(&triangles, 0);
            for k in 0..4000 {
                let p = match k % 4 {
                    // Near a vertex, near an edge's middle, in or near the plane, anywhere.
                    0 => triangles[k % 8][k % 3].map(|c| c + (unit() - 0.5) * 1e-4),
                    1 => {
                        let t = &triangles[k % 8];
                        [0, 1, 2].map(|c| (t[0][c] + t[1][c]) * 0.5 + (unit() - 0.5) * 1e-5)
                    }
                    2 => [offset + unit(), unit(), (unit() - 0.5) * 1e-3],
                    _ => [offset + unit() * 3.0 - 1.0, unit() * 3.0 - 1.0, unit() * 3.0 - 1.0],
                };
                let count = 1 + k % 8;
                for fused in [false, true] {
                    let mut lanes = Lanes::default();
                    let exact = if fused {
                        block.solid_angles::<true>(p, count, &mut lanes)
                    } else {
                        block.solid_angles::<false>(p, count, &mut lanes)
                    };
                    let sum = lanes.total();
                    let want: f64 =
                        (0..count).filter(|l| exact >> l & 1 == 0).map(|l| solid_angle(wide(p), &triangles[l])).sum();
                    assert!(exact >> count == 0, "{p:?}: a lane past the count flagged");
                    assert!((sum.value - want).abs() <= sum.bound + 1e-12, "{p:?}: {sum:?} against {want}");
                    flagged += exact.count_ones();
                    answered += count as u32 - exact.count_ones();
                }
            }
        }
        assert!(flagged > 0 && answered > 2 * flagged, "{flagged} flagged, {answered} answered");
    }
}
