//! The top level: a binary BVH over the instances' world boxes, built by binned SAH
//! (the BVH seed's construction, with boxes for primitives) and refit in place when
//! only placements change.

/// An instance's world box, `f32`, rounded outward.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Aabb {
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { lo: [f32::INFINITY; 3], hi: [f32::NEG_INFINITY; 3] };

    fn grow(&mut self, b: &Aabb) {
        // Plain comparisons (boxes are finite, or the empty box's infinities): NaN-aware
        // `min` and `max` cost the build a third of its time.
        for k in 0..3 {
            self.lo[k] = if b.lo[k] < self.lo[k] { b.lo[k] } else { self.lo[k] };
            self.hi[k] = if b.hi[k] > self.hi[k] { b.hi[k] } else { self.hi[k] };
        }
    }

    fn area(&self) -> f32 {
        let e = [0, 1, 2].map(|k| (self.hi[k] - self.lo[k]).max(0.0));
        e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
    }

    fn centre(&self, k: usize) -> f32 {
        0.5 * self.lo[k] + 0.5 * self.hi[k]
    }
}

/// A node: its box, and either two children (`first`, `first + 1`; `count` 0) or
/// `count` instances (`refs[first..first + count]`).
#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    first: u32,
    count: u32,
}

/// The BVH over the live instances.
#[derive(Clone, Debug, Default)]
pub(super) struct Top {
    nodes: Vec<Node>,
    refs: Vec<u32>,
    /// The SAH cost when last built (refits are compared with it).
    built_cost: f32,
}

/// The walk's stack: 64 entries in place, more on the heap (a tree as deep as a
/// degenerate layout makes it).
struct Stack {
    fixed: [u32; 64],
    len: usize,
    spill: Vec<u32>,
}

impl Stack {
    #[inline]
    fn push(&mut self, x: u32) {
        if self.len < self.fixed.len() {
            self.fixed[self.len] = x;
            self.len += 1;
        } else {
            self.spill.push(x);
        }
    }

    #[inline]
    fn pop(&mut self) -> Option<u32> {
        if let Some(x) = self.spill.pop() {
            return Some(x);
        }
        self.len = self.len.checked_sub(1)?;
        Some(self.fixed[self.len])
    }
}

/// The bins of the SAH sweep.
const BINS: usize = 16;

impl Top {
    /// The BVH over the instances `ids`, whose boxes are `boxes[id]`.
    pub fn build(boxes: &[Aabb], ids: Vec<u32>) -> Top {
        if ids.is_empty() {
            return Top::default();
        }
        // Boxes beside their ids, so that the splits read and move them in order.
        let mut items: Vec<(Aabb, u32)> = ids.iter().map(|&id| (boxes[id as usize], id)).collect();
        let mut nodes = Vec::with_capacity(2 * ids.len());
        nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
        let mut work = vec![(0usize, 0usize, items.len())];
        while let Some((at, start, end)) = work.pop() {
            let mut bounds = Aabb::EMPTY;
            let mut centres = Aabb::EMPTY;
            for (b, _) in &items[start..end] {
                bounds.grow(b);
                let c = [0, 1, 2].map(|k| b.centre(k));
                centres.grow(&Aabb { lo: c, hi: c });
            }
            nodes[at].bounds = bounds;
            if end - start == 1 {
                nodes[at].first = start as u32;
                nodes[at].count = 1;
                continue;
            }
            let mid = split(&mut items[start..end], &centres) + start;
            let first = nodes.len();
            nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
            nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
            nodes[at].first = first as u32;
            work.push((first + 1, mid, end));
            work.push((first, start, mid));
        }
        let refs = items.into_iter().map(|(_, id)| id).collect();
        let mut top = Top { nodes, refs, built_cost: 0.0 };
        top.built_cost = top.cost();
        top
    }

    /// The boxes made anew from `boxes`, the tree's shape kept. Returns whether the
    /// tree is still good: its SAH cost within twice its build's (else it should be
    /// built again).
    pub fn refit(&mut self, boxes: &[Aabb]) -> bool {
        // Children come after their parents: from the last node back.
        for at in (0..self.nodes.len()).rev() {
            let Node { first, count, .. } = self.nodes[at];
            let mut b = Aabb::EMPTY;
            if count > 0 {
                for &id in &self.refs[first as usize..(first + count) as usize] {
                    b.grow(&boxes[id as usize]);
                }
            } else {
                b = self.nodes[first as usize].bounds;
                b.grow(&self.nodes[first as usize + 1].bounds);
            }
            self.nodes[at].bounds = b;
        }
        self.cost() <= 2.0 * self.built_cost
    }

