//! Eight walks stepped at once, one a lane of AVX2 registers (x86-64-v3): the batch
//! calls' walk where the processor has AVX2.
//!
//! A step of one walk is about 190 instructions when its leaf is empty (three steps
//! in four on the standard sets), nearly all of them the per-axis arithmetic of the
//! exit face, the neighbour and the next cell. Here that arithmetic runs on eight
//! walks in one pass, each walk in its own lane; the records are read with gathers,
//! and only the walks whose leaf holds triangles leave the registers to test them
//! (`Tracer::test_leaf`, as every step does). A walk that ends hands its lane to the
//! next ray at once. Two groups of eight step in turn, each asking for its next
//! records (and its leaves' references and triangles) ahead, so that one group's
//! loads are in flight while the other steps.
//!
//! Each lane computes what the SSE step (`sse2::step`) computes, with the same
//! operations in the same order (no fused multiply-adds), so each walk visits the
//! same leaves and returns the same bits; the tests check it ray for ray.

use std::arch::x86_64::*;

use octrace_format::layout::{COARSER_SHIFT, LEAF_HEADER_WORDS};

use super::avx2::{self, at_most, mask_of};
use super::begin8::{begin8, Begun};
use super::sse2::SseTest;
use crate::cpu::hw::prefetch;
use crate::cpu::tables::{octant, EXIT_ROWS};
use crate::cpu::tracer::{NoTally, Tracer};
use crate::cpu::walk::{exit_along_moving_axes, LeafVisit, RayWalk};
use crate::cpu::watertight::Shear;
use crate::ray::{Hit, Ray};

/// Walks stepped at once.
pub(super) const LANES: usize = 8;

/// Eight floats, one a lane, aligned for a vector load.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub(super) struct F8(pub(super) [f32; LANES]);

/// Eight words, one a lane, aligned for a vector load.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub(super) struct U8(pub(super) [u32; LANES]);

/// What the vector step reads of each walk, one lane a walk (as `sse2::SseWalk`
/// holds it for one).
#[derive(Debug, Default)]
pub(super) struct Vectors {
    o: [F8; 3],
    d: [F8; 3],
    inv: [F8; 3],
    /// 1.0 where the exit corner is on the cell's high side.
    high: [F8; 3],
    cell: [U8; 3],
    level: U8,
    pub(super) address: U8,
    tmax: F8,
    /// The nearest hit's distance so far (the ray's `tmax` before any).
    pub(super) t_best: F8,
    steps: U8,
    /// The ray octant's row of the exit-face table, four bits a code.
    exits: U8,
}

/// The rest of a walk: what its triangle tests need, and its answer so far.
#[derive(Debug)]
pub(super) struct Walk {
    /// The ray's index in the batch.
    pub(super) index: usize,
    /// The ray's shear, scalar: its triangles go eight at a time (`avx2::hit8`, which
    /// reads the scalar form); the vector form's broadcasts cost a walk more to make
    /// and copy than the rare one-by-one tests gain from them.
    pub(super) shear: Shear,
    pub(super) o: __m128,
    pub(super) d: __m128,
    pub(super) d_s: [f32; 3],
    pub(super) tmin: f32,
    pub(super) best: Option<Hit>,
}

/// Groups of lanes stepped in turn: while one steps, the other's loads are on
/// their way.
pub(super) const GROUPS: usize = 2;

/// Eight walks: their vectors, the rest of each, and the lanes in use.
#[derive(Debug, Default)]
pub(super) struct Group {
    pub(super) v: Vectors,
    pub(super) walks: [Option<Walk>; LANES],
    pub(super) active: u32,
}

/// Leaves whose triangles were asked for lately, by record address (a direct-mapped
/// filter): coherent rays visit the same leaves one after another, and asking again
/// for lines already in the cache costs more than it saves.
#[derive(Debug)]
pub(super) struct Recent(pub(super) [u32; RECENT]);

/// Entries of [`Recent`] (a power of two; 64 caught fewer of the primary rays'
/// repeats: 3-9 % slower on them).
pub(super) const RECENT: usize = 1024;

impl Recent {
    /// Records `address`; returns whether it was not there.
    #[inline(always)]
    pub(super) fn insert(&mut self, address: u32) -> bool {
        let slot = &mut self.0[(address.wrapping_mul(0x9E37_79B1) >> (32 - RECENT.trailing_zeros())) as usize];
        std::mem::replace(slot, address) != address
    }
}

