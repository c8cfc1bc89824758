//! Inside or outside of points for a closed mesh, where the octree's cells answer
//! most points without casting a ray.
//!
//! An empty leaf is wholly inside or wholly outside a closed mesh (no triangle comes
//! within the bake's margin of its box), and empty leaves joined by a face link are on
//! the same side: one crossing count from one of them (parity, edges owned:
//! `Tracer::crossings`) labels each connected group. A point in an empty leaf is then
//! answered by point location alone. A leaf with triangles gets a reference point of
//! its own, labelled once: the first of 27 points of its box (its centre, then the
//! points at a quarter and three quarters of its edges) at least 1/1024 of its edge
//! from the plane of every triangle it lists; a point in it counts the crossings of
//! the segment to that point, testing the leaf's triangles alone (the segment stays in
//! the box, and every triangle that meets the box is listed), in `f64`, edges owned.
//! A leaf with no such point, and a point whose segment starts on a triangle, walk on
//! in a fixed direction instead, counting crossings, until they enter an empty leaf
//! (or leave the scene): that leaf's label, flipped by the parity of the count, is the
//! answer.
//!
//! Before any of that, a grid over the root cube answers most points in one or two
//! reads (`cells`): cells wholly in empty leaves of one side, and where the surface
//! passes, finer cells that no triangle touches (a conservative test), labelled by
//! flooding from the cells of one side or by one exact answer a group.
//!
//! A point on the surface is answered as the points just beside it along
//! [`COUNT_DIRECTION`] are (crossings at a distance of zero are not counted): a
//! defined answer, the same on every path, where the exact one is a tie.
//! A mesh that is not closed (an edge used by an odd number of triangles) has no
//! inside: it is refused, naming its boundary edges; [`Tracer::contains_by_vote`]
//! gives an approximate answer for it.

use std::ops::ControlFlow;

use octrace_format::layout::{total_links, LEAF_HEADER_WORDS, TRIANGLE_FLOATS};
use octrace_format::topology::EdgeCensus;

use robust::{orient3d, Coord3D};

use super::crossings::{arrives_on_front, Crossing, CrossingCount, LeafCrossings};
use super::tracer::{Tracer, TriangleTest};
use super::watertight::Shear;
use crate::error::{Error, Result};
use crate::ray::Ray;
use cells::Cells;

mod cells;

/// The fixed direction points walk along to an empty leaf (and groups' counts run
/// along): no coordinate plane holds it, so it lies in no cell plane.
pub const COUNT_DIRECTION: [f32; 3] = [0.5773, 0.6151, 0.5371];

/// A leaf's side: empty and outside, empty and inside, or holding triangles (and no
/// reference point: answered by the walk); from `REFERENCED` on, a leaf with triangles
/// and a reference point: `REFERENCED + 2 * candidate + inside`.
const OUTSIDE: u8 = 0;
const INSIDE: u8 = 1;
const SURFACE: u8 = 2;
const REFERENCED: u8 = 3;

/// A reference point's least distance from the planes of its leaf's triangles, as a
/// fraction of the leaf's edge.
const CLEARANCE: f64 = 1.0 / 1024.0;

/// Candidate `i` of 27 for a leaf's reference point: its box's centre first, then the
/// points at 1/4, 1/2 and 3/4 of each edge (exact in `f32`: a leaf's box is a cell of
/// the root cube, whose edge is a power of two).
fn candidate(bx: &[f32], i: u8) -> [f32; 3] {
    const AT: [f32; 3] = [0.5, 0.25, 0.75];
    let f = [i % 3, (i / 3) % 3, i / 9].map(|k| AT[k as usize]);
    [0, 1, 2].map(|k| bx[k] + (bx[k + 3] - bx[k]) * f[k])
}

/// The labels of a closed scene's leaves ([`Solid::of`]), for [`Tracer::contains`].
#[derive(Clone, Debug)]
pub struct Solid {
    /// By box index: outside, inside, or a leaf with triangles.
    labels: Vec<u8>,
    /// The labels again on a uniform grid of the root cube (`Cells`), where a cell
    /// lies wholly in empty leaves of one side, and on 8 x 8 x 8 finer cells where
    /// the surface passes, where no triangle touches one: most points are answered by
    /// one or two reads.
    cells: Cells,
    /// Connected groups of empty leaves, and how many of them are inside.
    groups: usize,
    inside_groups: usize,
    /// Whether every group's winding number is its label (0 outside, 1 inside: no
    /// nested or inside-out shell around any), so that an empty leaf's label is the
    /// winding number of its points ([`Tracer::winding_by_label`]).
    plain: bool,
}

