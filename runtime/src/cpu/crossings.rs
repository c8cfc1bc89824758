//! Every crossing along a ray, in increasing distance, each once: the walk's order
//! (it meets leaves in the order the ray does, with no stack and no sort but within a
//! leaf) with the watertight test's edge ownership (`Shear::intersect_owned`: a ray
//! through an edge or a vertex that triangles share crosses exactly one of them).
//!
//! # Each crossing once
//! A triangle spanning several leaves is listed in each and found again in each. The
//! leaves the walk visits tile the ray: leaf `k` holds the piece `(t_{k-1}, t_k]`
//! between the previous leaf's exit and its own (the first from `tmin`, the last to
//! `tmax`), and a leaf reports only the crossings in its piece, so each distance falls
//! in exactly one leaf, and that leaf lists every triangle through the ray's point
//! there (the bake lists a triangle in every leaf its enlarged box meets). The pieces'
//! ends never go backwards (an exit that rounds before the previous one gives an empty
//! piece). Crossings in a piece are sorted by distance, equal distances by input id.

use std::ops::ControlFlow;

use octrace_format::layout::{LEAF_HEADER_WORDS, TRIANGLE_FLOATS};

use super::fans;
use super::tables::ExitRule;
use super::tracer::{Tracer, TriangleTest};
use super::walk::RayWalk;
use super::watertight::Shear;
use crate::ray::Ray;

/// One crossing of a ray with a triangle ([`Tracer::crossings`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Crossing {
    /// Distance along the ray, in units of its direction (as [`crate::Hit::t`]).
    pub t: f32,
    /// The triangle's index in the input mesh.
    pub triangle: u32,
    /// Barycentric coordinate of the second vertex.
    pub u: f32,
    /// Barycentric coordinate of the third vertex.
    pub v: f32,
    /// Whether the ray arrives on the triangle's front, the side its normal
    /// `(v1 - v0) x (v2 - v0)` points to (counter-clockwise seen from there): for a
    /// closed mesh wound outward, whether it enters the solid there.
    pub enters: bool,
}

/// How many times a ray crosses a mesh ([`Tracer::count_crossings`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CrossingCount {
    /// Every crossing.
    pub total: u32,
    /// Crossings arriving on a triangle's front ([`Crossing::enters`]).
    pub entries: u32,
}

impl CrossingCount {
    /// Crossings arriving on a triangle's back.
    pub fn exits(&self) -> u32 {
        self.total - self.entries
    }

    /// Entries minus exits: for a ray from a point to infinity through a closed mesh
    /// wound outward, -1 for each solid the point is inside, 0 outside.
    pub fn winding(&self) -> i64 {
        self.entries as i64 - self.exits() as i64
    }
}

/// A walk's reusable buffer for the crossings of one leaf.
#[derive(Debug, Default)]
pub(crate) struct LeafCrossings(Vec<(Crossing, u32)>);