/// Whether the tracer's arrays suit the lanes' gathers (signed 32-bit indices).
pub(crate) fn fits(t: &Tracer<'_>) -> bool {
    t.view().octree.len() <= i32::MAX as usize
}

/// Walks `rays` eight at a time; `done(i, answer)` receives each ray's answer, as
/// `Tracer::interleaved` does.
///
/// # Safety
/// The processor must have x86-64-v3's features (AVX2 and friends), and [`fits`]
/// must hold.
#[target_feature(enable = "avx2,bmi1,bmi2,fma,lzcnt,popcnt")]
pub(crate) unsafe fn trace<const ANY: bool, const TEST: u8>(
    t: &Tracer<'_>,
    rays: &[Ray],
    mut done: impl FnMut(usize, Option<Hit>),
) {
    debug_assert!(fits(t) && t.uses_x86_64_v3());
    let mut groups: [Group; GROUPS] = Default::default();
    let mut recent = Recent([u32::MAX; RECENT]);
    let mut feed = Feed::default();
    // Rays that miss, and those only the scalar step walks (the exact exit rule,
    // re-originated rays): answered off the lanes.
    let off = |done: &mut dyn FnMut(usize, Option<Hit>), i: usize, w: Option<RayWalk>| {
        done(i, w.and_then(|w| t.walk_scalar::<ANY>(w, &mut NoTally)))
    };
    for g in groups.iter_mut() {
        for lane in 0..LANES {
            // SAFETY: AVX2 is this function's.
            unsafe { refill(t, rays, &mut feed, &mut |i, w| off(&mut done, i, w), g, lane) };
        }
    }
    while groups.iter().any(|g| g.active != 0) {
        for g in groups.iter_mut() {
            if g.active == 0 {
                continue;
            }
            // SAFETY: AVX2 is this function's; `fits` is the caller's.
            let mut ended = unsafe { step::<ANY, TEST>(t, g, &mut recent) };
            while ended != 0 {
                let lane = ended.trailing_zeros() as usize;
                ended &= ended - 1;
                // Read in place (the refill overwrites the slot, or empties it).
                if let Some(w) = &g.walks[lane] {
                    done(w.index, t.answer(w.best));
                }
                // SAFETY: AVX2 is this function's.
                unsafe { refill(t, rays, &mut feed, &mut |i, w| off(&mut done, i, w), g, lane) };
            }
        }
    }
}

/// Where the batch stands: the next ray to begin, and what [`begin8`] found for its
/// block of eight (rays `8k..8k + 8`), begun for the whole block when its first ray
/// comes up.
#[derive(Debug, Default)]
pub(super) struct Feed {
    next: usize,
    block: Begun,
}

/// Starts the next ray of the batch that needs a walk in `lane`; rays that cannot
/// hit go to `off(i, None)`, and those only the scalar step walks (the exact exit
/// rule, re-originated rays) to `off(i, Some(walk))`. Rays are begun eight at a time
/// ([`begin8`]); those it leaves take `Tracer::begin`. The lane is left inactive and
/// empty when none is left.
///
/// # Safety
/// AVX2 must be available (inlined into `trace`).
#[inline(always)]
pub(super) unsafe fn refill(
    t: &Tracer<'_>,
    rays: &[Ray],
    feed: &mut Feed,
    off: &mut impl FnMut(usize, Option<RayWalk>),
    g: &mut Group,
    lane: usize,
) {
    g.active &= !(1 << lane);
    while feed.next < rays.len() {
        let i = feed.next;
        feed.next += 1;
        let (l, b) = (i % LANES, &mut feed.block);
        if l == 0 {
            *b = match rays.get(i..i + LANES).and_then(|b| <&[Ray; LANES]>::try_from(b).ok()) {
                // SAFETY: AVX2 is the caller's.
                Some(block) => unsafe { begin8(t, block) },
                None => Begun::default(),
            };
        }
        let start = if b.misses >> l & 1 != 0 {
            None
        } else if b.begun >> l & 1 != 0 {
            Some(Start::begun(&rays[i], b, l))
        } else {
            match t.begin(&rays[i]) {
                // The exact exit rule and re-originated rays are the scalar step's
                // alone: walked to their end here.
                Some(w) if w.scalar_only() => {
                    off(i, Some(w));
                    continue;
                }
                w => w.map(|w| Start::of(&w)),
            }
        };
        match start {
            Some(s) => {
                prefetch(t.view().octree, s.address);
                g.walks[lane] = Some(s.write(&mut g.v, lane, i));
                g.active |= 1 << lane;
                return;
            }
            None => off(i, None),
        }
    }
    g.walks[lane] = None;
}

