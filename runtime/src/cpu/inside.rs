//! Inside or outside of points for a closed mesh, where the octree's cells answer
//! most points without casting a ray.
//!
//! An empty leaf is wholly inside or wholly outside a closed mesh (no triangle comes
//! within the bake's margin of its box), and empty leaves joined by a face link are on
//! the same side: one crossing count from one of them (parity, edges owned:
//! `Tracer::crossings`) labels each connected group. A point in an empty leaf is then
//! answered by point location alone. A point in a leaf with triangles walks on from it
//! in a fixed direction, counting crossings, until it enters an empty leaf (or leaves
//! the scene): that leaf's label, flipped by the parity of the count, is the answer.
//!
//! A point on the surface is answered as the points just beside it along
//! [`COUNT_DIRECTION`] are (crossings at a distance of zero are not counted): a
//! defined answer, the same on every path, where the exact one is a tie.
//! A mesh that is not closed (an edge used by an odd number of triangles) has no
//! inside: it is refused, naming its boundary edges; [`Tracer::contains_by_vote`]
//! gives an approximate answer for it.

use std::ops::ControlFlow;

use octrace_format::layout::{total_links, LEAF_HEADER_WORDS};
use octrace_format::topology::EdgeCensus;

use robust::{orient3d, Coord3D};

use super::crossings::{Crossing, CrossingCount, LeafCrossings};
use super::tracer::Tracer;
use crate::error::{Error, Result};
use crate::ray::Ray;

/// The fixed direction points walk along to an empty leaf (and groups' counts run
/// along): no coordinate plane holds it, so it lies in no cell plane.
pub const COUNT_DIRECTION: [f32; 3] = [0.5773, 0.6151, 0.5371];

/// A leaf's side: empty and outside, empty and inside, or holding triangles.
const OUTSIDE: u8 = 0;
const INSIDE: u8 = 1;
const SURFACE: u8 = 2;

/// The labels of a closed scene's leaves ([`Solid::of`]), for [`Tracer::contains`].
#[derive(Clone, Debug)]
pub struct Solid {
    /// By box index: outside, inside, or a leaf with triangles.
    labels: Vec<u8>,
    /// Connected groups of empty leaves, and how many of them are inside.
    groups: usize,
    inside_groups: usize,
}

impl Solid {
    /// Labels the leaves of `tracer`'s scene, which must be closed (every edge of its
    /// stored triangles used by an even number of them).
    ///
    /// # Errors
    /// [`Error::NotClosed`] for an open scene, with its edge counts.
    pub fn of(tracer: &Tracer<'_>) -> Result<Solid> {
        let v = tracer.view();
        let triangles: Vec<[[f32; 3]; 3]> = (0..v.triangle_count() as u32).map(|t| v.triangle(t)).collect();
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
            records.push((a as u32, rec[0], rec[3]));
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
        for (b, &(address, count, ncount)) in records.iter().enumerate() {
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
        for (b, &(_, count, _)) in records.iter().enumerate() {
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
        let labels = (0..records.len())
            .map(|b| if records[b].1 != 0 { SURFACE } else { side[find(&mut parent, b as u32) as usize] })
            .collect();
        Ok(Solid { labels, groups: roots.len(), inside_groups })
    }

    /// Connected groups of empty leaves (each labelled by one crossing count).
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// Of those, the groups inside.
    pub fn inside_groups(&self) -> usize {
        self.inside_groups
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
        let (address, _, _) = self.locate_cell(p);
        let Some(&box_index) = self.view().octree.get(address as usize + 2) else { return false };
        match solid.labels.get(box_index as usize) {
            Some(&OUTSIDE) => false,
            Some(&INSIDE) => true,
            Some(_) => self.contains_near_surface(solid, p),
            None => false, // a hostile file on the trusted path
        }
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
                Some(&l) if l != SURFACE => {
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
        let crossings = self.all_crossings(&to_infinity);
        let mut inside = crossings.len() % 2 == 1;
        let (mut t, mut length) = (ray.tmin as f64, 0.0f64);
        for c in &crossings {
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

    /// [`Tracer::length_inside`] of each ray, on all threads of the current rayon pool.
    pub fn par_length_inside(&self, solid: &Solid, rays: &[Ray], out: &mut [f32]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_iter().zip(out.par_iter_mut()).for_each(|(r, o)| *o = self.length_inside(solid, r));
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

/// The `i`-th direction of [`Tracer::contains_by_vote`]: spread over the sphere
/// (the golden angle), none in a coordinate plane.
fn vote_direction(i: usize) -> [f32; 3] {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - (2 * i + 1) as f64 / 64.0;
    let r = (1.0 - z * z).sqrt();
    let phi = golden * i as f64 + 0.1234;
    [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
}

/// Whether crossing `c` of the ray from `p` along [`COUNT_DIRECTION`] lies at a
/// distance above zero, exactly: its rounded distance may be a few units of `f64`
/// rounding off zero where `p` is a vertex of the triangle, or on one of its edges or
/// in its face. The sign of the distance is the sign of the orientation of `p` against
/// the triangle's plane (Shewchuk's adaptive predicate, exact for `f32` coordinates)
/// times the side the ray arrives from; a point in the plane is at distance zero.
fn ahead(p: [f32; 3], c: &Crossing, tri: &[f32]) -> bool {
    let point = |x: &[f32]| Coord3D { x: x[0], y: x[1], z: x[2] };
    // (v0 - p) . ((v1 - p) x (v2 - p)) = (v0 - p) . n: the distance's numerator.
    let orientation = orient3d(point(&tri[0..3]), point(&tri[3..6]), point(&tri[6..9]), point(&p));
    // Arriving on the front, d . n < 0: ahead where (v0 - p) . n < 0 too.
    orientation != 0.0 && (orientation < 0.0) == c.enters
}
