//! The closest-point search's tree of a scene ([`octrace_format::distance`]): the
//! scene's own `distance` section where it has one (`bake --distance`: nothing to make
//! at open), else made on the first query from the triangles its leaves list.
//!
//! The octree's leaves are cubes that list every triangle crossing them: a triangle is
//! read again from each leaf it crosses, through an index, and a leaf's bound is its
//! cube's share of the surface. The tree's clusters hold each triangle once, and their
//! bounds are as tight as their triangles: a search measures fewer triangles.

use rayon::prelude::*;

use octrace_format::distance::{self, Bounds8, Tree, CLUSTER};
use octrace_format::layout::TRIANGLE_FLOATS;
use octrace_format::memory::{try_with_capacity, AllocError};
use octrace_format::SceneView;

use super::U;
use crate::cpu::tracer::Tracer;

/// The closest-point search's tree of a scene (see the module docs): the scene's
/// `distance` section, or one made from its triangles (about 24 bytes a triangle and
/// 16 more while it is made: 0.3-0.4 s for the dragon's 871k triangles on one core).
/// [`crate::Scene`] keeps it.
#[derive(Clone, Debug)]
pub struct SurfaceBounds {
    /// The tree's words, or empty where the scene's own section is the tree.
    words: Vec<u32>,
}

impl SurfaceBounds {
    /// The tree of `tracer`'s scene: its `distance` section where its sizes are
    /// sound, else one made from the triangles its leaves list.
    ///
    /// # Errors
    /// [`AllocError`] where the memory for a tree to be made cannot be had.
    pub fn of(tracer: &Tracer<'_>) -> Result<SurfaceBounds, AllocError> {
        let v = tracer.view();
        if Tree::parse(v.distance).is_some() {
            return Ok(SurfaceBounds { words: Vec::new() });
        }
        let count = v.triangles.len() / TRIANGLE_FLOATS;
        let mut listed = try_with_capacity(count, "the distance tree's triangles")?;
        listed.resize(count, false);
        for &prim in v.tri_refs {
            if let Some(l) = listed.get_mut(prim as usize) {
                *l = true;
            }
        }
        Ok(SurfaceBounds { words: distance::build(v.triangles, |i| listed[i])? })
    }

    /// Whether the tree is the scene's own `distance` section (else it was made).
    pub fn is_baked(&self) -> bool {
        self.words.is_empty()
    }

    /// Bytes of the tree made at open (0 where the scene's section is the tree).
    pub fn made_bytes(&self) -> usize {
        4 * self.words.len()
    }

    /// The tree, read from `view` (the scene it was made for) where it is the scene's
    /// section; `None` where that does not parse (another scene's view).
    #[inline]
    pub(super) fn tree<'a>(&'a self, view: &SceneView<'a>) -> Option<Tree<'a>> {
        Tree::parse(if self.words.is_empty() { view.distance } else { &self.words })
    }
}

/// The root's lower bound on the squared distance from `p` (as a node's children's)
/// and its word.
#[inline]
pub(super) fn root(tree: &Tree<'_>, p: [f64; 3]) -> (f64, u32) {
    (distance2(&tree.root.bounds, p)[0], tree.root.kids[0])
}

/// For each child, a lower bound on the squared distance from `p` to the surface
/// in it (infinity where it holds none: its box's gap is infinite): the larger of
/// the box's and the slab's. For `x` in both, `|p - x|^2 = (m.(p - x))^2 / m.m +
/// |P(p - x)|^2` (`P` the projection across `m`): the first is at least the squared
/// gap between `m.p` and the slab, the second at least `|P(p - c)| - R` squared (`c`
/// the box's centre, `R` its half diagonal). Each term shrunk by its rounding.
#[inline(always)]
pub(super) fn distance2(b: &Bounds8, p: [f64; 3]) -> [f64; 8] {
    let mut out = [0.0f64; 8];
    let p_abs = p.map(f64::abs);
    for (l, out) in out.iter_mut().enumerate() {
        let (mut boxed, mut r2) = (0.0f64, 0.0f64);
        let mut c = [0.0f64; 3];
        for k in 0..3 {
            let (lo, hi) = (b.lo[k][l] as f64, b.hi[k][l] as f64);
            let below = lo - p[k];
            let above = p[k] - hi;
            let gap = if below > above { below } else { above };
            let gap = if gap > 0.0 { gap } else { 0.0 };
            boxed += gap * gap;
            c[k] = 0.5 * (lo + hi);
            r2 += 0.25 * (hi - lo) * (hi - lo);
        }
        let m = [b.m[0][l] as f64, b.m[1][l] as f64, b.m[2][l] as f64];
        let mm = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
        let s = m[0] * p[0] + m[1] * p[1] + m[2] * p[2];
        let s_err = 4.0 * U * (m[0].abs() * p_abs[0] + m[1].abs() * p_abs[1] + m[2].abs() * p_abs[2]);
        let below = b.slab[0][l] as f64 - s;
        let above = s - b.slab[1][l] as f64;
        let gap = (if below > above { below } else { above }) - s_err;
        let gap = if gap > 0.0 { gap } else { 0.0 };
        let w = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let along = (m[0] * w[0] + m[1] * w[1] + m[2] * w[2]) / mm;
        let perp = [w[0] - m[0] * along, w[1] - m[1] * along, w[2] - m[2] * along];
        let w_len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        let lateral = (perp[0] * perp[0] + perp[1] * perp[1] + perp[2] * perp[2]).sqrt()
            - r2.sqrt() * (1.0 + 4.0 * U)
            - 16.0 * U * w_len;
        let lateral = if lateral > 0.0 { lateral } else { 0.0 };
        let disk = (gap * gap / mm + lateral * lateral) * (1.0 - 16.0 * U);
        // An empty child: its box's gap is infinite (its centre NaN, so the disk's
        // NaN: the comparison keeps the box's).
        *out = if disk > boxed { disk } else { boxed };
    }
    out
}