/// A walk's starting state, from `Tracer::begin` or from [`begin8`] (the same
/// values either way).
struct Start {
    o: [f32; 3],
    d: [f32; 3],
    inv: [f32; 3],
    shear: Shear,
    tmin: f32,
    tmax: f32,
    t_best: f32,
    address: u32,
    level: u32,
    cell: [u32; 3],
}

impl Start {
    #[inline(always)]
    fn of(w: &RayWalk) -> Start {
        Start {
            o: w.o(),
            d: w.d(),
            inv: w.inv(),
            shear: w.shear(),
            tmin: w.tmin(),
            tmax: w.tmax(),
            t_best: w.t_best(),
            address: w.address(),
            level: w.level(),
            cell: w.cell(),
        }
    }

    /// The start [`begin8`] found for `ray`, lane `l` of block `b`: what
    /// `Tracer::begin` makes of the ray's own fields, the rest from the block.
    #[inline(always)]
    fn begun(ray: &Ray, b: &Begun, l: usize) -> Start {
        let (o, d) = (ray.origin.to_array(), ray.dir.to_array());
        Start {
            o,
            d,
            inv: [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]],
            shear: Shear::new(o, d),
            tmin: ray.tmin,
            tmax: b.tmax[l],
            t_best: ray.tmax,
            address: b.address[l],
            level: b.level[l],
            cell: [b.cell[0][l], b.cell[1][l], b.cell[2][l]],
        }
    }

    /// Writes the walk (ray `index`) into `lane`.
    #[inline(always)]
    fn write(&self, v: &mut Vectors, lane: usize, index: usize) -> Walk {
        let Start { o, d, inv, .. } = *self;
        for k in 0..3 {
            v.o[k].0[lane] = o[k];
            v.d[k].0[lane] = d[k];
            v.inv[k].0[lane] = inv[k];
            v.high[k].0[lane] = !d[k].is_sign_negative() as u32 as f32;
            v.cell[k].0[lane] = self.cell[k];
        }
        v.level.0[lane] = self.level;
        v.address.0[lane] = self.address;
        v.tmax.0[lane] = self.tmax;
        v.t_best.0[lane] = self.t_best;
        v.steps.0[lane] = 0;
        v.exits.0[lane] = EXIT_ROWS[octant(d)];
        // SAFETY: SSE2 is enabled at compile time for this module (`simd/mod.rs`).
        unsafe {
            Walk {
                index,
                shear: self.shear,
                o: _mm_setr_ps(o[0], o[1], o[2], 0.0),
                d: _mm_setr_ps(d[0], d[1], d[2], 0.0),
                d_s: d,
                tmin: self.tmin,
                best: None,
            }
        }
    }
}