    /// The SAH cost: every node's area over the root's (inner nodes one unit, an
    /// instance ten: a whole octree's walk against a box).
    fn cost(&self) -> f32 {
        let Some(root) = self.nodes.first() else { return 0.0 };
        let whole = root.bounds.area().max(f32::MIN_POSITIVE);
        self.nodes.iter().map(|n| n.bounds.area() / whole * if n.count > 0 { 10.0 * n.count as f32 } else { 1.0 }).sum()
    }

    /// The instances whose boxes the ray `origin + t dir` meets within
    /// `[tmin, tmax]`, nearest box first: `visit(id, near, &mut tmax)` for each
    /// (`near` where the ray enters the box), which may lower `tmax` (boxes past it
    /// are then skipped) and returns `true` to stop.
    #[inline]
    pub fn walk(
        &self,
        origin: [f32; 3],
        dir: [f32; 3],
        tmin: f32,
        mut tmax: f32,
        mut visit: impl FnMut(u32, f32, &mut f32) -> bool,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let inv = dir.map(|d| 1.0 / d);
        let enter = |b: &Aabb, tmax: f32| -> Option<f32> {
            let (mut near, mut far) = (tmin, tmax);
            for k in 0..3 {
                // A zero direction gives infinities, and NaN where the origin lies on
                // the slab's plane: `min` and `max` then take the other operand, so
                // that slab does not narrow the interval.
                let t0 = (b.lo[k] - origin[k]) * inv[k];
                let t1 = (b.hi[k] - origin[k]) * inv[k];
                near = near.max(t0.min(t1));
                far = far.min(t0.max(t1));
            }
            // Each slab distance is within three roundings of its exact value: a
            // relative margin keeps a grazed box (Ize 2013, "Robust BVH ray traversal").
            (near <= far + far.abs() * 4.0 * f32::EPSILON).then_some(near)
        };
        let mut stack = Stack { fixed: [0; 64], len: 0, spill: Vec::new() };
        let Some(mut at_near) = enter(&self.nodes[0].bounds, tmax) else { return };
        let mut at = 0u32;
        loop {
            let node = self.nodes[at as usize];
            if node.count > 0 {
                for &id in &self.refs[node.first as usize..(node.first + node.count) as usize] {
                    if visit(id, at_near, &mut tmax) {
                        return;
                    }
                }
            } else {
                let (a, b) = (node.first, node.first + 1);
                let ta = enter(&self.nodes[a as usize].bounds, tmax);
                let tb = enter(&self.nodes[b as usize].bounds, tmax);
                let next = match (ta, tb) {
                    (Some(x), Some(y)) => {
                        let (near, far) = if x <= y { ((a, x), b) } else { ((b, y), a) };
                        stack.push(far);
                        Some(near)
                    }
                    (Some(x), None) => Some((a, x)),
                    (None, Some(y)) => Some((b, y)),
                    (None, None) => None,
                };
                if let Some((next, near)) = next {
                    (at, at_near) = (next, near);
                    continue;
                }
            }
            // Pop a node still in reach.
            loop {
                let Some(candidate) = stack.pop() else { return };
                if let Some(near) = enter(&self.nodes[candidate as usize].bounds, tmax) {
                    (at, at_near) = (candidate, near);
                    break;
                }
            }
        }
    }

    /// The instances whose boxes hold `p` (boundary included): `visit(id)` for each.
    pub fn holding(&self, p: [f32; 3], mut visit: impl FnMut(u32)) {
        let inside = |b: &Aabb| (0..3).all(|k| b.lo[k] <= p[k] && p[k] <= b.hi[k]);
        let mut stack = Stack { fixed: [0; 64], len: 0, spill: Vec::new() };
        if self.nodes.first().is_some_and(|n| inside(&n.bounds)) {
            stack.push(0);
        }
        while let Some(at) = stack.pop() {
            let node = self.nodes[at as usize];
            if node.count > 0 {
                self.refs[node.first as usize..(node.first + node.count) as usize].iter().for_each(|&id| visit(id));
                continue;
            }
            for kid in [node.first, node.first + 1] {
                if inside(&self.nodes[kid as usize].bounds) {
                    stack.push(kid);
                }
            }
        }
    }

