//! Barill et al.'s fast rule eight clusters at a time, in `f32`.
//!
//! A node's children are one [`Group`]: each child's expansion as the coefficients of
//! polynomials in `y = c - p` (the dipole's three, the first correction's trace and
//! quadratic form, the second's linear and cubic forms), stored lane by lane, so that
//! a query evaluates all eight children in one vector loop and opens only the near
//! ones. `y` is taken in `f64` (the centres are kept in `f64`: a scene far from the
//! origin loses nothing) and rounded once; everything after it is `f32`, which the
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

use super::{solid_angle, Cluster, Sum, WindingTree};

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

/// `atan2(y, x)` in `f32` within [`ATAN2_ERROR`], branch-free (eight lanes in one
/// loop); 0 at the origin.
#[inline(always)]
fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = if ay > ax { (ax, ay) } else { (ay, ax) };
    let t = if hi > 0.0 { lo / hi } else { 0.0 };
    let s = t * t;
    // Horner's rule written out: a loop here would keep the lanes' loop scalar.
    let c = &ATAN;
    let r = ((((((c[7] * s + c[6]) * s + c[5]) * s + c[4]) * s + c[3]) * s + c[2]) * s + c[1]) * s + c[0];
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

/// The lanes' values and bounds summed pairwise in `f32`: three roundings of at most
/// `eps` each of the lanes' magnitudes, far inside their bounds (a lane's value is at
/// most some `30 A / R^2`, its rounding term `2048 eps A / R^2`).
#[inline(always)]
fn lane_sum(mut values: [f32; LANES], mut bounds: [f32; LANES]) -> Sum {
    let mut half = LANES / 2;
    while half > 0 {
        for l in 0..half {
            values[l] += values[l + half];
            bounds[l] += bounds[l + half];
        }
        half /= 2;
    }
    Sum { value: values[0] as f64, bound: bounds[0] as f64 * (1.0 + 1e-6) }
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

    /// The solid angles at `p` of the block's first `count` triangles, summed with
    /// their bounds, and a mask of those to measure in `f64` instead.
    #[inline(always)]
    fn solid_angles(&self, p: [f32; 3], count: usize) -> (Sum, u32) {
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
            let la = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            let lb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
            let lc = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            let det = a[0] * (b[1] * c[2] - b[2] * c[1])
                + a[1] * (b[2] * c[0] - b[0] * c[2])
                + a[2] * (b[0] * c[1] - b[1] * c[0]);
            let product = la * lb * lc;
            let ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let bc = b[0] * c[0] + b[1] * c[1] + b[2] * c[2];
            let ca = c[0] * a[0] + c[1] * a[1] + c[2] * a[2];
            let den = product + ab * lc + bc * la + ca * lb;
            let (adet, aden) = (det.abs(), den.abs());
            let off = 64.0 * f32::EPSILON * product / if adet > aden { adet } else { aden } + ATAN2_ERROR;
            // Past the limit (or NaN, at a vertex): in f64.
            let fine = off <= EXACT_PAST;
            again[l] = !fine;
            values[l] = if fine { 2.0 * atan2(det, den) } else { 0.0 };
            bounds[l] = if fine { 2.0 * off } else { 0.0 };
        }
        let live = if count >= LANES { 0xff } else { (1u32 << count) - 1 };
        for l in 0..LANES {
            // Lanes past the count hold zeros (NaN where `p` is at the origin).
            values[l] = if l < count { values[l] } else { 0.0 };
            bounds[l] = if l < count { bounds[l] } else { 0.0 };
        }
        (lane_sum(values, bounds), bit_mask(again) & live)
    }
}

/// The children of one node, coefficient by coefficient (see the module's text).
#[derive(Clone, Copy, Debug)]
pub(super) struct Group {
    centre: [[f64; LANES]; 3],
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
            self.centre[k][l] = c.centre[k];
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