// Loads, stores and lane picks, inlined into `trace` (AVX2).
#[inline(always)]
unsafe fn ld(x: &F8) -> __m256 {
    // SAFETY: `F8` is 32-byte aligned; AVX is the caller's.
    unsafe { _mm256_load_ps(x.0.as_ptr()) }
}
#[inline(always)]
unsafe fn ldi(x: &U8) -> __m256i {
    // SAFETY: as `ld`.
    unsafe { _mm256_load_si256(x.0.as_ptr().cast()) }
}
#[inline(always)]
unsafe fn sti(x: &mut U8, v: __m256i) {
    // SAFETY: as `ld`.
    unsafe { _mm256_store_si256(x.0.as_mut_ptr().cast(), v) }
}
#[inline(always)]
unsafe fn st(x: &mut F8, v: __m256) {
    // SAFETY: as `ld`.
    unsafe { _mm256_store_ps(x.0.as_mut_ptr(), v) }
}
/// 1.0 where axis `a` is `k`, as a mask.
#[inline(always)]
unsafe fn is(a: __m256i, k: i32) -> __m256 {
    // SAFETY: AVX2 is the caller's.
    unsafe { _mm256_castsi256_ps(_mm256_cmpeq_epi32(a, _mm256_set1_epi32(k))) }
}
/// `bit` where `x > 0`.
#[inline(always)]
unsafe fn positive(x: __m256, bit: i32) -> __m256i {
    // SAFETY: AVX2 is the caller's.
    unsafe {
        _mm256_and_si256(
            _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(x, _mm256_setzero_ps())),
            _mm256_set1_epi32(bit),
        )
    }
}
/// The exit corner's offset from the origin on one axis: `lo + (cell + high) * size - o`.
#[inline(always)]
unsafe fn corner_offset(cellf: __m256, high: __m256, size: __m256, lo: f32, o: __m256) -> __m256 {
    // SAFETY: AVX is the caller's.
    unsafe { _mm256_sub_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_add_ps(cellf, high), size), _mm256_set1_ps(lo)), o) }
}
/// `bit` where the exit point is on the far side of the face's median line across
/// axis `k` (the sign of a Plücker product, flipped on a face down the axis).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn side(
    cellf: __m256,
    half: __m256,
    lo: f32,
    o: __m256,
    d: __m256,
    off_a: __m256,
    d_a: __m256,
    negative_a: __m256i,
    bit: i32,
) -> __m256i {
    // SAFETY: AVX2 is the caller's.
    unsafe {
        let mid = _mm256_add_ps(
            _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(cellf, cellf), _mm256_set1_ps(1.0)), half),
            _mm256_set1_ps(lo),
        );
        let ps = _mm256_sub_ps(_mm256_mul_ps(off_a, d), _mm256_mul_ps(_mm256_sub_ps(mid, o), d_a));
        let above = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(ps, _mm256_setzero_ps()));
        _mm256_and_si256(_mm256_xor_si256(above, negative_a), _mm256_set1_epi32(bit))
    }
}
/// The lanes whose mask is set, as bits.
#[inline(always)]
unsafe fn bits(m: __m256i) -> u32 {
    // SAFETY: AVX is the caller's.
    unsafe { _mm256_movemask_ps(_mm256_castsi256_ps(m)) as u32 }
}
/// Lane by lane, `x` where the axis is 0, `y` where it is 1, else `z`.
#[inline(always)]
unsafe fn pick(x: __m256, y: __m256, z: __m256, is0: __m256, is1: __m256) -> __m256 {
    // SAFETY: AVX is the caller's.
    unsafe { _mm256_blendv_ps(_mm256_blendv_ps(z, y, is1), x, is0) }
}

/// One step of every walk of the group: visits its leaf and moves to the next.
/// Returns the lanes whose walk is over (answers in `walks`).
///
/// # Safety
/// AVX2 must be available (inlined into `trace`); [`fits`] must hold.
#[inline(always)]
unsafe fn step<const ANY: bool, const TEST: u8>(t: &Tracer<'_>, g: &mut Group, recent: &mut Recent) -> u32 {
    let octree = t.view().octree;
    // SAFETY: AVX2 is the caller's (and `fits`, for the gathers of `records` and
    // `advance`).
    unsafe {
        let (count, ncount, ok, mut ended) = records(t, &mut g.v, g.active);
        let (v, walks) = (&mut g.v, &mut g.walks);
        let zero = _mm256_setzero_si256();
        // 2. Triangles, walk by walk, where the leaf has some.
        let mut full = bits(ok) & !bits(_mm256_cmpeq_epi32(count, zero));
        if full != 0 {
            let mut counts = U8::default();
            sti(&mut counts, count);
            // Ask for every leaf's triangle references first: their loads overlap.
            let mut ask = full;
            while ask != 0 {
                let lane = ask.trailing_zeros() as usize;
                ask &= ask - 1;
                let offset = octree[v.address.0[lane] as usize + 1] as usize;
                _mm_prefetch::<_MM_HINT_T0>(t.view().tri_refs.as_ptr().wrapping_add(offset).cast());
            }
            // Then for their triangles, all in flight before the first test waits:
            // dragon incoherent rays 1.14-1.18x (9 paired rounds), the other sets
            // unchanged. Not for a leaf asked for lately (coherent rays: its lines
            // are in the cache, and asking again cost bunny primary rays 5 % more
            // instructions), nor for an any-hit query, which often stops at its
            // first triangle (dragon shadow rays 0.90x).
            let mut ask = if ANY { 0 } else { full };
            while ask != 0 {
                let lane = ask.trailing_zeros() as usize;
                ask &= ask - 1;
                let a = v.address.0[lane] as usize;
                if !recent.insert(a as u32) {
                    continue;
                }
                let (count, offset) = (counts.0[lane] as usize, octree[a + 1] as usize);
                if let Some(refs) = t.view().tri_refs.get(offset..offset.saturating_add(count)) {
                    avx2::prefetch_triangles(t.view().triangles, refs);
                }
            }
            while full != 0 {
                let lane = full.trailing_zeros() as usize;
                full &= full - 1;
                let Some(w) = walks[lane].as_mut() else { continue };
                let a = v.address.0[lane] as usize;
                let (offset, box_index) = (octree[a + 1], octree[a + 2]);
                let test = SseTest::<TEST, Shear> { shear: &w.shear, o: w.o, d: w.d, d_s: w.d_s, wide: true };
                let mut t_best = v.t_best.0[lane];
                let mut visit = LeafVisit { tmin: w.tmin, t_best: &mut t_best, best: &mut w.best };
                if t.test_leaf::<ANY>(counts.0[lane], offset, box_index, &mut visit, &test) {
                    ended |= 1 << lane;
                }
                v.t_best.0[lane] = t_best;
            }
        }
        ended | advance(t, v, g.active, ended, ncount, None)
    }
}

