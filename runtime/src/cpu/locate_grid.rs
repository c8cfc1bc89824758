//! The grid of the point-location tree's top levels ([`LocateGrid`]), and the descent
//! below it: the data point location (`locate`) reads.

use octrace_format::layout::{NodeRef, MAX_LEVEL};
use octrace_format::SceneView;

/// Descends the point-location tree from `word` (a node at `level`) towards
/// finest-grid cell `q` until a leaf or level `stop`: (the word there, its level). A
/// valid tree has no internal node at `max_depth`; a hostile one (on the trusted path)
/// stops there too, so the descent is bounded whatever the file.
#[inline(always)]
pub(super) fn descend_to(
    view: &SceneView<'_>,
    mut word: u32,
    mut level: u32,
    q: [u32; 3],
    stop: u32,
    depth: u32,
) -> (u32, u32) {
    // `q` is on the grid of `depth`, the depth the tracer uses (the file's, at most the
    // format's limit); `stop <= depth`, so the shift cannot underflow.
    debug_assert!(stop <= depth);
    while let NodeRef::Internal(i) = NodeRef::decode(word) {
        if level >= stop {
            break;
        }
        let shift = (depth - level - 1).min(31);
        let child = (q[0] >> shift & 1) | (q[1] >> shift & 1) << 1 | (q[2] >> shift & 1) << 2;
        word = view.nodes.get(8 * i as usize + child as usize).copied().unwrap_or(0);
        level += 1;
    }
    (word, level)
}

/// The point-location tree's top levels as a grid: for each cell of level `level`, the
/// leaf that holds it (and that leaf's level) or the internal node at that level. A
/// point is located with one load and a short descent instead of up to `max_depth`
/// dependent loads. Built once per scene (`Scene` keeps it).
#[derive(Debug)]
pub struct LocateGrid {
    level: u32,
    words: Vec<u32>,
    /// A level a cell, then three bytes of padding: the eight-ray begin
    /// (`simd::begin8`) gathers them as four-byte words from any cell's byte.
    levels: Vec<u8>,
}

impl LocateGrid {
    /// Grid cells a side at most: 2^6 (262,144 cells, 1.25 MB).
    const MAX_LEVEL: u32 = 6;

    /// The grid of a validated scene.
    pub fn build(view: &SceneView<'_>) -> LocateGrid {
        let depth = view.params.max_depth.min(MAX_LEVEL);
        let level = depth.min(Self::MAX_LEVEL);
        let res = 1u32 << level;
        let shift = depth - level;
        let cells = (res as usize).pow(3);
        let (mut words, mut levels) = (Vec::with_capacity(cells), Vec::with_capacity(cells));
        for z in 0..res {
            for y in 0..res {
                for x in 0..res {
                    let q = [x << shift, y << shift, z << shift];
                    let (word, l) = descend_to(view, view.root, 0, q, level, depth);
                    words.push(word);
                    levels.push(l as u8);
                }
            }
        }
        levels.extend_from_slice(&[0; 3]);
        LocateGrid { level, words, levels }
    }

    /// The grid's level (its cells a side: `2^level`).
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn level(&self) -> u32 {
        self.level
    }

    /// The word to descend from for each cell (x fastest, then y, then z).
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn words(&self) -> &[u32] {
        &self.words
    }

    /// That word's level for each cell, followed by three bytes of padding (a
    /// four-byte read from any cell's byte stays inside).
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[inline(always)]
    pub(crate) fn padded_levels(&self) -> &[u8] {
        &self.levels
    }

    /// The word and level to descend from for finest-grid cell `q`.
    #[inline(always)]
    pub(super) fn entry(&self, q: [u32; 3], max_depth: u32) -> (u32, u32) {
        let shift = max_depth.saturating_sub(self.level).min(31);
        let res = 1usize << self.level;
        let mask = res - 1;
        let i = (((q[2] >> shift) as usize & mask) * res + ((q[1] >> shift) as usize & mask)) * res
            + ((q[0] >> shift) as usize & mask);
        match (self.words.get(i), self.levels.get(i)) {
            (Some(&w), Some(&l)) => (w, l as u32),
            _ => (0, 0),
        }
    }
}
