//! Memory order for incoherent batches: rays sorted by the cell they start in.
//!
//! A walk is a chain of dependent loads, and a batch of random rays sends each walk
//! to a different part of the file: on the dragon (64 MB) most loads miss the cache.
//! Rays that start in the same small region of the scene, going the same way, read
//! the same leaves first; walked one after another, those leaves are loaded once for
//! all of them. This is the first step of Pharr et al.'s memory-coherent ray tracing
//! (1997), rays grouped by where their walk begins rather than queued at every leaf:
//! the sort is a few milliseconds a million rays, and it leaves each ray's answer as
//! it was (a batch's answers are each ray's own, whatever order they are walked in).
//!
//! Coherent batches (camera rays, shadow rays towards one light, in pixel order) walk
//! the same leaves one after another already, and sorting them would only cost:
//! [`memory_order`] tells them apart by sampling consecutive rays.

use super::tracer::{MemoryOrder, Tracer};
use crate::ray::Ray;

/// Batches shorter than this are walked as given: too few rays share a leaf for the
/// sort to pay.
const MIN_RAYS: usize = 4096;

/// Bits of each coordinate in the sort key: cells of a 64^3 grid over the root cube
/// (10 bits, 1024^3, sorted no better on the dragon).
const CELL_BITS: u32 = 6;

/// Consecutive pairs sampled to decide whether a batch is coherent.
const SAMPLE_PAIRS: usize = 256;

/// The order to walk `rays` in under `rule`, as indices into `rays`, or `None` to
/// walk them as given: memory order off, a scene that stays in the cache (for
/// [`MemoryOrder::Auto`]), a batch too short, or one coherent already (at least half
/// the sampled consecutive pairs start in the same cell and go the same way).
pub(crate) fn memory_order(t: &Tracer<'_>, rays: &[Ray], rule: MemoryOrder) -> Option<Vec<u32>> {
    let wanted = match rule {
        MemoryOrder::Off => false,
        MemoryOrder::Incoherent => true,
        MemoryOrder::Auto => t.outgrows_cache(),
    };
    if !wanted || rays.len() < MIN_RAYS || rays.len() > u32::MAX as usize {
        return None;
    }
    let key = Key::new(t);
    // Four stretches of consecutive rays, spread over the batch.
    let stretch = SAMPLE_PAIRS / 4;
    let alike = (0..4)
        .map(|k| k * (rays.len() - stretch - 1) / 3)
        .flat_map(|start| start..start + stretch)
        .filter(|&i| key.of(&rays[i]) == key.of(&rays[i + 1]))
        .count();
    if 2 * alike >= SAMPLE_PAIRS {
        return None;
    }
    let mut keyed: Vec<u64> = rays.iter().enumerate().map(|(i, r)| (key.of(r) as u64) << 32 | i as u64).collect();
    radix_sort(&mut keyed, Key::BITS);
    Some(keyed.into_iter().map(|k| k as u32).collect())
}

/// A ray's sort key: the Morton code of the grid cell holding its origin (clamped
/// into the root cube), then its direction's octant.
struct Key {
    lo: [f32; 3],
    scale: f32,
}

impl Key {
    /// Bits a key has.
    const BITS: u32 = 3 * CELL_BITS + 3;

    fn new(t: &Tracer<'_>) -> Key {
        let b = t.view().bounds;
        Key { lo: b.root_lo, scale: (1u32 << CELL_BITS) as f32 / b.root_size }
    }

    #[inline]
    fn of(&self, r: &Ray) -> u32 {
        let o = r.origin.to_array();
        let last = (1u32 << CELL_BITS) - 1;
        // NaN clamps to 0 (`max`), infinities to the ends (`as` saturates): any ray
        // gets a key, and untraceable ones are answered as usual when walked.
        let q = |a: usize| (((o[a] - self.lo[a]) * self.scale).max(0.0) as u32).min(last);
        let octant = (r.dir.x < 0.0) as u32 | ((r.dir.y < 0.0) as u32) << 1 | ((r.dir.z < 0.0) as u32) << 2;
        (spread(q(0)) | spread(q(1)) << 1 | spread(q(2)) << 2) << 3 | octant
    }
}

/// The bits of `x` (below 2^[`CELL_BITS`]) two places apart.
#[inline]
fn spread(x: u32) -> u32 {
    SPREAD[x as usize & ((1 << CELL_BITS) - 1)]
}

/// [`spread`] of every cell coordinate.
const SPREAD: [u32; 1 << CELL_BITS] = {
    let mut table = [0; 1 << CELL_BITS];
    let mut x = 0;
    while x < table.len() {
        let mut b = 0;
        while b < CELL_BITS {
            table[x] |= ((x as u32) >> b & 1) << (3 * b);
            b += 1;
        }
        x += 1;
    }
    table
};

/// Sorts `keys` by their top half's low `bits` bits, stably (least significant digit
/// first, 11 bits a pass).
fn radix_sort(keys: &mut Vec<u64>, bits: u32) {
    const DIGIT: u32 = 11;
    let mut other = vec![0u64; keys.len()];
    let mut shift = 32;
    while shift < 32 + bits {
        let digit = |k: u64| (k >> shift) as usize & ((1 << DIGIT) - 1);
        let mut starts = vec![0usize; 1 << DIGIT];
        for &k in keys.iter() {
            starts[digit(k)] += 1;
        }
        let mut sum = 0;
        for s in starts.iter_mut() {
            (*s, sum) = (sum, sum + *s);
        }
        for &k in keys.iter() {
            let d = digit(k);
            other[starts[d]] = k;
            starts[d] += 1;
        }
        std::mem::swap(keys, &mut other);
        shift += DIGIT;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_radix_sort_is_a_stable_sort_by_key() {
        let mut state = 12345u64;
        let mut keys: Vec<u64> = (0..50_000u64)
            .map(|i| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 43) & ((1 << Key::BITS) - 1)) << 32 | i
            })
            .collect();
        let mut want = keys.clone();
        want.sort_by_key(|k| k >> 32); // stable
        radix_sort(&mut keys, Key::BITS);
        assert_eq!(keys, want);
    }

    #[test]
    fn spread_interleaves_bits() {
        assert_eq!(spread(0b111111), 0b001001001001001001);
        assert_eq!(spread(0b101), 0b001000001);
    }
}
