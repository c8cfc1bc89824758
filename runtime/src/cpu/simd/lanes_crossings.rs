//! Every crossing of a batch of rays, eight walks at once in AVX2 lanes: the lanes'
//! walk (`lanes.rs`: records gathered, and the exit, the neighbour and the next cell
//! of eight walks in one pass) with the crossing walk's leaves (`crossings.rs`: each
//! leaf reports the crossings in its piece of the ray, edges owned, in order).
//!
//! A walk's leaf is tested over the ray's whole interval (its exit is not known until
//! the vector pass), its crossings past the previous exit kept aside; once the pass
//! has the exit, those up to it are the leaf's piece, sorted into the ray's list, and
//! the others dropped (a later leaf lists them again). Every lane's walk answers as
//! `Tracer::crossings` does, the same bits (the tests check it ray for ray).

use std::arch::x86_64::*;

use octrace_format::layout::TRIANGLE_FLOATS;

use super::avx2::{self, crossings8};
use super::begin8::mask8;
use super::lanes::{advance, records, refill, Feed, Group, Recent, Walk, F8, GROUPS, LANES, RECENT};
use crate::cpu::crossings::{arrives_on_front, sort_piece, Crossing, CrossingSink, LeafCrossings};
use crate::cpu::fans;
use crate::cpu::tracer::{Tracer, TriangleTest};
use crate::cpu::walk::RayWalk;
use crate::ray::Ray;

/// A lane's crossings: where the ray's current piece starts, what the current leaf
/// found past it (each with its stored triangle's index, which orders ties of rounded
/// distances under the exact test), and the ray's list so far.
#[derive(Debug, Default)]
struct Lane {
    lo: f32,
    pending: Vec<(Crossing, u32)>,
    list: Vec<Crossing>,
}

/// Walks `rays` eight at a time, handing each ray's first `limit` crossings to `sink`,
/// with the crossing walk's test: the exact one under `TriangleTest::Exact`, else the
/// watertight one with edges owned (as `Tracer::crossings`).
///
/// # Safety
/// The processor must have x86-64-v3's features (AVX2 and friends), and
/// `lanes::fits` must hold.
#[target_feature(enable = "avx2,bmi1,bmi2,fma,lzcnt,popcnt")]
pub(crate) unsafe fn trace(t: &Tracer<'_>, rays: &[Ray], limit: usize, sink: &mut impl CrossingSink) {
    let mut groups: [Group; GROUPS] = Default::default();
    let mut lanes: [[Lane; LANES]; GROUPS] = Default::default();
    let mut recent = Recent([u32::MAX; RECENT]);
    let mut feed = Feed::default();
    let mut scratch = LeafCrossings::default();
    // Rays that miss answer an empty list; those only the scalar walk takes (the exact
    // exit rule, re-originated rays) are walked off the lanes.
    let mut list = Vec::new();
    let off = |sink: &mut dyn FnMut(usize, &[Crossing]),
               list: &mut Vec<Crossing>,
               scratch: &mut LeafCrossings,
               i: usize,
               w: Option<RayWalk>| {
        list.clear();
        if let Some(w) = w {
            t.crossings_from(w, scratch, |c| {
                list.push(c);
                if list.len() >= limit {
                    std::ops::ControlFlow::Break(())
                } else {
                    std::ops::ControlFlow::Continue(())
                }
            });
        }
        sink(i, list);
    };
    let mut emit = |i: usize, c: &[Crossing]| sink.ray(i, c);
    let exact = t.triangle_test() == TriangleTest::Exact;
    for (g, ls) in groups.iter_mut().zip(lanes.iter_mut()) {
        for lane in 0..LANES {
            // SAFETY: AVX2 is this function's.
            unsafe { refill(t, rays, &mut feed, &mut |i, w| off(&mut emit, &mut list, &mut scratch, i, w), g, lane) };
            ls[lane].lo = f32::NEG_INFINITY;
        }
    }
    while groups.iter().any(|g| g.active != 0) {
        for (g, ls) in groups.iter_mut().zip(lanes.iter_mut()) {
            if g.active == 0 {
                continue;
            }
            // SAFETY: AVX2 is this function's; `fits` is the caller's.
            let mut ended = unsafe {
                match exact {
                    true => step::<true>(t, g, ls, &mut recent, limit),
                    false => step::<false>(t, g, ls, &mut recent, limit),
                }
            };
            while ended != 0 {
                let lane = ended.trailing_zeros() as usize;
                ended &= ended - 1;
                if let Some(w) = &g.walks[lane] {
                    let l = &mut ls[lane];
                    l.list.truncate(limit);
                    emit(w.index, &l.list);
                    l.list.clear();
                    l.pending.clear();
                }
                // SAFETY: AVX2 is this function's.
                unsafe {
                    refill(t, rays, &mut feed, &mut |i, w| off(&mut emit, &mut list, &mut scratch, i, w), g, lane)
                };
                ls[lane].lo = f32::NEG_INFINITY;
            }
        }
    }
}

