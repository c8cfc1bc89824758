//! The octree walk of Portalez & Duguet 2016 (section 4.2.3): enter a leaf, test its
//! triangles, leave through the face the Plücker signs give, follow the link.
//!
//! What the paper leaves out, and this walk does:
//! * a triangle hit beyond the current leaf's exit is kept as a candidate but not
//!   returned until the walk reaches a leaf whose exit lies beyond it, so the result
//!   is the nearest hit whatever leaf a triangle is listed in;
//! * rays that start inside the root cube start in the leaf holding their first point,
//!   found by descending the point-location tree; rays from outside enter through the
//!   cube map, which holds a leaf or the node to descend from;
//! * a walk is bounded by [`Tracer::max_steps`] whatever the file holds.

use octrace_format::layout::{links_before, NodeRef, LEAF_HEADER_WORDS, TRIANGLE_FLOATS};
use octrace_format::SceneView;

use super::tables::{exit_code, octant, EXIT_FACE, OTHER_AXES};
use super::triangle::{intersect, TriRay};
use crate::ray::{Hit, Ray};

/// Traces rays through one scene. Cheap to build (no allocation): make one per batch.
#[derive(Clone, Debug)]
pub struct Tracer<'a> {
    view: SceneView<'a>,
    root_lo: [f32; 3],
    root_hi: [f32; 3],
    /// `2^max_depth / root_size`: world to finest-grid coordinates.
    grid_scale: f64,
    max_depth: u32,
    max_steps: u32,
}

/// What a walk did, for the cells view and for statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkStats {
    /// Leaves visited.
    pub leaves: u32,
    /// Triangle tests run.
    pub triangle_tests: u32,
}

/// A prepared ray: what every step needs, computed once.
struct Walk {
    o: [f32; 3],
    d: [f32; 3],
    /// Index into a box `[lo.xyz, hi.xyz]` of the exit corner's coordinate per axis.
    corner: [usize; 3],
    /// Exit-face row of the ray's octant.
    exits: &'static [u8; 8],
    /// Direction component is negative (sign bit), per axis.
    negative: [bool; 3],
    inv: [f32; 3],
}

impl<'a> Tracer<'a> {
    /// Prepares a tracer for a validated view.
    pub fn new(view: SceneView<'a>) -> Tracer<'a> {
        let b = view.bounds;
        let root_box = octrace_format::layout::cell_box(b.root_lo, b.root_size, 0, [0; 3]);
        let max_depth = view.params.max_depth;
        Tracer {
            root_lo: [root_box[0], root_box[1], root_box[2]],
            root_hi: [root_box[3], root_box[4], root_box[5]],
            grid_scale: (1u64 << max_depth) as f64 / b.root_size as f64,
            max_depth,
            // A line crosses at most 3 * 2^depth planes of the finest grid, and each
            // step crosses one (or sits on an edge or corner and crosses one at no
            // distance, at most twice more): 3x that, plus slack for tiny trees.
            max_steps: 9 * (1u32 << max_depth) + 64,
            view,
        }
    }

    /// The view this tracer reads.
    pub fn view(&self) -> &SceneView<'a> {
        &self.view
    }

    /// The most leaves one walk may visit; see the module docs.
    pub fn max_steps(&self) -> u32 {
        self.max_steps
    }

