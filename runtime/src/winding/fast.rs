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
//! truncation bound. Triangles of near leaves are summed in `f64` as before.
//!
//! Used where the tree's scale keeps every coefficient a normal `f32`
//! ([`Groups::of`] says `None` elsewhere, and queries take the `f64` path).

use super::{solid_angle, Cluster, Sum, WindingTree};

/// Lanes a group: a node has at most eight children.
pub(super) const LANES: usize = 8;

/// A lane's child is a leaf: its first triangle below this bit, `count` triangles.
const LEAF_BIT: u32 = 1 << 31;
/// A lane with no child.
const EMPTY: u32 = u32::MAX;

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
    /// A group's index, `LEAF_BIT | first triangle`, or [`EMPTY`].
    child: [u32; LANES],
    /// A leaf's triangles.
    count: [u8; LANES],
}

/// Every node's group, the root's first.
#[derive(Clone, Debug, Default)]
pub(super) struct Groups(Vec<Group>);

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
            let inv2 = 1.0 / r2;
            let inv3 = inv2 / dist;
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
            let ratio = radius / gap;
            let truncation = 4.0 * area / (gap * gap) * ratio * ratio * ratio;
            let rounding = 2048.0 * f32::EPSILON * area * inv2;
            far[l] = !near;
            values[l] = if near { 0.0 } else { dipole + first + second };
            bounds[l] = if near { 0.0 } else { truncation + rounding };
        }
        let mut sum = Sum::default();
        for l in 0..LANES {
            sum.add(values[l] as f64, bounds[l] as f64);
        }
        let mut near = 0u32;
        for l in 0..LANES {
            near |= ((!far[l] && self.child[l] != EMPTY) as u32) << l;
        }
        (sum, near)
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
        let mut groups = Groups(Vec::new());
        groups.add(tree, root)?;
        Some(groups)
    }

    /// The group of `node`'s children (pushed with its descendants'): its index.
    fn add(&mut self, tree: &WindingTree, node: &Cluster) -> Option<u32> {
        let at = self.0.len();
        self.0.push(Group::empty());
        let mut group = Group::empty();
        let (first, count) = (node.first as usize, node.count as usize);
        if count > LANES {
            return None;
        }
        for (l, child) in tree.nodes[first..first + count].iter().enumerate() {
            group.set(l, child);
            group.child[l] = if child.leaf {
                group.count[l] = child.count as u8;
                LEAF_BIT | child.first
            } else {
                self.add(tree, child)?
            };
        }
        if !group.representable() {
            return None;
        }
        self.0[at] = group;
        Some(at as u32)
    }

    /// The bytes the groups take.
    pub(super) fn bytes(&self) -> usize {
        self.0.len() * std::mem::size_of::<Group>()
    }

    /// Barill's rule at `p` over the root's descendants (the root itself is near):
    /// the far clusters' expansions and the near leaves' triangles, summed.
    #[inline(always)]
    pub(super) fn sum(&self, tree: &WindingTree, stack: &mut Vec<u32>, p: [f64; 3], beta: f32) -> Sum {
        stack.clear();
        stack.push(0);
        let mut sum = Sum::default();
        while let Some(g) = stack.pop() {
            let group = &self.0[g as usize];
            let (far, mut near) = group.evaluate(p, beta);
            sum.add(far.value, far.bound);
            while near != 0 {
                let l = near.trailing_zeros() as usize;
                near &= near - 1;
                let child = group.child[l];
                if child & LEAF_BIT != 0 {
                    let first = (child & !LEAF_BIT) as usize;
                    let triangles = &tree.triangles[first..first + group.count[l] as usize];
                    sum.value += triangles.iter().map(|t| solid_angle(p, t)).sum::<f64>();
                } else {
                    stack.push(child);
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

    /// A lane's `f32` expansion agrees with [`Cluster::far`]'s `f64` one within the
    /// rounding term of its bound, far from the origin too.
    #[test]
    fn a_lane_is_the_clusters_expansion() {
        let mut state = 7u64;
        let mut unit = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
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
}