impl Solid {
    /// Labels the leaves of `tracer`'s scene, which must be closed (every edge of its
    /// stored triangles used by an even number of them).
    ///
    /// # Errors
    /// [`Error::NotClosed`] for an open scene, with its edge counts.
    pub fn of(tracer: &Tracer<'_>) -> Result<Solid> {
        let v = tracer.view();
        let triangles: Vec<[[f32; 3]; 3]> = v.stored_triangles().collect();
        let census = EdgeCensus::of(&triangles);
        if !census.is_closed() {
            return Err(Error::NotClosed { boundary_edges: census.boundary, edges: census.edges });
        }
        // Each leaf's record, in box order (records lie back to back from address 0).
        let leaves = v.leaf_count();
        let mut records = Vec::with_capacity(leaves);
        let mut a = 0usize;
        while records.len() < leaves {
            let Some(rec) = v.octree.get(a..a + LEAF_HEADER_WORDS) else { break };
            records.push((a as u32, rec[0], rec[3], rec[1]));
            a += LEAF_HEADER_WORDS + total_links(rec[3]) as usize;
        }
        let box_of = |address: u32| v.octree.get(address as usize + 2).copied();
        // Empty leaves joined through faces: union-find over box indices.
        let mut parent: Vec<u32> = (0..records.len() as u32).collect();
        let find = |parent: &mut Vec<u32>, mut x: u32| {
            while parent[x as usize] != x {
                let up = parent[parent[x as usize] as usize];
                parent[x as usize] = up;
                x = up;
            }
            x
        };
        for (b, &(address, count, ncount, _)) in records.iter().enumerate() {
            if count != 0 {
                continue;
            }
            let start = address as usize + LEAF_HEADER_WORDS;
            for &link in v.octree.get(start..start + total_links(ncount) as usize).unwrap_or_default() {
                let Some(nb) = box_of(link).filter(|&nb| (nb as usize) < records.len()) else { continue };
                if records[nb as usize].1 == 0 {
                    let (x, y) = (find(&mut parent, b as u32), find(&mut parent, nb));
                    parent[x.max(y) as usize] = x.min(y);
                }
            }
        }
        // One count a group, from the centre of its first leaf, to infinity.
        let mut roots = Vec::new();
        for (b, &(_, count, _, _)) in records.iter().enumerate() {
            if count == 0 && find(&mut parent, b as u32) == b as u32 {
                roots.push(b as u32);
            }
        }
        let rays: Vec<Ray> = roots
            .iter()
            .map(|&b| {
                let bx = &v.boxes[b as usize * 6..][..6];
                let centre = [0, 1, 2].map(|k| 0.5 * (bx[k] + bx[k + 3]));
                Ray::new(centre.into(), COUNT_DIRECTION.into())
            })
            .collect();
        let mut counts = vec![CrossingCount::default(); rays.len()];
        tracer.par_count_crossings_batch(&rays, &mut counts);
        let mut side = vec![OUTSIDE; records.len()];
        for (&b, c) in roots.iter().zip(&counts) {
            side[b as usize] = (c.total % 2 == 1) as u8;
        }
        let inside_groups = side.iter().zip(&records).filter(|(s, r)| r.1 == 0 && **s == INSIDE).count();
        // Exits minus entries to infinity: the group's winding number.
        let plain = tracer.triangle_test() == TriangleTest::Exact
            && counts.iter().all(|c| -c.winding() == (c.total % 2) as i64);
        let labels: Vec<u8> = (0..records.len())
            .map(|b| if records[b].1 != 0 { SURFACE } else { side[find(&mut parent, b as u32) as usize] })
            .collect();
        let mut solid = Solid { labels, cells: Cells::default(), groups: roots.len(), inside_groups, plain };
        // Reference points of the leaves with triangles, labelled by the walk.
        use rayon::prelude::*;
        let referenced: Vec<u8> = records
            .par_iter()
            .enumerate()
            .map(|(b, &(_, count, _, offset))| {
                if count == 0 {
                    return solid.labels[b];
                }
                let Some(bx) = v.boxes.get(b * 6..b * 6 + 6) else { return SURFACE };
                let refs = v.tri_refs.get(offset as usize..offset as usize + count as usize).unwrap_or_default();
                let clearance = CLEARANCE * (bx[3] - bx[0]) as f64;
                let clear = |c: [f32; 3]| {
                    refs.iter().all(|&prim| {
                        v.triangles
                            .get(prim as usize * TRIANGLE_FLOATS..)
                            .and_then(|t| t.get(..TRIANGLE_FLOATS))
                            .is_some_and(|t| plane_gap(c, t) >= clearance)
                    })
                };
                match (0..27u8).find(|&i| clear(candidate(bx, i))) {
                    Some(i) => REFERENCED + 2 * i + tracer.contains_near_surface(&solid, candidate(bx, i)) as u8,
                    None => SURFACE,
                }
            })
            .collect();
        solid.labels = referenced;
        solid.cells = Cells::of(v, &solid.labels);
        let blocks = solid.cells.blocks(v, |p| tracer.contains(&solid, p));
        solid.cells.attach(blocks);
        Ok(solid)
    }