/// Step 1 of a step: each walk's record words `count` and `nCount` (gathered where the
/// record lies in the array and the walk is within its step bound), the lanes read,
/// and the lanes already over. Counts the step.
///
/// # Safety
/// AVX2 must be available; [`fits`] must hold.
#[inline(always)]
pub(super) unsafe fn records(t: &Tracer<'_>, v: &mut Vectors, active: u32) -> (__m256i, __m256i, __m256i, u32) {
    let octree = t.view().octree;
    // SAFETY: AVX2 is the caller's. Every gather is masked to lanes whose index was
    // checked against the array's length (which `fits` keeps below 2^31).
    unsafe {
        let zero = _mm256_setzero_si256();
        let one = _mm256_set1_epi32(1);
        let base = octree.as_ptr().cast::<i32>();
        let len = octree.len() as i32;
        let act = mask_of(active);
        // The record: `count` and `nCount` (words 0 and 3), where it lies in the
        // array, and the step bound.
        let address = ldi(&v.address);
        let steps = _mm256_add_epi32(ldi(&v.steps), one);
        sti(&mut v.steps, steps);
        let within = at_most(steps, _mm256_set1_epi32(t.max_steps() as i32));
        let record_in = if len >= LEAF_HEADER_WORDS as i32 {
            at_most(address, _mm256_set1_epi32(len - LEAF_HEADER_WORDS as i32))
        } else {
            zero
        };
        let ok = _mm256_and_si256(_mm256_and_si256(act, within), record_in);
        let count = _mm256_mask_i32gather_epi32::<4>(zero, base, address, ok);
        let ncount = _mm256_mask_i32gather_epi32::<4>(zero, base.wrapping_add(3), address, ok);
        (count, ncount, ok, active & !bits(ok))
    }
}