/// Asks the processor to start reading what `word` names, which a search will likely
/// open soon: a node's first four cache lines, or a cluster's triangles (of
/// `triangles`, from its first: side by side where the tree was baked).
#[inline(always)]
pub(super) fn prefetch(tree: &Tree<'_>, triangles: &[f32], word: u32) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let at: Option<*const i8> = if word & CLUSTER != 0 {
            let first = tree.firsts.get((word & !CLUSTER) as usize).and_then(|&f| tree.prims.get(f as usize));
            first.and_then(|&t| triangles.get(t as usize * TRIANGLE_FLOATS)).map(|t| std::ptr::from_ref(t).cast())
        } else {
            tree.nodes.get(word as usize).map(|n| std::ptr::from_ref(n).cast())
        };
        if let Some(at) = at {
            for line in 0..4 {
                // SAFETY: a prefetch reads nothing architecturally and cannot fault;
                // SSE (PREFETCHT0) is in every x86-64 target this compiles for.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(64 * line)) };
            }
        }
    }
}

/// The points' indices along a Morton curve through the box `lo..hi` (ten bits an
/// axis: cells of a thousandth of the box; points outside clamp to its faces), so
/// that neighbours come one after the other: `None` for fewer than 64 points, an
/// inverted box, or where the order's memory cannot be had.
fn curve_order_in(lo: [f64; 3], hi: [f64; 3], points: &[[f32; 3]]) -> Option<Vec<u32>> {
    // (An empty surface's box is inverted.)
    if points.len() < 64 || points.len() > u32::MAX as usize || lo[0] > hi[0] || lo[0].is_nan() || hi[0].is_nan() {
        return None;
    }
    let scale = [0, 1, 2].map(|k| if hi[k] > lo[k] { 1023.0 / (hi[k] - lo[k]) } else { 0.0 });
    let spread = |x: u64| {
        let mut x = x & 0x3ff;
        x = (x | x << 16) & 0x0300_00ff;
        x = (x | x << 8) & 0x0300_f00f;
        x = (x | x << 4) & 0x030c_30c3;
        (x | x << 2) & 0x0924_9249
    };
    let mut keyed: Vec<(u32, u32)> = try_with_capacity(points.len(), "points in curve order").ok()?;
    keyed.extend(points.iter().enumerate().map(|(i, p)| {
        // NaN and the infinities clamp to an end.
        let q = [0, 1, 2].map(|k| ((p[k] as f64 - lo[k]) * scale[k]).clamp(0.0, 1023.0) as u64);
        ((spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2) as u32, i as u32)
    }));
    keyed.par_sort_unstable();
    let mut order: Vec<u32> = try_with_capacity(points.len(), "points in curve order").ok()?;
    order.extend(keyed.iter().map(|k| k.1));
    Some(order)
}

/// `answer(points, out)` with the points taken along [`curve_order_in`]'s curve
/// (neighbours share a tree's nodes in cache), the answers written where their points
/// are; as they come where the order or its copies' memory cannot be had.
pub(crate) fn along_curve<T: Clone + Default>(
    lo: [f64; 3],
    hi: [f64; 3],
    points: &[[f32; 3]],
    out: &mut [T],
    answer: impl FnOnce(&[[f32; 3]], &mut [T]),
) {
    let sorted = curve_order_in(lo, hi, points).and_then(|order| {
        let mut sorted: Vec<[f32; 3]> = try_with_capacity(points.len(), "points in curve order").ok()?;
        sorted.extend(order.iter().map(|&i| points[i as usize]));
        let mut found: Vec<T> = try_with_capacity(points.len(), "points in curve order").ok()?;
        found.resize(points.len(), T::default());
        Some((order, sorted, found))
    });
    match sorted {
        Some((order, sorted, mut found)) => {
            answer(&sorted, &mut found);
            for (&i, a) in order.iter().zip(found) {
                out[i as usize] = a;
            }
        }
        None => answer(points, out),
    }
}

/// How many nodes and clusters `tree` has (a bound on a search's steps).
pub(super) fn node_count(tree: &Tree<'_>) -> usize {
    tree.nodes.len() + tree.clusters()
}