    /// Each leaf's label by box index, for the GPU's filter (`gpu::inside`): 0 an empty
    /// leaf outside, 1 an empty leaf inside (its whole closed box on that side), above
    /// 1 a leaf with triangles.
    #[cfg(feature = "gpu")]
    pub(crate) fn leaf_labels(&self) -> &[u8] {
        &self.labels
    }

    /// Connected groups of empty leaves (each labelled by one crossing count).
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// Of those, the groups inside.
    pub fn inside_groups(&self) -> usize {
        self.inside_groups
    }

    /// Bytes of the grid that answers most points in one or two reads: two bits a
    /// cell of a grid of up to 128 cells a side (outside, inside, mixed, or a block),
    /// and for the cells the surface passes through, 8 x 8 x 8 finer labels in 128
    /// bytes (a block).
    pub fn grid_bytes(&self) -> usize {
        self.cells.bytes()
    }

    /// The grid's blocks of finer labels (see [`Solid::grid_bytes`]).
    pub fn grid_blocks(&self) -> usize {
        self.cells.block_count()
    }
}

impl Tracer<'_> {
    /// Whether `p` lies inside the closed mesh `solid` labels (made for this tracer's
    /// scene: [`Solid::of`]). A point on the surface is answered as the points just
    /// beside it along [`COUNT_DIRECTION`]; a point outside the mesh's box, or not
    /// finite, is outside.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::cpu::Solid;
    /// use octrace_runtime::Scene;
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let tracer = scene.tracer();
    /// let solid = Solid::of(&tracer)?;
    /// assert!(tracer.contains(&solid, [0.1, 0.2, -0.3]));
    /// assert!(!tracer.contains(&solid, [0.9, 0.9, 0.0]));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn contains(&self, solid: &Solid, p: [f32; 3]) -> bool {
        let b = self.view().bounds;
        if !(0..3).all(|k| b.mesh_lo[k] <= p[k] && p[k] <= b.mesh_hi[k]) {
            return false; // outside the box of every triangle (or NaN)
        }
        match solid.cells.label(p) {
            OUTSIDE => return false,
            INSIDE => return true,
            _ => {}
        }
        let (address, _, _) = self.locate_cell(p);
        let Some(&box_index) = self.view().octree.get(address as usize + 2) else { return false };
        match solid.labels.get(box_index as usize) {
            Some(&OUTSIDE) => false,
            Some(&INSIDE) => true,
            Some(&SURFACE) => self.contains_near_surface(solid, p),
            Some(&label) => {
                let (i, inside) = ((label - REFERENCED) / 2, (label - REFERENCED) % 2 == 1);
                self.contains_by_reference(solid, p, address, box_index, i, inside)
            }
            None => false, // a hostile file on the trusted path
        }
    }

    /// The winding number of `p` where its leaf answers it: the label of an empty
    /// leaf (0 or 1) in a scene whose groups of empty leaves wind as they are
    /// labelled (counted by the exact test; no nested or inside-out shells around
    /// them), 0 outside the mesh box. `None` elsewhere: a leaf with triangles, or
    /// another scene.
    pub(crate) fn winding_by_label(&self, solid: &Solid, p: [f32; 3]) -> Option<i64> {
        if !solid.plain || p.iter().any(|x| x.is_nan()) {
            return None;
        }
        let b = self.view().bounds;
        if !(0..3).all(|k| b.mesh_lo[k] <= p[k] && p[k] <= b.mesh_hi[k]) {
            return Some(0);
        }
        let (address, _, _) = self.locate_cell(p);
        let box_index = *self.view().octree.get(address as usize + 2)?;
        match solid.labels.get(box_index as usize) {
            Some(&OUTSIDE) => Some(0),
            Some(&INSIDE) => Some(1),
            _ => None,
        }
    }

    /// [`Tracer::contains`] for a point in a leaf with a reference point (candidate
    /// `i` of its box, inside or not): the parity of the crossings of the segment from
    /// `p` to it, over the leaf's triangles.
    fn contains_by_reference(&self, solid: &Solid, p: [f32; 3], address: u32, b: u32, i: u8, inside: bool) -> bool {
        let v = self.view();
        let (Some(bx), Some(rec)) =
            (v.boxes.get(b as usize * 6..b as usize * 6 + 6), v.octree.get(address as usize..address as usize + 2))
        else {
            return false;
        };
        let c = candidate(bx, i);
        let d = [0, 1, 2].map(|k| c[k] - p[k]);
        if d == [0.0; 3] {
            return inside;
        }
        let shear = Shear::new(p, d);
        // In f32 unless a component is so small against the largest that the shear's
        // factors lose their bits (as for the walk's exact rule: `Shear::intersect_f64`).
        let big = d.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        let fine = big >= f32::MIN_POSITIVE * (1u64 << 50) as f32
            && d.iter().all(|x| *x == 0.0 || x.abs() >= big * (1.0 / (1u64 << 40) as f32));
        let refs = v.tri_refs.get(rec[1] as usize..rec[1] as usize + rec[0] as usize).unwrap_or_default();
        let mut odd = false;
        for &prim in refs {
            let Some(tri) = v.triangles.get(prim as usize * TRIANGLE_FLOATS..).and_then(|t| t.get(..TRIANGLE_FLOATS))
            else {
                continue;
            };
            if in_plane(p, tri) {
                // Perhaps on the surface (and the segment need not cross there): answered
                // by the documented rule, along COUNT_DIRECTION.
                return self.contains_near_surface(solid, p);
            }
            // The segment ends at the reference point, clear of every plane: a crossing
            // lies before t = 1 by far. Near t = 0 its side is decided exactly.
            let hit = if self.triangle_test() == TriangleTest::Exact {
                shear.intersect_owned_exact(tri, f32::NEG_INFINITY, 1.0)
            } else if fine {
                shear.intersect_owned(tri, f32::NEG_INFINITY, 1.0)
            } else {
                shear.intersect_owned_f64(tri, f32::NEG_INFINITY, 1.0)
            };
            let Some((t, _, _)) = hit else { continue };
            if t.abs() >= 1.0 / 1024.0 {
                odd ^= t > 0.0;
                continue;
            }
            // Not in the plane (above): the orientation is not zero.
            odd ^= (orientation(p, tri) < 0.0) == arrives_on_front(d, tri);
        }
        inside ^ odd
    }

    /// [`Tracer::contains`] for a point in a leaf with triangles: the parity of the
    /// crossings past it (at a distance above zero) on the way to the first empty leaf
    /// along [`COUNT_DIRECTION`], and that leaf's label (outside where the walk leaves
    /// the scene first).
    #[cold]
    fn contains_near_surface(&self, solid: &Solid, p: [f32; 3]) -> bool {
        let v = self.view();
        let ray = Ray::new(p.into(), COUNT_DIRECTION.into());
        let Some(w) = self.begin(&ray) else { return false };
        let (mut crossings, mut reached) = (0u32, OUTSIDE);
        let counted = |c: Crossing, tri: &[f32]| {
            crossings += ahead(p, &c, tri) as u32;
            ControlFlow::Continue(())
        };
        let empty = |address: u32| {
            let label = v.octree.get(address as usize + 2).and_then(|&b| solid.labels.get(b as usize));
            match label {
                Some(&l) if l <= INSIDE => {
                    reached = l;
                    ControlFlow::Break(())
                }
                _ => ControlFlow::Continue(()),
            }
        };
        self.crossings_entering(w, &mut LeafCrossings::default(), counted, empty);
        (reached == INSIDE) ^ (crossings % 2 == 1)
    }

    /// Whether each point lies inside ([`Tracer::contains`]), on this thread.
    pub fn contains_batch(&self, solid: &Solid, points: &[[f32; 3]], out: &mut [bool]) {
        assert_eq!(points.len(), out.len(), "one result slot a point");
        for (p, o) in points.iter().zip(out) {
            *o = self.contains(solid, *p);
        }
    }

    /// [`Tracer::contains_batch`] on all threads of the current rayon pool.
    pub fn par_contains_batch(&self, solid: &Solid, points: &[[f32; 3]], out: &mut [bool]) {
        use rayon::prelude::*;
        assert_eq!(points.len(), out.len(), "one result slot a point");
        points.par_chunks(4096).zip(out.par_chunks_mut(4096)).for_each(|(p, o)| self.contains_batch(solid, p, o));
    }

    /// The length of `ray` inside the closed mesh `solid` labels (a proof that it is
    /// closed), in units of the ray's `t` (times `|dir|` for a distance): the sum of the
    /// pieces of `[tmin, tmax]` between crossings that the parity of the crossings
    /// after them puts inside (a ray must leave a closed mesh as often as it enters, so
    /// the crossings from a point on to infinity are odd exactly when it is inside).
    pub fn length_inside(&self, solid: &Solid, ray: &Ray) -> f32 {
        let _ = solid;
        let to_infinity = Ray { tmax: f32::INFINITY, ..*ray };
        length_from(ray, &self.all_crossings(&to_infinity))
    }

    /// [`Tracer::length_inside`] of each ray, on this thread (the crossings found
    /// eight rays at a time, `Tracer::crossings_batch`).
    pub fn length_inside_batch(&self, solid: &Solid, rays: &[Ray], out: &mut [f32]) {
        let _ = solid;
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        for (rays, out) in rays.chunks(1024).zip(out.chunks_mut(1024)) {
            let to_infinity: Vec<Ray> = rays.iter().map(|r| Ray { tmax: f32::INFINITY, ..*r }).collect();
            let all = self.crossings_batch(&to_infinity, usize::MAX);
            for (i, (r, o)) in rays.iter().zip(out).enumerate() {
                *o = length_from(r, all.of(i));
            }
        }
    }

    /// [`Tracer::length_inside_batch`] on all threads of the current rayon pool.
    pub fn par_length_inside(&self, solid: &Solid, rays: &[Ray], out: &mut [f32]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(1024).zip(out.par_chunks_mut(1024)).for_each(|(r, o)| self.length_inside_batch(solid, r, o));
    }

    /// Inside or outside by a parity vote over `k` rays (the majority of `k` crossing
    /// counts along fixed directions, `k` odd): for a mesh that is not closed, where
    /// nothing is exact (a ray may leave through a hole); for a closed one it agrees
    /// with [`Tracer::contains`] except on the surface. Each ray costs a full walk.
    pub fn contains_by_vote(&self, p: [f32; 3], k: usize) -> bool {
        let k = k.max(1);
        let inside: usize = (0..k)
            .map(|i| {
                let d = vote_direction(i);
                (self.count_crossings(&Ray::new(p.into(), d.into())).total % 2) as usize
            })
            .sum();
        2 * inside > k
    }
}

