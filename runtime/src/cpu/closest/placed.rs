//! The closest point of a scene's triangles as a placement puts them: each vertex
//! carried to the world in `f64` and rounded to `f32` (the triangles a bake of the
//! placed mesh would store), searched through the scene's own tree.
//!
//! A node of the tree bounds the distance from the point carried into the scene's
//! space to its triangles; the placement stretches that distance by at least its least
//! scale, and the placed triangles' rounding moves them by at most `slack`: so
//! `least * local - slack` bounds the world distance from below, and the best-first
//! search prunes by it. Each triangle is measured in the world, as placed, with the
//! search's exact rules (distance correctly rounded, ties to the lower input index).

use octrace_format::distance::Kid;
use octrace_format::layout::TRIANGLE_FLOATS;
use octrace_format::StoredIndex;

use super::{bounds, Best, ClosestPoint, ClosestScratch, Pending, SurfaceBounds};
use crate::cpu::tracer::Tracer;
use crate::world::Transform;

impl Tracer<'_> {
    /// The closest point to `p` (in the world) of this scene's triangles placed by
    /// `to_world` (`to_local` its inverse, `least` a lower bound on the factor it scales
    /// lengths by, `slack` a bound on how far rounding a placed vertex to `f32` moves
    /// it), within `max_distance`; its point, distance and barycentrics those of the
    /// placed triangle.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn closest_point_placed(
        &self,
        bounds: &SurfaceBounds,
        scratch: &mut ClosestScratch,
        p: [f32; 3],
        to_world: &Transform,
        to_local: &Transform,
        least: f64,
        slack: f64,
        max_distance: f32,
    ) -> Option<ClosestPoint> {
        if !p.iter().all(|c| c.is_finite())
            || max_distance.is_nan()
            || max_distance < 0.0
            || least.is_nan()
            || least <= 0.0
        {
            return None;
        }
        let tree = bounds.tree(&self.view)?;
        let pd = p.map(f64::from);
        let local = to_local.point(pd);
        // A local squared distance as a lower bound on the world's.
        let world2 = |d2: f64| {
            let d = least * d2.max(0.0).sqrt() * (1.0 - 1e-9) - slack;
            if d > 0.0 {
                d * d
            } else {
                0.0
            }
        };
        let placed = |prim: u32| -> [[f32; 3]; 3] {
            self.view.triangle(StoredIndex(prim)).map(|v| to_world.point(v.map(f64::from)).map(|c| c as f32))
        };
        let limit = max_distance as f64;
        let limit2 = limit * limit * (1.0 + 1e-6);
        let mut best: Option<Best> = None;
        let heap = &mut scratch.heap;
        heap.clear();
        let (d2, word) = bounds::root(&tree, local);
        heap.push(Pending { d2: world2(d2), node: word });
        let mut visits = 0usize;
        while let Some(next) = heap.pop() {
            let bound = best.map_or(limit2, |b| b.near.d2 + b.near.err);
            if next.d2 * (1.0 - 1e-9) > bound {
                break;
            }
            visits += 1;
            if visits > bounds::node_count(&tree) + 64 {
                break; // each is pushed once: a guard, not a limit
            }
            match tree.kid(next.node) {
                None => {}
                Some(Kid::Cluster(prims)) => {
                    for &prim in prims {
                        let at = prim as usize * TRIANGLE_FLOATS;
                        if self.view.triangles.get(at..at + TRIANGLE_FLOATS).is_none() {
                            continue;
                        }
                        let t = placed(prim);
                        let flat = [t[0][0], t[0][1], t[0][2], t[1][0], t[1][1], t[1][2], t[2][0], t[2][1], t[2][2]];
                        self.closest_in_triangle(p, pd, prim, &flat, &mut best, placed);
                    }
                }
                Some(Kid::Node(node)) => {
                    let bound = best.map_or(limit2, |b| b.near.d2 + b.near.err);
                    for (&word, d2) in node.kids.iter().zip(bounds::distance2(&node.bounds, local)) {
                        let d2 = world2(d2);
                        if d2 * (1.0 - 1e-9) <= bound {
                            heap.push(Pending { d2, node: word });
                        }
                    }
                }
            }
        }
        self.closest_answer(p, best?, max_distance, placed)
    }
}
