//! obvhs's CWBVH on the scene's triangles, the comparison peer of `bench` and
//! `report`.

use std::time::{Duration, Instant};

use glam::Vec3A;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray as ORay, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use octrace_runtime::Ray;

pub(crate) struct Peer {
    bvh: CwBvh,
    /// Triangles in the BVH's primitive order, so a leaf reads them in sequence.
    tris: Vec<Triangle>,
    pub build_time: Duration,
}

impl Peer {
    pub(crate) fn build(view: &octrace_format::SceneView<'_>) -> Peer {
        let tris: Vec<Triangle> = view
            .stored_triangles()
            .map(|t| {
                let [a, b, c] = t.map(Vec3A::from);
                Triangle { v0: a, v1: b, v2: c }
            })
            .collect();
        let t = Instant::now();
        let mut core = Duration::ZERO;
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut core);
        let build_time = t.elapsed();
        let tris = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
        Peer { bvh, tris, build_time }
    }

    /// The nearest hit of `r`: its distance and stored triangle (view order).
    pub(crate) fn nearest(&self, r: &Ray) -> Option<(f32, u32)> {
        let ray = ORay::new(r.origin.into(), r.dir.into(), r.tmin, r.tmax);
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |ray, id| self.tris[id].intersect(ray))
            .then(|| (hit.t, self.bvh.primitive_indices[hit.primitive_id as usize]))
    }

    /// Whether anything blocks `r`.
    pub(crate) fn occluded(&self, r: &Ray) -> bool {
        let ray = ORay::new(r.origin.into(), r.dir.into(), r.tmin, r.tmax);
        !self.bvh.ray_traverse_miss(ray, |ray, id| self.tris[id].intersect(ray))
    }

    /// Traces a batch on this thread; returns (hits or occluded, sum of t).
    pub(crate) fn trace(&self, rays: &[Ray], occlusion: bool) -> (usize, f64) {
        let (mut n, mut sum) = (0, 0.0);
        for r in rays {
            let ray = ORay::new(r.origin.into(), r.dir.into(), r.tmin, r.tmax);
            if occlusion {
                n += !self.bvh.ray_traverse_miss(ray, |ray, id| self.tris[id].intersect(ray)) as usize;
            } else {
                let mut hit = RayHit::none();
                if self.bvh.ray_traverse(ray, &mut hit, |ray, id| self.tris[id].intersect(ray)) {
                    n += 1;
                    sum += hit.t as f64;
                }
            }
        }
        (n, sum)
    }
}