impl Tracer<'_> {
    /// [`Tracer::contains_by_vote`] for many points, on all threads of the current rayon
    /// pool, the counts eight rays at a time (`Tracer::count_crossings_batch`).
    pub fn par_contains_by_vote(&self, points: &[[f32; 3]], k: usize, out: &mut [bool]) {
        use rayon::prelude::*;
        assert_eq!(points.len(), out.len(), "one result slot a point");
        let k = k.max(1);
        points.par_chunks(1024).zip(out.par_chunks_mut(1024)).for_each(|(points, out)| {
            let rays: Vec<Ray> = points
                .iter()
                .flat_map(|&p| (0..k).map(move |i| Ray::new(p.into(), vote_direction(i).into())))
                .collect();
            let mut counts = vec![CrossingCount::default(); rays.len()];
            self.count_crossings_batch(&rays, &mut counts);
            for (o, c) in out.iter_mut().zip(counts.chunks(k)) {
                *o = 2 * c.iter().filter(|c| c.total % 2 == 1).count() > k;
            }
        });
    }
}

/// The `i`-th direction of [`Tracer::contains_by_vote`]: spread over the sphere
/// (the golden angle), none in a coordinate plane.
fn vote_direction(i: usize) -> [f32; 3] {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - (2 * i + 1) as f64 / 64.0;
    let r = (1.0 - z * z).sqrt();
    let phi = golden * i as f64 + 0.1234;
    [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
}

/// The length of `ray`'s `[tmin, tmax]` inside, from its crossings from `tmin` to
/// infinity (a point is inside where the crossings after it are odd).
pub(crate) fn length_from(ray: &Ray, crossings: &[Crossing]) -> f32 {
    // A ray that can hit nothing (a NaN interval, ...) is a defined miss: no length,
    // as it has no crossings (the crossings to infinity were found without its tmax).
    if !ray.is_traceable() {
        return 0.0;
    }
    let mut inside = crossings.len() % 2 == 1;
    let (mut t, mut length) = (ray.tmin as f64, 0.0f64);
    for c in crossings {
        let at = (c.t as f64).min(ray.tmax as f64);
        if inside {
            length += at - t;
        }
        t = at;
        inside = !inside;
        if c.t >= ray.tmax {
            break;
        }
    }
    if inside && t < ray.tmax as f64 {
        length += ray.tmax as f64 - t;
    }
    length as f32
}

/// Whether crossing `c` of the ray from `p` along [`COUNT_DIRECTION`] lies at a
/// distance above zero, exactly: its rounded distance may be a few units of `f64`
/// rounding off zero where `p` is a vertex of the triangle, or on one of its edges or
/// in its face. The sign of the distance is the sign of the orientation of `p` against
/// the triangle's plane (Shewchuk's adaptive predicate, exact for `f32` coordinates)
/// times the side the ray arrives from; a point in the plane is at distance zero.
fn ahead(p: [f32; 3], c: &Crossing, tri: &[f32]) -> bool {
    let orientation = orientation(p, tri);
    // Arriving on the front, d . n < 0: ahead where (v0 - p) . n < 0 too.
    orientation != 0.0 && (orientation < 0.0) == c.enters
}

/// `(v0 - p) . ((v1 - p) x (v2 - p)) = (v0 - p) . n` for triangle `tri` (nine floats),
/// whose sign is exact (Shewchuk's `orient3d`): zero when `p` lies in its plane.
fn orientation(p: [f32; 3], tri: &[f32]) -> f64 {
    let point = |x: &[f32]| Coord3D { x: x[0], y: x[1], z: x[2] };
    orient3d(point(&tri[0..3]), point(&tri[3..6]), point(&tri[6..9]), point(&p))
}

/// Whether `p` lies exactly in the plane of `tri` (nine floats): the `f64` triple
/// product first, and where it is within its rounding of zero, [`orientation`].
#[inline(always)]
fn in_plane(p: [f32; 3], tri: &[f32]) -> bool {
    let v = |i: usize| [0, 1, 2].map(|k| tri[3 * i + k] as f64);
    let (a, b, c) = (v(0), v(1), v(2));
    let ap = [a[0] - p[0] as f64, a[1] - p[1] as f64, a[2] - p[2] as f64];
    let (e1, e2) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let g = ap[0] * n[0] + ap[1] * n[1] + ap[2] * n[2];
    let size = |x: [f64; 3]| x[0].abs().max(x[1].abs()).max(x[2].abs());
    // Each operand is exact or within 2^-53 of its value; a few roundings on the way.
    let bound = 1e-13 * size(ap) * size(e1) * size(e2);
    g.abs() <= bound && orientation(p, tri) == 0.0
}

/// The distance from `c` to the plane of `tri` (nine floats), in `f64`; infinite for
/// a degenerate triangle (it has no plane, and no crossing).
fn plane_gap(c: [f32; 3], tri: &[f32]) -> f64 {
    let v = |i: usize| [0, 1, 2].map(|k| tri[3 * i + k] as f64);
    let (a, b, cc) = (v(0), v(1), v(2));
    let (e1, e2) = ([0, 1, 2].map(|k| b[k] - a[k]), [0, 1, 2].map(|k| cc[k] - a[k]));
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len == 0.0 {
        return f64::INFINITY;
    }
    ((0..3).map(|k| (c[k] as f64 - a[k]) * n[k]).sum::<f64>() / len).abs()
}