    /// The instances whose boxes lie within `reach` of `p`, nearest box first:
    /// `visit(id, near)` for each (`near` a lower bound on the distance from `p` to
    /// the box, in `f64`), which returns the reach from then on (boxes past it are
    /// skipped).
    pub fn nearest(&self, p: [f32; 3], mut reach: f64, mut visit: impl FnMut(u32, f64) -> f64) {
        // The distance to a box from f32 corners, in f64: within a few ulps of exact,
        // which the relative margin takes off, so that it stays a lower bound.
        let near = |b: &Aabb| {
            let d2: f64 = (0..3)
                .map(|k| {
                    let (x, lo, hi) = (f64::from(p[k]), f64::from(b.lo[k]), f64::from(b.hi[k]));
                    let g = (lo - x).max(x - hi).max(0.0);
                    g * g
                })
                .sum();
            d2.sqrt() * (1.0 - 1e-12)
        };
        let Some(root) = self.nodes.first() else { return };
        let mut stack: Vec<(u32, f64)> = vec![(0, near(&root.bounds))];
        while let Some((at, lower)) = stack.pop() {
            if lower > reach {
                continue;
            }
            let node = self.nodes[at as usize];
            if node.count > 0 {
                for &id in &self.refs[node.first as usize..(node.first + node.count) as usize] {
                    reach = visit(id, lower);
                }
                continue;
            }
            let (a, b) = (node.first, node.first + 1);
            let (da, db) = (near(&self.nodes[a as usize].bounds), near(&self.nodes[b as usize].bounds));
            // The nearer child popped first.
            let (first, second) = if da <= db { ((a, da), (b, db)) } else { ((b, db), (a, da)) };
            stack.extend([second, first].into_iter().filter(|&(_, d)| d <= reach));
        }
    }

    /// The nodes, for the memory a world reports.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>() + self.refs.len() * 4
    }
}

/// Splits `items` (a node's instances, `centres` their centres' box) by the binned
/// SAH on the axis where the centres spread most; both sides non-empty. Returns where
/// the second side begins.
fn split(items: &mut [(Aabb, u32)], centres: &Aabb) -> usize {
    let axis = (0..3).fold(0, |a, k| if centres.hi[k] - centres.lo[k] > centres.hi[a] - centres.lo[a] { k } else { a });
    let (lo, extent) = (centres.lo[axis], centres.hi[axis] - centres.lo[axis]);
    let half = items.len() / 2;
    if extent.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !extent.is_finite() {
        return half; // every centre at one point: any split
    }
    let scale = BINS as f32 / extent;
    let bin = |b: &Aabb| (((b.centre(axis) - lo) * scale) as usize).min(BINS - 1);
    let mut count = [0usize; BINS];
    let mut bounds = [Aabb::EMPTY; BINS];
    for (b, _) in items.iter() {
        let k = bin(b);
        count[k] += 1;
        bounds[k].grow(b);
    }
    // Sweep: the cost of splitting after each bin.
    let mut right_area = [0.0f32; BINS];
    let mut right_count = [0usize; BINS];
    let (mut acc, mut n) = (Aabb::EMPTY, 0);
    for k in (1..BINS).rev() {
        acc.grow(&bounds[k]);
        n += count[k];
        right_area[k] = acc.area();
        right_count[k] = n;
    }
    let (mut best, mut best_cost) = (0, f32::INFINITY);
    let (mut acc, mut n) = (Aabb::EMPTY, 0);
    for k in 0..BINS - 1 {
        acc.grow(&bounds[k]);
        n += count[k];
        let right = right_count[k + 1];
        if n == 0 || right == 0 {
            continue;
        }
        let cost = acc.area() * n as f32 + right_area[k + 1] * right as f32;
        if cost < best_cost {
            (best, best_cost) = (k, cost);
        }
    }
    if !best_cost.is_finite() {
        // Every centre in one bin: the median.
        items.select_nth_unstable_by(half, |a, b| a.0.centre(axis).total_cmp(&b.0.centre(axis)));
        return half;
    }
    // Partition: bins up to `best` first.
    let mut i = 0;
    for j in 0..items.len() {
        if bin(&items[j].0) <= best {
            items.swap(i, j);
            i += 1;
        }
    }
    i
}