    /// The far children's expansions at `p` summed with their bounds, and a mask of
    /// the near ones (within `beta` times their radius, to be opened).
    #[inline(always)]
    fn evaluate(&self, p: [f64; 3], beta: f32) -> (Sum, u32) {
        let mut y = [[0.0f32; LANES]; 3];
        for k in 0..3 {
            for l in 0..LANES {
                y[k][l] = (self.centre[k][l] - p[k]) as f32;
            }
        }
        let (mut values, mut bounds, mut far) = ([0.0f32; LANES], [0.0f32; LANES], [false; LANES]);
        for l in 0..LANES {
            let (x, yy, z) = (y[0][l], y[1][l], y[2][l]);
            let r2 = x * x + yy * yy + z * z;
            let dist = r2.sqrt();
            let radius = self.radius[l];
            let reach = beta * radius;
            // The distance's rounding is far inside this margin.
            let gap = dist * (1.0 - 1e-6) - radius;
            let near = !(r2 > reach * reach && gap > 0.0);
            let inv1 = 1.0 / dist;
            let inv2 = inv1 * inv1;
            let inv3 = inv2 * inv1;
            let inv5 = inv3 * inv2;
            let inv7 = inv5 * inv2;
            let dipole = (self.n[0][l] * x + self.n[1][l] * yy + self.n[2][l] * z) * inv3;
            let q = &self.quad;
            let quad = q[0][l] * x * x
                + q[1][l] * yy * yy
                + q[2][l] * z * z
                + q[3][l] * x * yy
                + q[4][l] * x * z
                + q[5][l] * yy * z;
            let first = self.trace[l] * inv3 - 3.0 * quad * inv5;
            let c = &self.cubic;
            let cubic = x * (c[0][l] * x * x + c[3][l] * x * yy + c[4][l] * x * z + c[9][l] * yy * z)
                + yy * (c[1][l] * yy * yy + c[5][l] * x * yy + c[6][l] * yy * z)
                + z * (c[2][l] * z * z + c[7][l] * x * z + c[8][l] * yy * z);
            let linear = self.linear[0][l] * x + self.linear[1][l] * yy + self.linear[2][l] * z;
            let second = -1.5 * linear * inv5 + 7.5 * cubic * inv7;
            let area = self.area[l];
            let over = 1.0 / gap;
            let ratio = radius * over;
            let truncation = 4.0 * area * over * over * ratio * ratio * ratio;
            let rounding = 2048.0 * f32::EPSILON * area * inv2;
            far[l] = !near;
            values[l] = if near { 0.0 } else { dipole + first + second };
            bounds[l] = if near { 0.0 } else { truncation + rounding };
        }
        (lane_sum(values, bounds), !bit_mask(far) & self.live as u32)
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

    /// Barill's rule at `p` over the root's descendants (the root itself is near):
    /// the far clusters' expansions and the near leaves' triangles, summed.
    #[inline(always)]
    pub(super) fn sum(&self, tree: &WindingTree, stack: &mut Vec<u32>, p: [f64; 3], beta: f32) -> Sum {
        stack.clear();
        stack.push(0);
        let mut sum = Sum::default();
        let p32 = p.map(|c| c as f32);
        while let Some(g) = stack.pop() {
            let group = &self.groups[g as usize];
            let (far, mut near) = group.evaluate(p, beta);
            sum.add(far.value, far.bound);
            while near != 0 {
                let l = near.trailing_zeros() as usize;
                near &= near - 1;
                let child = group.child[l];
                if child & LEAF_BIT == 0 {
                    stack.push(child);
                    continue;
                }
                let first = (child & !LEAF_BIT) as usize;
                let count = group.count[l] as usize;
                for (k, block) in self.blocks[first..first + count.div_ceil(LANES)].iter().enumerate() {
                    let (angles, mut exact) = block.solid_angles(p32, count - k * LANES);
                    sum.add(angles.value, angles.bound);
                    while exact != 0 {
                        let t = block.first as usize + exact.trailing_zeros() as usize;
                        exact &= exact - 1;
                        sum.value += solid_angle(p, &tree.triangles[t]);
                    }
                }
            }
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::winding::wide;
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
                    let p = wide([offset + 4.0 * unit() - 1.5, 4.0 * unit() - 1.5, 4.0 * unit() - 1.5]);
                    let (sum, near) = group.evaluate(p, 1.0);
                    let (mut want, mut rounding) = (0.0, 0.0);
                    for (l, c) in children.iter().enumerate() {
                        if near >> l & 1 == 0 {
                            let y = crate::cpu::sub(c.centre, p);
                            want += c.far(p).0;
                            rounding += 2048.0 * f32::EPSILON as f64 * c.area / crate::cpu::dot(y, y);
                        }
                    }
                    assert!((sum.value - want).abs() <= rounding, "{p:?}: {sum:?} against {want}");
                    assert!(sum.bound >= rounding);
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
            let got = atan2(y, x) as f64;
            assert!((got - want).abs() <= ATAN2_ERROR as f64, "atan2({y}, {x}): {got} against {want}");
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
                let (sum, exact) = block.solid_angles(p, count);
                let want: f64 =
                    (0..count).filter(|l| exact >> l & 1 == 0).map(|l| solid_angle(wide(p), &triangles[l])).sum();
                assert!(exact >> count == 0, "{p:?}: a lane past the count flagged");
                assert!((sum.value - want).abs() <= sum.bound + 1e-12, "{p:?}: {sum:?} against {want}");
                flagged += exact.count_ones();
                answered += count as u32 - exact.count_ones();
            }
        }
        assert!(flagged > 0 && answered > 2 * flagged, "{flagged} flagged, {answered} answered");
    }
}