impl Tracer<'_> {
    /// Calls `visit` with every crossing of `ray` in `[tmin, tmax]`, in increasing
    /// distance (equal distances in increasing input id), each once: a ray through an
    /// edge or vertex that triangles share crosses one of them (the watertight test's
    /// edge ownership, `cpu::watertight::Shear::intersect_owned`); two triangles at the
    /// same place (coplanar copies) are both listed. `visit` may stop the walk by
    /// returning `ControlFlow::Break`.
    ///
    /// The nearest-hit queries keep their closed edges: a ray exactly through the edge
    /// of an open mesh's rim hits it there, and may cross nothing here.
    ///
    /// # Example
    /// ```
    /// use std::ops::ControlFlow;
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let ray = Ray::new([-3.0, 0.1, 0.2].into(), [1.0, 0.0, 0.0].into());
    /// let mut ts = Vec::new();
    /// scene.tracer().crossings(&ray, |c| {
    ///     ts.push((c.t, c.enters));
    ///     ControlFlow::Continue(())
    /// });
    /// assert_eq!(ts.len(), 2); // in, then out
    /// assert!(ts[0].0 < ts[1].0 && ts[0].1 && !ts[1].1);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn crossings(&self, ray: &Ray, visit: impl FnMut(Crossing) -> ControlFlow<()>) {
        self.crossings_with(ray, &mut LeafCrossings::default(), visit);
    }

    /// Every crossing of `ray`, in order ([`Tracer::crossings`]).
    pub fn all_crossings(&self, ray: &Ray) -> Vec<Crossing> {
        let mut out = Vec::new();
        self.crossings(ray, |c| {
            out.push(c);
            ControlFlow::Continue(())
        });
        out
    }

    /// The first `k` crossings of `ray`, in order ([`Tracer::crossings`], stopped there).
    pub fn first_crossings(&self, ray: &Ray, k: usize) -> Vec<Crossing> {
        let mut out = Vec::with_capacity(k.min(64));
        if k > 0 {
            self.crossings(ray, |c| {
                out.push(c);
                if out.len() == k {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            });
        }
        out
    }

    /// How many times `ray` crosses the mesh in `[tmin, tmax]`, and how many of those
    /// arrive on a triangle's front ([`Tracer::crossings`]' crossings, counted).
    pub fn count_crossings(&self, ray: &Ray) -> CrossingCount {
        let mut count = CrossingCount::default();
        self.crossings(ray, |c| {
            count.total += 1;
            count.entries += c.enters as u32;
            ControlFlow::Continue(())
        });
        count
    }

    /// The winding number of `p` about a closed mesh whose every edge is in two
    /// triangles running it opposite ways, exactly: exits minus entries along one ray
    /// from `p` to the mesh box's nearest face ([`CrossingCount::winding`], negated).
    /// Under [`TriangleTest::Exact`] each crossing is decided by exact arithmetic and a
    /// ray through an edge or vertex by the edge rule, which is the answer for the ray
    /// moved aside by an infinitesimal (rasterisers' top-left rule): a crossing of the
    /// surface is counted once with its side, a graze at a silhouette as a pair of
    /// opposite sides, so the sum is the number of times the surface winds around `p`.
    ///
    /// On the surface, where the winding number is not defined, the crossings at
    /// distance 0 count: the answer is the winding number of a point beside `p`, just
    /// behind it along the ray. `None` for a tracer with another test and for a point
    /// with a NaN; a point outside the mesh box winds 0.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams, Mesh};
    /// use octrace_runtime::Scene;
    /// // Two spheres, one inside the other: 2 inside both.
    /// let (a, b) = (procedural::sphere([0.0; 3], 1.0, 12, 16), procedural::sphere([0.0; 3], 0.5, 12, 16));
    /// let both = Mesh::from_triangles(a.triangles.iter().chain(&b.triangles).copied().collect());
    /// let scene = Scene::from_baked(bake(&both, &BuildParams::auto())?)?;
    /// let tracer = scene.tracer();
    /// assert_eq!([[0.1, 0.0, 0.0], [0.0, 0.7, 0.0], [0.0, 0.0, 0.99]].map(|p| tracer.winding_by_ray(p)), [Some(2), Some(1), Some(1)]);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn winding_by_ray(&self, p: [f32; 3]) -> Option<i64> {
        let bounds = super::mesh_box(self.view());
        self.winding_by_ray_with(&mut LeafCrossings::default(), p, &bounds).map(|(n, _)| n)
    }

    /// [`Tracer::winding_by_label`] of many points on all threads of the current
    /// rayon pool.
    pub(crate) fn par_windings_by_label(&self, solid: &super::Solid, points: &[[f32; 3]], out: &mut [Option<i64>]) {
        use rayon::prelude::*;
        assert_eq!(points.len(), out.len(), "one result slot a point");
        points.par_iter().zip(out.par_iter_mut()).for_each(|(&p, o)| *o = self.winding_by_label(solid, p));
    }

    /// [`Tracer::winding_by_ray`] of many points of a closed oriented scene on all
    /// threads of the current rayon pool, checked against the parity of the exact
    /// inside/outside (on the surface, a crossing at distance 0, the ray's answer):
    /// `None` where it cannot answer or the parity disagrees.
    pub(crate) fn par_windings_by_ray(&self, solid: &super::Solid, points: &[[f32; 3]], out: &mut [Option<i64>]) {
        use rayon::prelude::*;
        assert_eq!(points.len(), out.len(), "one result slot a point");
        let bounds = super::mesh_box(self.view());
        points.par_chunks(256).zip(out.par_chunks_mut(256)).for_each(|(p, o)| {
            let mut buffer = LeafCrossings::default();
            for (&p, o) in p.iter().zip(o) {
                *o = self.winding_by_ray_with(&mut buffer, p, &bounds).and_then(|(n, touched)| {
                    (touched || n.rem_euclid(2) == self.contains(solid, p) as i64).then_some(n)
                });
            }
        });
    }

    fn winding_by_ray_with(
        &self,
        buffer: &mut LeafCrossings,
        p: [f32; 3],
        (lo, hi): &([f32; 3], [f32; 3]),
    ) -> Option<(i64, bool)> {
        if self.triangle_test() != TriangleTest::Exact || p.iter().any(|x| x.is_nan()) {
            return None;
        }
        if (0..3).any(|k| p[k] < lo[k] || p[k] > hi[k]) {
            return Some((0, false));
        }
        // The shortest way out: along the axis to the nearest face.
        let (mut axis, mut sign, mut gap) = (0, 1.0f32, f32::INFINITY);
        for k in 0..3 {
            for (s, g) in [(-1.0, p[k] - lo[k]), (1.0, hi[k] - p[k])] {
                if g < gap {
                    (axis, sign, gap) = (k, s, g);
                }
            }
        }
        let mut dir = [0.0f32; 3];
        dir[axis] = sign;
        let (mut winding, mut touched) = (0i64, false);
        self.crossings_with(&Ray::new(p.into(), dir.into()), buffer, |c| {
            touched |= c.t == 0.0;
            winding += if c.enters { -1 } else { 1 };
            ControlFlow::Continue(())
        });
        Some((winding, touched))
    }

    /// [`Tracer::all_crossings`] by brute force: every stored triangle tested with the
    /// same test and edge rule, from the same (possibly moved) origin, sorted as the
    /// walk sorts (distance, the exact order of equal distances under the exact test,
    /// input id). The reference the walk is tested against: the same list, bit for bit.
    pub fn crossings_by_brute_force(&self, ray: &Ray) -> Vec<Crossing> {
        let Some(w) = self.begin(ray) else { return Vec::new() };
        let v = self.view();
        let (shear, d, exact) = (w.shear(), w.d(), w.rule() == ExitRule::Exact);
        let exact_test = self.triangle_test() == TriangleTest::Exact;
        let far = w.far();
        let mut out: Vec<(Crossing, u32)> = v
            .triangles
            .chunks_exact(TRIANGLE_FLOATS)
            .zip(v.triangle_ids)
            .enumerate()
            .filter_map(|(prim, (tri, &triangle))| {
                let (tmin, tmax) = (w.tmin(), w.t_best());
                let hit = if let Some(far) = &far {
                    // The ray as given decides, and gives its own distance.
                    far.hit(tri, true, tmin, tmax).map(|((_, u, v), t)| (t, u, v))
                } else if exact_test {
                    shear.intersect_owned_exact(tri, tmin, tmax)
                } else if exact {
                    shear.intersect_owned_f64(tri, tmin, tmax)
                } else {
                    shear.intersect_owned(tri, tmin, tmax)
                };
                let (t, u, vv) = hit?;
                Some((Crossing { t, triangle, u, v: vv, enters: arrives_on_front(d, tri) }, prim as u32))
            })
            .collect();
        // In the walk's order, then measured from the ray's own origin.
        sort_piece(v.triangles, &far.map_or(shear, |f| f.shear), exact_test, &mut out);
        out.into_iter()
            .map(|(c, _)| Crossing { t: far.map_or_else(|| w.unshift_distance(c.t), |_| c.t), ..c })
            .collect()
    }

    /// [`Tracer::crossings`] with a caller's buffer (batches reuse one a thread).
    pub(crate) fn crossings_with(
        &self,
        ray: &Ray,
        buffer: &mut LeafCrossings,
        visit: impl FnMut(Crossing) -> ControlFlow<()>,
    ) {
        if let Some(w) = self.begin(ray) {
            self.crossings_from(w, buffer, visit);
        }
    }

    /// The crossing walk from a begun walk `w` (the scalar form, which every ray can
    /// take: the lanes hand it the rays only it walks).
    pub(crate) fn crossings_from(
        &self,
        w: RayWalk,
        buffer: &mut LeafCrossings,
        visit: impl FnMut(Crossing) -> ControlFlow<()>,
    ) {
        let mut visit = visit;
        self.crossings_entering(w, buffer, |c, _| visit(c), |_| ControlFlow::Continue(()));
    }

    /// [`Tracer::crossings_from`], with `enter(address)` asked as the walk enters each
    /// leaf (its record's address), before the leaf's crossings: `Break` ends the walk
    /// there. `visit` is handed each crossing's stored vertices beside it.
    pub(crate) fn crossings_entering(
        &self,
        mut w: RayWalk,
        buffer: &mut LeafCrossings,
        mut visit: impl FnMut(Crossing, &[f32]) -> ControlFlow<()>,
        mut enter: impl FnMut(u32) -> ControlFlow<()>,
    ) {
        // The ray's own interval in the walk's units (a far origin is moved: the walk's
        // distances are from there, `RayWalk::unshift`).
        // Where the walk stops: the ray's tmax, or where it leaves the mesh box.
        let (tmin, tmax, stop) = (w.tmin(), w.t_best(), w.tmax());
        let (shear, d) = (w.shear(), w.d());
        // A ray under the exact exit rule is tested in f64 (`Shear::intersect_f64`);
        // the exact test (`TriangleTest::Exact`) decides every ray exactly.
        let exact = w.rule() == ExitRule::Exact;
        let exact_test = self.triangle_test() == TriangleTest::Exact;
        // A re-originated ray under the exact test: the ray as given decides each
        // crossing and gives its distance; the walk's distance places it in a piece.
        let far = w.far();
        let order = far.map_or(shear, |f| f.shear);
        let v = self.view();
        // The end of the previous leaf's piece; `None` in the first leaf, whose piece
        // starts at tmin, closed.
        let mut lo: Option<f32> = None;
        for _ in 0..self.max_steps() {
            if enter(w.address()).is_break() {
                return;
            }
            let a = w.address() as usize;
            // A hostile file's link past the array (on the trusted path) ends the walk.
            let Some(rec) = v.octree.get(a..a + LEAF_HEADER_WORDS) else { return };
            let (count, offset, box_index, ncount) = (rec[0], rec[1], rec[2], rec[3]);
            let exit = self.exit_of(&w);
            let n = (ncount >> (4 * exit.face)) & 0xF;
            let last = exit.t >= stop || n == 0;
            let hi = if last { tmax } else { exit.t.max(lo.unwrap_or(tmin)) };
            // The leaf's crossings in its piece.
            let refs = v.tri_refs.get(offset as usize..offset as usize + count as usize).unwrap_or_default();
            // A fan's leaf: the triangles its hierarchy picks (`fans.rs`), in the same order.
            let mut room = fans::candidates_room();
            let refs = self
                .fan_refs((box_index, offset, refs), || (!exact && !exact_test).then_some(&shear), true, &mut room)
                .unwrap_or(refs);
            buffer.0.clear();
            for &prim in refs {
                let Some(tri) =
                    v.triangles.get(prim as usize * TRIANGLE_FLOATS..).and_then(|t| t.get(..TRIANGLE_FLOATS))
                else {
                    continue;
                };
                let hit = if let Some(far) = &far {
                    far.hit(tri, true, tmin, hi)
                } else {
                    let hit = if exact_test {
                        shear.intersect_owned_exact(tri, tmin, hi)
                    } else if exact {
                        shear.intersect_owned_f64(tri, tmin, hi)
                    } else {
                        shear.intersect_owned(tri, tmin, hi)
                    };
                    hit.map(|h| (h, h.0))
                };
                // The walk's distance, and the one the crossing is listed with.
                let Some(((t, u, vv), listed)) = hit else { continue };
                if lo.is_some_and(|lo| t <= lo) {
                    continue;
                }
                let Some(&triangle) = v.triangle_ids.get(prim as usize) else { continue };
                let enters = arrives_on_front(d, tri);
                buffer.0.push((Crossing { t: listed, triangle, u, v: vv, enters }, prim));
            }
            sort_piece(v.triangles, &order, exact_test, &mut buffer.0);
            for &(c, prim) in &buffer.0 {
                let c = if far.is_some() { c } else { Crossing { t: w.unshift_distance(c.t), ..c } };
                let tri = &v.triangles[prim as usize * TRIANGLE_FLOATS..][..TRIANGLE_FLOATS];
                if visit(c, tri).is_break() {
                    return;
                }
            }
            lo = Some(hi);
            if last || !self.follow(&mut w, &exit, ncount) {
                return;
            }
        }
    }
}