/// Steps 3 to 6 of a step, on every lane at once: the exit face and distance, the
/// stop (the best hit inside the leaf, past `tmax`, no neighbour), the neighbour's
/// record and cell. Returns `ended` with the lanes that stop here; `exits`, where
/// given, receives each lane's exit distance.
///
/// # Safety
/// AVX2 must be available; [`fits`] must hold.
#[inline(always)]
pub(super) unsafe fn advance(
    t: &Tracer<'_>,
    v: &mut Vectors,
    active: u32,
    mut ended: u32,
    ncount: __m256i,
    exits: Option<&mut F8>,
) -> u32 {
    let octree = t.view().octree;
    // SAFETY: AVX2 is the caller's. Every gather is masked to lanes whose index was
    // checked against the array's length (which `fits` keeps below 2^31).
    unsafe {
        let zero = _mm256_setzero_si256();
        let zf = _mm256_setzero_ps();
        let one = _mm256_set1_epi32(1);
        let base = octree.as_ptr().cast::<i32>();
        let len = octree.len() as i32;
        let address = ldi(&v.address);
        // 3. Exit corner `lo + (cell + high) * size - o`, and the Plücker exit code.
        let level = ldi(&v.level);
        let size = _mm256_i32gather_ps::<4>(t.cell_sizes().as_ptr(), _mm256_and_si256(level, _mm256_set1_epi32(31)));
        let lo = t.root_lo();
        let o = [ld(&v.o[0]), ld(&v.o[1]), ld(&v.o[2])];
        let d = [ld(&v.d[0]), ld(&v.d[1]), ld(&v.d[2])];
        let cell = [ldi(&v.cell[0]), ldi(&v.cell[1]), ldi(&v.cell[2])];
        let cellf = [_mm256_cvtepi32_ps(cell[0]), _mm256_cvtepi32_ps(cell[1]), _mm256_cvtepi32_ps(cell[2])];
        let off = [
            corner_offset(cellf[0], ld(&v.high[0]), size, lo[0], o[0]),
            corner_offset(cellf[1], ld(&v.high[1]), size, lo[1], o[1]),
            corner_offset(cellf[2], ld(&v.high[2]), size, lo[2], o[2]),
        ];
        let p = [
            _mm256_sub_ps(_mm256_mul_ps(off[0], d[1]), _mm256_mul_ps(off[1], d[0])),
            _mm256_sub_ps(_mm256_mul_ps(off[1], d[2]), _mm256_mul_ps(off[2], d[1])),
            _mm256_sub_ps(_mm256_mul_ps(off[2], d[0]), _mm256_mul_ps(off[0], d[2])),
        ];
        let code = _mm256_or_si256(_mm256_or_si256(positive(p[0], 1), positive(p[1], 2)), positive(p[2], 4));
        let mut face =
            _mm256_and_si256(_mm256_srlv_epi32(ldi(&v.exits), _mm256_slli_epi32::<2>(code)), _mm256_set1_epi32(0xF));
        // A ray with a zero direction component (rare) leaves by the scalar slab
        // rule, whatever the table says (`walk::exit_along_moving_axes`).
        let zeros = _mm256_or_ps(
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(d[0], zf), _mm256_cmp_ps::<_CMP_EQ_OQ>(d[1], zf)),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(d[2], zf),
        );
        let flat = bits(_mm256_castps_si256(zeros)) & active;
        if flat != 0 {
            let mut faces = U8::default();
            sti(&mut faces, face);
            let (mut offs, mut ds) = ([F8::default(); 3], [F8::default(); 3]);
            for k in 0..3 {
                st(&mut offs[k], off[k]);
                st(&mut ds[k], d[k]);
            }
            for lane in (0..LANES).filter(|l| flat >> l & 1 != 0) {
                let of = |x: &[F8; 3]| [x[0].0[lane], x[1].0[lane], x[2].0[lane]];
                let inv = [v.inv[0].0[lane], v.inv[1].0[lane], v.inv[2].0[lane]];
                faces.0[lane] = exit_along_moving_axes(of(&offs), of(&ds), inv) as u32;
            }
            face = ldi(&faces);
        }
        let axis = _mm256_srli_epi32::<1>(face);
        let (is0, is1) = (is(axis, 0), is(axis, 1));
        let off_a = pick(off[0], off[1], off[2], is0, is1);
        let d_a = pick(d[0], d[1], d[2], is0, is1);
        let inv_a = pick(ld(&v.inv[0]), ld(&v.inv[1]), ld(&v.inv[2]), is0, is1);
        // 4. Stop when the best hit is inside this leaf, or past tmax. (Before any hit,
        //    `t_best` is the ray's tmax, at least the walk's: the first test adds no
        //    stop the second does not.)
        let t_exit = _mm256_mul_ps(off_a, inv_a);
        if let Some(exits) = exits {
            st(exits, t_exit);
        }
        let stop = _mm256_or_ps(
            _mm256_cmp_ps::<_CMP_LE_OQ>(ld(&v.t_best), t_exit),
            _mm256_cmp_ps::<_CMP_GE_OQ>(t_exit, ld(&v.tmax)),
        );
        // 5. The neighbour: none, one, or one of four by the sides of the face's
        //    median lines.
        let face4 = _mm256_slli_epi32::<2>(face);
        let n = _mm256_and_si256(_mm256_srlv_epi32(ncount, face4), _mm256_set1_epi32(0xF));
        let stop = _mm256_or_si256(_mm256_castps_si256(stop), _mm256_cmpeq_epi32(n, zero));
        ended |= active & bits(stop);
        let half = _mm256_mul_ps(_mm256_set1_ps(0.5), size);
        let negative_a = _mm256_cmpeq_epi32(_mm256_and_si256(face, one), zero);
        let sides = _mm256_or_si256(
            _mm256_or_si256(
                side(cellf[0], half, lo[0], o[0], d[0], off_a, d_a, negative_a, 1),
                side(cellf[1], half, lo[1], o[1], d[1], off_a, d_a, negative_a, 2),
            ),
            side(cellf[2], half, lo[2], o[2], d[2], off_a, d_a, negative_a, 4),
        );
        let axis_bit = _mm256_sllv_epi32(one, axis);
        let quadrant = _mm256_or_si256(
            _mm256_and_si256(sides, _mm256_sub_epi32(axis_bit, one)),
            _mm256_sllv_epi32(_mm256_srlv_epi32(sides, _mm256_add_epi32(axis, one)), axis),
        );
        // `links_before`: the counts of the faces before this one, summed.
        let below = _mm256_and_si256(ncount, _mm256_sub_epi32(_mm256_sllv_epi32(one, face4), one));
        let nibbles = _mm256_set1_epi32(0x0F0F0F);
        let pairs = _mm256_add_epi32(
            _mm256_and_si256(below, nibbles),
            _mm256_and_si256(_mm256_srli_epi32::<4>(below), nibbles),
        );
        let before = _mm256_and_si256(
            _mm256_srli_epi32::<16>(_mm256_mullo_epi32(pairs, _mm256_set1_epi32(0x010101))),
            _mm256_set1_epi32(0xFF),
        );
        let finer = _mm256_srli_epi32::<2>(n);
        let link = _mm256_add_epi32(
            _mm256_add_epi32(address, _mm256_set1_epi32(LEAF_HEADER_WORDS as i32)),
            _mm256_add_epi32(before, _mm256_mullo_epi32(finer, quadrant)),
        );
        let going = mask_of(active & !ended);
        let link_in = at_most(link, _mm256_set1_epi32(len - 1));
        let follow = _mm256_and_si256(going, link_in);
        ended |= active & !ended & !bits(link_in);
        let next = _mm256_mask_i32gather_epi32::<4>(address, base, link, follow);
        sti(&mut v.address, next);
        // Ask for the next records now: the other group steps before they are read.
        // (A record's links spill onto the next line when it starts late in one.)
        // Every lane, without a branch: a finished walk's lane asks for a line it
        // no longer needs, which costs less than picking the lanes out.
        for &address in &v.address.0 {
            let record = octree.as_ptr().wrapping_add(address as usize);
            _mm_prefetch::<_MM_HINT_T0>(record.cast());
            _mm_prefetch::<_MM_HINT_T0>(record.wrapping_add(15).cast());
        }
        // 6. The next cell: ((across << 1) | child bits) >> (1 + coarser - finer).
        let coarser = _mm256_and_si256(
            _mm256_srlv_epi32(ncount, _mm256_add_epi32(face, _mm256_set1_epi32(COARSER_SHIFT as i32))),
            one,
        );
        // +1 up the axis, -1 down it.
        let up = _mm256_or_si256(negative_a, one);
        let child_bits = _mm256_or_si256(
            _mm256_andnot_si256(axis_bit, sides),
            _mm256_sllv_epi32(_mm256_and_si256(negative_a, one), axis),
        );
        let shift = _mm256_sub_epi32(_mm256_add_epi32(one, coarser), finer);
        for k in 0..3 {
            let on_axis = _mm256_castps_si256(is(axis, k as i32));
            let across = _mm256_add_epi32(cell[k], _mm256_and_si256(on_axis, up));
            let bit = _mm256_and_si256(_mm256_srlv_epi32(child_bits, _mm256_set1_epi32(k as i32)), one);
            let shifted = _mm256_or_si256(_mm256_slli_epi32::<1>(across), bit);
            sti(&mut v.cell[k], _mm256_srlv_epi32(shifted, shift));
        }
        sti(&mut v.level, _mm256_sub_epi32(_mm256_add_epi32(level, finer), coarser));
        ended
    }
}