/// One step of every walk of the group: its leaf's crossings, then the exit, the
/// piece's crossings sorted into each ray's list, and the next leaf. Returns the lanes
/// whose walk is over. `EXACT`: the tracer's test is `TriangleTest::Exact`.
///
/// # Safety
/// AVX2 must be available (inlined into `trace`); `lanes::fits` must hold.
#[inline(always)]
unsafe fn step<const EXACT: bool>(
    t: &Tracer<'_>,
    g: &mut Group,
    ls: &mut [Lane; LANES],
    recent: &mut Recent,
    limit: usize,
) -> u32 {
    let octree = t.view().octree;
    // SAFETY: AVX2 is the caller's (and `fits`, for `records` and `advance`).
    unsafe {
        let (count, ncount, ok, ended) = records(t, &mut g.v, g.active);
        let zero = _mm256_setzero_si256();
        let mask = |m: __m256i| _mm256_movemask_ps(_mm256_castsi256_ps(m)) as u32;
        let mut full = mask(ok) & !mask(_mm256_cmpeq_epi32(count, zero));
        let counts: [u32; LANES] = std::mem::transmute(count);
        // The leaves' references and triangles asked for before the first test.
        let mut ask = full;
        while ask != 0 {
            let lane = ask.trailing_zeros() as usize;
            ask &= ask - 1;
            let a = g.v.address.0[lane] as usize;
            if !recent.insert(a as u32) {
                continue;
            }
            let offset = octree[a + 1] as usize;
            if let Some(refs) = t.view().tri_refs.get(offset..offset.saturating_add(counts[lane] as usize)) {
                avx2::prefetch_triangles(t.view().triangles, refs);
            }
        }
        let mut found = 0u32;
        while full != 0 {
            let lane = full.trailing_zeros() as usize;
            full &= full - 1;
            let Some(w) = g.walks[lane].as_ref() else { continue };
            let a = g.v.address.0[lane] as usize;
            let (offset, box_index) = (octree[a + 1], octree[a + 2]);
            // Tested up to the ray's tmax (`t_best`, never lowered here).
            let tmax = g.v.t_best.0[lane];
            leaf_crossings::<EXACT>(t, w, &mut ls[lane], (counts[lane], offset, box_index), tmax);
            found |= (!ls[lane].pending.is_empty() as u32) << lane;
        }
        let mut exits = F8::default();
        let ended = advance(t, &mut g.v, g.active, ended, ncount, Some(&mut exits));
        // Each piece ends at the exit (never before its start), or at tmax where the
        // walk ends: every lane at once, `maxps` taking the exit first (a NaN exit, of
        // a lane not in use, leaves the start).
        let ends = mask8(ended);
        let lo = _mm256_loadu_ps(lo_of(ls).as_ptr());
        let hi = _mm256_blendv_ps(
            _mm256_max_ps(_mm256_loadu_ps(exits.0.as_ptr()), lo),
            _mm256_loadu_ps(g.v.t_best.0.as_ptr()),
            ends,
        );
        let mut his = [0.0f32; LANES];
        _mm256_storeu_ps(his.as_mut_ptr(), hi);
        // The pieces' crossings, sorted into the rays' lists.
        let mut over = 0;
        let mut flush = found;
        while flush != 0 {
            let lane = flush.trailing_zeros() as usize;
            flush &= flush - 1;
            let (l, hi) = (&mut ls[lane], his[lane]);
            l.pending.retain(|c| c.0.t <= hi);
            if let Some(w) = g.walks[lane].as_ref() {
                sort_piece(t.view().triangles, &w.shear, EXACT, &mut l.pending);
            }
            l.list.extend(l.pending.drain(..).map(|c| c.0));
            over |= ((l.list.len() >= limit) as u32) << lane;
        }
        for (l, &hi) in ls.iter_mut().zip(&his) {
            l.lo = hi;
        }
        ended | over
    }
}

/// The pieces' starts of a group's lanes.
#[inline(always)]
fn lo_of(ls: &[Lane; LANES]) -> [f32; LANES] {
    std::array::from_fn(|i| ls[i].lo)
}

/// Lane `l`'s crossings in its leaf (`count` references from `offset`, box index
/// `box_index`) past its piece's start, up to `tmax`, into `l.pending`: eight triangles
/// at a time, one by one where an edge function is zero (ownership) or an index is out
/// of range. In a fan's leaf, the triangles its hierarchy picks (`fans.rs`), except
/// under the exact test (`EXACT`), which tests leaves whole, as the scalar walk does.
#[inline(always)]
fn leaf_crossings<const EXACT: bool>(
    t: &Tracer<'_>,
    w: &Walk,
    l: &mut Lane,
    (count, offset, box_index): (u32, u32, u32),
    tmax: f32,
) {
    let v = t.view();
    let refs = v.tri_refs.get(offset as usize..offset as usize + count as usize).unwrap_or_default();
    let mut room = fans::candidates_room();
    let refs = t.fan_refs((box_index, offset, refs), || (!EXACT).then_some(&w.shear), true, &mut room).unwrap_or(refs);
    let lo = l.lo;
    for chunk in refs.chunks(LANES) {
        let mut push = |prim: u32, (tt, u, vv): (f32, f32, f32), enters: bool| {
            if tt > lo {
                if let Some(&triangle) = v.triangle_ids.get(prim as usize) {
                    l.pending.push((Crossing { t: tt, triangle, u, v: vv, enters }, prim));
                }
            }
        };
        // SAFETY: the lanes run only where the processor has AVX2.
        let batched = unsafe {
            crossings8::<EXACT>(&w.shear, v.triangles, chunk, w.tmin, tmax, |i, tt, u, vv, enters| {
                push(chunk[i], (tt, u, vv), enters)
            })
        };
        if batched {
            continue;
        }
        for &prim in chunk {
            let Some(tri) = v.triangles.get(prim as usize * TRIANGLE_FLOATS..).and_then(|x| x.get(..TRIANGLE_FLOATS))
            else {
                continue;
            };
            let hit = match EXACT {
                true => w.shear.intersect_owned_exact(tri, w.tmin, tmax),
                false => w.shear.intersect_owned(tri, w.tmin, tmax),
            };
            if let Some(hit) = hit {
                push(prim, hit, arrives_on_front(w.d_s, tri));
            }
        }
    }
}