    /// The nearest hit in `[tmin, tmax]`, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<false>(ray, &mut WalkStats::default())
    }

    /// Whether anything is hit in `[tmin, tmax]`; stops at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.walk::<true>(ray, &mut WalkStats::default()).is_some()
    }

    /// Some hit in `[tmin, tmax]` (not necessarily the nearest): the occluder that
    /// [`Tracer::occluded`] found.
    pub fn occluder(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<true>(ray, &mut WalkStats::default())
    }

    /// [`Tracer::intersect`], counting what the walk did.
    pub fn intersect_with_stats(&self, ray: &Ray) -> (Option<Hit>, WalkStats) {
        let mut stats = WalkStats::default();
        (self.walk::<false>(ray, &mut stats), stats)
    }

    /// Any hit for `ANY`, else the nearest.
    fn walk<const ANY: bool>(&self, ray: &Ray, stats: &mut WalkStats) -> Option<Hit> {
        if !ray.is_traceable() {
            return None;
        }
        let o = ray.origin.to_array();
        let d = ray.dir.to_array();
        let (t_enter, t_leave, entry_axis) = self.clip_to_root(o, d)?;
        let t_start = t_enter.max(ray.tmin);
        if t_start > t_leave.min(ray.tmax) {
            return None; // misses the root cube within [tmin, tmax]: no memory touched
        }
        let mut address = if t_enter > ray.tmin {
            self.enter_through_cube_map(o, d, t_enter, entry_axis)
        } else {
            self.locate(point_at(o, d, t_start))
        };
        let oct = octant(d);
        let w = Walk {
            o,
            d,
            corner: [0, 1, 2].map(|a| if d[a].is_sign_negative() { a } else { a + 3 }),
            exits: &EXIT_FACE[oct],
            negative: [d[0].is_sign_negative(), d[1].is_sign_negative(), d[2].is_sign_negative()],
            inv: d.map(|c| 1.0 / c),
        };
        let tri_ray = TriRay { o, d };
        let v = &self.view;
        let mut best: Option<Hit> = None;
        let mut t_best = ray.tmax;
        for _ in 0..self.max_steps {
            stats.leaves += 1;
            let a = address as usize;
            let rec = &v.octree[a..a + LEAF_HEADER_WORDS];
            let (count, offset, box_index, ncount) = (rec[0], rec[1], rec[2], rec[3]);
            // 1. The leaf's triangles: keep the nearest in [tmin, t_best].
            let refs = &v.tri_refs[offset as usize..(offset + count) as usize];
            stats.triangle_tests += count;
            for &tri in refs {
                let data = &v.triangles[tri as usize * TRIANGLE_FLOATS..][..TRIANGLE_FLOATS];
                if let Some((t, u, vv)) = intersect(&tri_ray, data, ray.tmin, t_best) {
                    t_best = t;
                    best = Some(Hit { t, triangle: v.triangle_ids[tri as usize], u, v: vv, leaf: box_index });
                    if ANY {
                        return best;
                    }
                }
            }
            // 2. The exit face, from the signs of three Plücker products.
            let bx = &v.boxes[box_index as usize * 6..][..6];
            let off = [0, 1, 2].map(|k| bx[w.corner[k]] - w.o[k]);
            let face = w.exits[exit_code(off, w.d)] as usize;
            let axis = face >> 1;
            // 3. A candidate inside this leaf is the nearest: nothing after the exit
            //    can be nearer. Past tmax, nothing more can count.
            let t_exit = off[axis] * w.inv[axis];
            if best.is_some_and(|h| h.t <= t_exit) || t_exit >= ray.tmax {
                return best;
            }
            // 4. The neighbour across the face: none at the root's boundary, else one,
            //    or one of four picked by the sides of the face's median lines.
            let n = (ncount >> (4 * face)) & 0xF;
            if n == 0 {
                return best;
            }
            let [u, vv] = OTHER_AXES[axis];
            let side = |k: usize| {
                let mid = 0.5 * (bx[k] + bx[k + 3]);
                let p = off[axis] * w.d[k] - (mid - w.o[k]) * w.d[axis];
                ((p > 0.0) ^ w.negative[axis]) as u32
            };
            let quadrant = side(u) | side(vv) << 1;
            let link = a + LEAF_HEADER_WORDS + (links_before(ncount, face) + (n >> 2) * quadrant) as usize;
            address = v.octree[link];
        }
        debug_assert!(false, "walk exceeded {} steps: ray {ray:?}", self.max_steps);
        best
    }

    /// The ray's parameter interval inside the root cube and the axis it enters by,
    /// or `None` if it misses. Zero components are handled explicitly: `0 * inf` never
    /// happens.
    fn clip_to_root(&self, o: [f32; 3], d: [f32; 3]) -> Option<(f32, f32, usize)> {
        let (mut t0, mut t1, mut axis) = (f32::NEG_INFINITY, f32::INFINITY, 0);
        for a in 0..3 {
            let (lo, hi) = (self.root_lo[a], self.root_hi[a]);
            if d[a] == 0.0 {
                if o[a] < lo || o[a] > hi {
                    return None;
                }
                continue;
            }
            let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
            let (near, far) = if ta < tb { (ta, tb) } else { (tb, ta) };
            if near > t0 {
                t0 = near;
                axis = a;
            }
            t1 = t1.min(far);
        }
        (t0 <= t1).then_some((t0, t1, axis))
    }

    /// Finest-grid coordinates of a point, clamped into the root.
    fn grid_coords(&self, p: [f32; 3]) -> [u32; 3] {
        let last = ((1u64 << self.max_depth) - 1) as f64;
        // NaN clamps to 0 through `as`; rounding can only move a point to a
        // neighbouring cell, which the bake margin covers.
        [0, 1, 2].map(|a| (((p[a] as f64 - self.root_lo[a] as f64) * self.grid_scale).floor().clamp(0.0, last)) as u32)
    }

    /// The address of the leaf holding point `p` (clamped into the root).
    pub fn locate(&self, p: [f32; 3]) -> u32 {
        self.descend(self.view.root, 0, self.grid_coords(p))
    }

    /// Descends from `word` (a node at `level`) to the leaf holding grid cell `q`.
    fn descend(&self, mut word: u32, mut level: u32, q: [u32; 3]) -> u32 {
        loop {
            match NodeRef::decode(word) {
                NodeRef::Leaf(address) => return address,
                NodeRef::Internal(i) => {
                    let shift = self.max_depth - level - 1;
                    let child = (q[0] >> shift & 1) | (q[1] >> shift & 1) << 1 | (q[2] >> shift & 1) << 2;
                    word = self.view.nodes[8 * i as usize + child as usize];
                    level += 1;
                }
            }
        }
    }

    /// The leaf a ray from outside enters first: the cube-map texel under its entry
    /// point holds that leaf, or the node to descend from.
    fn enter_through_cube_map(&self, o: [f32; 3], d: [f32; 3], t: f32, axis: usize) -> u32 {
        let mut q = self.grid_coords(point_at(o, d, t));
        let high = d[axis] < 0.0;
        q[axis] = if high { (1u32 << self.max_depth) - 1 } else { 0 };
        let face = 2 * axis + high as usize;
        let level = self.view.params.cube_level;
        let res = 1usize << level;
        let [u, v] = OTHER_AXES[axis];
        let shift = self.max_depth - level;
        let texel = (face * res + (q[v] >> shift) as usize) * res + (q[u] >> shift) as usize;
        self.descend(self.view.cube_map[texel], level, q)
    }
}

#[inline(always)]
fn point_at(o: [f32; 3], d: [f32; 3], t: f32) -> [f32; 3] {
    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
}