/// A leaf's crossings in its piece of the ray, each with its stored triangle's index,
/// in the walk's order: distances, then (under the exact test, `exact`, for equal
/// rounded distances) the exact order, then input ids.
#[inline(always)]
pub(crate) fn sort_piece(triangles: &[f32], shear: &Shear, exact: bool, piece: &mut [(Crossing, u32)]) {
    if piece.len() < 2 {
        return;
    }
    let stored = |prim: u32| &triangles[prim as usize * TRIANGLE_FLOATS..][..TRIANGLE_FLOATS];
    piece.sort_unstable_by(|x, y| {
        let exactly = || match exact && x.0.t == y.0.t {
            true => shear.compare_distances(stored(x.1), stored(y.1)),
            false => std::cmp::Ordering::Equal,
        };
        x.0.t.total_cmp(&y.0.t).then_with(exactly).then(x.0.triangle.cmp(&y.0.triangle))
    });
}

/// Whether a ray of direction `d` arrives on the front of triangle `tri` (nine
/// floats): `d . n < 0` with `n = (v1 - v0) x (v2 - v0)`, in `f64` (the products of
/// `f32` differences are exact there; the sum rounds once).
#[inline(always)]
pub(crate) fn arrives_on_front(d: [f32; 3], tri: &[f32]) -> bool {
    let v = |i: usize| [tri[3 * i] as f64, tri[3 * i + 1] as f64, tri[3 * i + 2] as f64];
    let (a, b, c) = (v(0), v(1), v(2));
    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    d[0] as f64 * n[0] + d[1] as f64 * n[1] + d[2] as f64 * n[2] < 0.0
}

/// Where a batch's crossings go, ray by ray (in ray order).
pub(crate) trait CrossingSink {
    /// Ray `index`'s crossings, in order.
    fn ray(&mut self, index: usize, crossings: &[Crossing]);
}
