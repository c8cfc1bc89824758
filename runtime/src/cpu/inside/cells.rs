//! The labels of a closed scene again on a grid of the root cube, so that most points
//! are answered by one or two reads: coarse cells that lie wholly in empty leaves of
//! one side, and, in the coarse cells where the surface is, blocks of 8 x 8 x 8 finer
//! cells labelled where no triangle touches them.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};

use octrace_format::layout::TRIANGLE_FLOATS;
use octrace_format::SceneView;

use super::{INSIDE, OUTSIDE};

/// A coarse or fine cell not known to lie on one side.
const MIXED: u8 = 255;
/// A coarse cell no leaf has been seen in yet (while building).
const UNSEEN: u8 = 254;

/// Fine cells a side of a coarse cell's block.
const SUB: usize = 8;
const SUB_BITS: u32 = 3;
/// A coarse cell with a block (while building).
const BLOCK: u8 = 253;
/// A coarse cell's code, two bits: `OUTSIDE`, `INSIDE`, mixed, or with a block.
const CODE_MIXED: u64 = 2;
const CODE_BLOCK: u64 = 3;
/// The low bit of each code of a word.
const LOW_BITS: u64 = 0x5555_5555_5555_5555;
/// A block's fine cells, two bits each (`OUTSIDE`, `INSIDE`, or [`FINE_MIXED`]): a
/// word a slice across z, cell `y * 8 + x` at bits `2 (y * 8 + x)` (a query reads 16
/// bytes of the block's 128).
type Block = [u128; SUB];
const FINE_MIXED: u128 = 2;
/// A block of mixed fine cells.
const ALL_MIXED: Block = [u128::MAX / 3 * 2; SUB];
/// A set of a block's fine cells: a word a slice across z, bit `y * 8 + x`.
type Bits = [u64; SUB];
const NONE: Bits = [0; SUB];
const ALL: Bits = [u64::MAX; SUB];

/// What a mixed coarse cell becomes: one label where no triangle touches it after
/// all (a cell of a leaf with triangles, away from them), or a block.
pub(super) enum Fine {
    Label(u8),
    Block(Block),
}
/// At most this many blocks (128 bytes each: 32 MiB).
const MAX_BLOCKS: usize = 1 << 18;
/// At most this many fine cells looked at for triangles (seconds): a file of
/// many large triangles over fine leaves (a hostile one) gets no blocks past it.
const MAX_WORK: u64 = 1 << 28;
/// At most this many groups of fine cells labelled by `contains` (a second or so): past
/// it (a file whose triangles cut blocks into many pockets), groups stay mixed.
const MAX_ASKED: u64 = 1 << 20;

/// A uniform grid over the root cube, `2^level` coarse cells a side, each labelled
/// [`OUTSIDE`] or [`INSIDE`] where it lies wholly in empty leaves of that side; the
/// others (the surface's) hold a block of `8^3` fine cells, labelled where no triangle
/// touches the fine cell (the side of one point of it then is the side of all), else
/// mixed. The leaves are cells of the same cube, so a leaf either covers whole coarse
/// cells or lies in one.
#[derive(Clone, Debug, Default)]
pub(super) struct Cells {
    level: u32,
    lo: [f64; 3],
    /// Fine cells per unit of length.
    scale: f64,
    /// By coarse cell, while building: `OUTSIDE`, `INSIDE`, [`MIXED`] or [`BLOCK`].
    entries: Vec<u8>,
    /// The same, two bits a cell ([`CODE_MIXED`], [`CODE_BLOCK`]), 32 cells a word
    /// (the grid of 128 cells a side in 512 KiB), once built.
    codes: Vec<u64>,
    /// By word of `codes`, the blocks of the cells before it.
    rank: Vec<u32>,
    /// The blocks, in the order of their cells.
    blocks: Vec<Block>,
}

impl Cells {
    /// The coarse labels from the leaves' (`labels`, by box index: `OUTSIDE`, `INSIDE`,
    /// or anything else for a leaf with triangles): the finest grid of at most 2^21
    /// cells, and at most twice as fine as the leaves. No blocks yet
    /// ([`Cells::blocks`]).
    pub(super) fn of(v: &SceneView<'_>, labels: &[u8]) -> Cells {
        let b = v.bounds;
        let level = (v.params.max_depth + 1).min(7);
        let side = 1usize << level;
        let lo = b.root_lo.map(f64::from);
        let scale = side as f64 / b.root_size as f64;
        let mut grid = vec![UNSEEN; side * side * side];
        // Leaves do not overlap, so they write each cell once, or share one: a file
        // whose boxes write more (a hostile file on the trusted path) gets no grid.
        let mut budget = grid.len() + labels.len();
        for (i, &label) in labels.iter().enumerate() {
            let Some(bx) = v.boxes.get(i * 6..i * 6 + 6) else { break };
            let label = if label <= INSIDE { label } else { MIXED };
            let (from, to) = span(bx, lo, scale, side);
            let cells = (0..3).map(|k| to[k] - from[k]).product::<usize>();
            if cells > budget {
                return Cells::default();
            }
            budget -= cells;
            for z in from[2]..to[2] {
                for y in from[1]..to[1] {
                    for x in from[0]..to[0] {
                        let cell = &mut grid[(z * side + y) * side + x];
                        *cell = if *cell == UNSEEN || *cell == label { label } else { MIXED };
                    }
                }
            }
        }
        let entries = grid.into_iter().map(|c| if c <= INSIDE { c } else { MIXED }).collect();
        Cells { level, lo, scale: scale * SUB as f64, entries, ..Cells::default() }
    }

    /// Blocks of fine labels for the mixed coarse cells (up to [`MAX_BLOCKS`]): a fine
    /// cell that no triangle touches (each triangle's plane and box tested against the
    /// fine cells its box reaches, conservatively) is on one side throughout, and
    /// fine cells so joined through faces, or through a face with a coarse cell of one
    /// side, are on the same side; `side` labels one point of each group that meets no
    /// such coarse cell (`contains`, exact, which may read these coarse cells).
    pub(super) fn blocks(&self, v: &SceneView<'_>, side: impl Fn([f32; 3]) -> bool + Sync) -> Vec<(u32, Fine)> {
        use rayon::prelude::*;
        let mixed: Vec<u32> =
            (0..self.entries.len() as u32).filter(|&c| self.entries[c as usize] == MIXED).take(MAX_BLOCKS).collect();
        if mixed.is_empty() {
            return Vec::new();
        }
        // By coarse cell, its place in `mixed` (or u32::MAX).
        let mut slot = vec![u32::MAX; self.entries.len()];
        for (i, &c) in mixed.iter().enumerate() {
            slot[c as usize] = i as u32;
        }
        let touched: Vec<[AtomicU64; SUB]> =
            (0..mixed.len()).map(|_| std::array::from_fn(|_| AtomicU64::new(0))).collect();
        let coarse = 1usize << self.level;
        let fine_side = coarse * SUB;
        let size = 1.0 / self.scale;
        let half = 0.5 * size;
        let root_far = self.lo.iter().fold(0.0f64, |m, x| m.max(x.abs()).max((x + fine_side as f64 * size).abs()));
        let count = v.triangles.len() / TRIANGLE_FLOATS;
        let (work, gave_up) = (AtomicU64::new(0), AtomicBool::new(false));
        (0..count).into_par_iter().for_each(|prim| {
            if gave_up.load(Relaxed) {
                return;
            }
            let t = &v.triangles[prim * TRIANGLE_FLOATS..(prim + 1) * TRIANGLE_FLOATS];
            if !t.iter().all(|x| x.is_finite()) {
                // Nothing is certain about where it lies (a hostile file on the trusted
                // path): no blocks at all.
                gave_up.store(true, Relaxed);
                return;
            }
            let tri = [0, 3, 6].map(|o| [t[o] as f64, t[o + 1] as f64, t[o + 2] as f64]);
            let big = t.iter().fold(root_far.max(half), |m, x| m.max(x.abs() as f64));
            let h = half + slack(big);
            // The fine cells the triangle's box reaches, grown as the cubes are.
            let (mut from, mut to) = ([0usize; 3], [0usize; 3]);
            for k in 0..3 {
                let lo = tri[0][k].min(tri[1][k]).min(tri[2][k]) - 2.0 * slack(big);
                let hi = tri[0][k].max(tri[1][k]).max(tri[2][k]) + 2.0 * slack(big);
                let a = floor((lo - self.lo[k]) * self.scale);
                let b = floor((hi - self.lo[k]) * self.scale);
                if !(a < fine_side as f64 && b >= 0.0) {
                    return; // outside the root: touches none of its cells
                }
                from[k] = a.clamp(0.0, (fine_side - 1) as f64) as usize;
                to[k] = b.clamp(0.0, (fine_side - 1) as f64) as usize;
            }
            let probe = Probe::new(tri);
            // Column by column across the normal's largest axis `k`, only the cells
            // whose span along `k` meets the plane's over the column (widened far
            // beyond the rounding), where the normal is well measured.
            let k = probe.n.map_or(2, |n| (0..3).max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs())).unwrap_or(2));
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let reach = probe.n.map(|n| (n[i].abs() + n[j].abs()) * h / n[k].abs() + h + 2.0 * slack(big));
            // The cells this triangle will look at, at most, within the budget.
            let depth = reach.map_or(f64::INFINITY, |r| 2.0 * r * self.scale + 2.0).min((to[k] - from[k] + 1) as f64);
            let cells = ((to[i] - from[i] + 1) * (to[j] - from[j] + 1)) as f64 * (depth + 1.0);
            if work.fetch_add(cells as u64, Relaxed) + cells as u64 > MAX_WORK {
                gave_up.store(true, Relaxed);
                return;
            }
            for a in from[i]..=to[i] {
                for b in from[j]..=to[j] {
                    let (mut first, mut last) = (from[k], to[k]);
                    if let (Some(n), Some(reach)) = (probe.n, reach) {
                        let ci = self.lo[i] + (a as f64 + 0.5) * size;
                        let cj = self.lo[j] + (b as f64 + 0.5) * size;
                        let d = n[0] * tri[0][0] + n[1] * tri[0][1] + n[2] * tri[0][2];
                        let mid = (d - n[i] * ci - n[j] * cj) / n[k];
                        let lo = floor((mid - reach - self.lo[k]) * self.scale);
                        let hi = floor((mid + reach - self.lo[k]) * self.scale);
                        if !(lo <= last as f64 && hi >= first as f64) {
                            continue;
                        }
                        first = first.max(lo as usize);
                        last = last.min(hi as usize);
                    }
                    for c in first..=last {
                        let mut f = [0usize; 3];
                        (f[i], f[j], f[k]) = (a, b, c);
                        let cell = ((f[2] / SUB) * coarse + f[1] / SUB) * coarse + f[0] / SUB;
                        let Some(&block) = slot.get(cell).filter(|&&b| b != u32::MAX) else { continue };
                        let (word, bit) =
                            (&touched[block as usize][f[2] % SUB], 1u64 << ((f[1] % SUB) * SUB + f[0] % SUB));
                        if word.load(Relaxed) & bit != 0 {
                            continue;
                        }
                        let centre = f.map(|c| c as f64 + 0.5);
                        let centre = [0, 1, 2].map(|k| self.lo[k] + centre[k] * size);
                        if probe.touches(centre, h) {
                            word.fetch_or(bit, Relaxed);
                        }
                    }
                }
            }
        });
        if gave_up.into_inner() {
            return Vec::new();
        }
        let touched: Vec<Bits> = touched.into_iter().map(|t| t.map(AtomicU64::into_inner)).collect();
        // Coarse cells no triangle touches after all are on one side throughout, and
        // so are such cells joined through faces, with each other and with the coarse
        // cells of one side: labelled by a flood from those, then, where a group meets
        // none, by one point of it.
        let mut known = self.entries.clone();
        let clear = |c: usize| slot[c] != u32::MAX && touched[slot[c] as usize] == NONE;
        let mut queue: Vec<usize> = Vec::new();
        let flood = |known: &mut Vec<u8>, queue: &mut Vec<usize>| {
            while let Some(c) = queue.pop() {
                for n in neighbours(c, coarse) {
                    if known[n] == MIXED && clear(n) {
                        known[n] = known[c];
                        queue.push(n);
                    }
                }
            }
        };
        for &c in &mixed {
            let c = c as usize;
            if clear(c) && known[c] == MIXED {
                if let Some(l) = neighbours(c, coarse).map(|n| known[n]).find(|&l| l <= INSIDE) {
                    known[c] = l;
                    queue.push(c);
                    flood(&mut known, &mut queue);
                }
            }
        }
        let asked = AtomicU64::new(0);
        for &c in &mixed {
            let c = c as usize;
            if clear(c) && known[c] == MIXED {
                let at = [c % coarse, (c / coarse) % coarse, c / (coarse * coarse)];
                let centre = [0, 1, 2].map(|k| self.lo[k] + ((at[k] * SUB) as f64 + 0.5 * SUB as f64) * size);
                let point = within(centre, half * SUB as f64).filter(|_| asked.fetch_add(1, Relaxed) < MAX_ASKED);
                if let Some(point) = point {
                    known[c] = side(point) as u8;
                    queue.push(c);
                    flood(&mut known, &mut queue);
                }
            }
        }
        mixed
            .par_iter()
            .zip(&touched)
            .filter_map(|(&cell, &touched)| {
                let cell = cell as usize;
                if touched == NONE {
                    return (known[cell] <= INSIDE).then_some((cell as u32, Fine::Label(known[cell])));
                }
                self.block(cell, touched, &known, &asked, &side).map(|b| (cell as u32, b))
            })
            .collect()
    }

    /// The fine labels of coarse cell `cell`, whose fine cells with bits in `touched`
    /// a triangle may touch (one label where none is); `None` where every one is.
    fn block(
        &self,
        cell: usize,
        touched: Bits,
        known: &[u8],
        asked: &AtomicU64,
        side: impl Fn([f32; 3]) -> bool,
    ) -> Option<Fine> {
        if touched == ALL {
            return None;
        }
        let coarse = 1usize << self.level;
        let at = [cell % coarse, (cell / coarse) % coarse, cell / (coarse * coarse)];
        let size = 1.0 / self.scale;
        let half = 0.5 * size;
        // The side of the coarse cell across face `2 k + high` of this one, if known.
        let across = |k: usize, high: bool| -> Option<u128> {
            let mut n = at;
            if high {
                n[k] += 1;
            } else {
                n[k] = n[k].checked_sub(1)?;
            }
            let l = *known.get((n[2] * coarse + n[1]) * coarse + n[0]).filter(|_| n[k] < coarse)?;
            (l <= INSIDE).then_some(l as u128)
        };
        let mut block = ALL_MIXED;
        let free = touched.map(|w| !w);
        let mut left = free;
        while let Some(z) = left.iter().position(|&w| w != 0) {
            // A group of untouched fine cells joined through faces: grown from its
            // first cell one step at a time.
            let start = z * 64 + left[z].trailing_zeros() as usize;
            let mut group = NONE;
            group[z] = 1 << (start % 64);
            loop {
                let grown = and(or(group, step(group)), free);
                if grown == group {
                    break;
                }
                group = grown;
            }
            left = and(left, group.map(|w| !w));
            // Its side: a coarse cell of one side it meets through a face, else one of
            // its points' (the centre of its first cell, which lies in that cell unless
            // the cell is a few f32 ulps wide: then the group stays mixed).
            let found = (0..6).find_map(|face| {
                if and(group, FACES[face]) == NONE {
                    return None;
                }
                across(face / 2, face % 2 == 1)
            });
            let l = found.unwrap_or_else(|| {
                let f = [start % SUB, (start / SUB) % SUB, start / (SUB * SUB)];
                let centre = [0, 1, 2].map(|k| self.lo[k] + ((at[k] * SUB + f[k]) as f64 + 0.5) * size);
                match within(centre, half) {
                    Some(point) if asked.fetch_add(1, Relaxed) < MAX_ASKED => side(point) as u128,
                    _ => FINE_MIXED,
                }
            });
            if group == ALL {
                return (l != FINE_MIXED).then_some(Fine::Label(l as u8));
            }
            for (word, bits) in block.iter_mut().zip(group) {
                let cells = spread(bits);
                *word = (*word & !(cells * 3)) | (cells * l);
            }
        }
        Some(Fine::Block(block))
    }

    /// Gives coarse cells the labels and blocks [`Cells::blocks`] made for them, and
    /// packs the grid.
    pub(super) fn attach(&mut self, mut fine: Vec<(u32, Fine)>) {
        fine.sort_unstable_by_key(|f| f.0);
        for (cell, fine) in fine {
            let Some(entry) = self.entries.get_mut(cell as usize) else { continue };
            match fine {
                Fine::Label(label) => *entry = label,
                Fine::Block(block) => {
                    *entry = BLOCK;
                    self.blocks.push(block);
                }
            }
        }
        let code = |e: u8| match e {
            OUTSIDE | INSIDE => e as u64,
            BLOCK => CODE_BLOCK,
            _ => CODE_MIXED,
        };
        self.codes = self.entries.chunks(32).map(|c| c.iter().rev().fold(0u64, |w, &e| w << 2 | code(e))).collect();
        let mut before = 0u32;
        self.rank = self
            .codes
            .iter()
            .map(|&w| {
                let r = before;
                before += (w & (w >> 1) & LOW_BITS).count_ones();
                r
            })
            .collect();
        self.entries = Vec::new();
    }

    /// Bytes the grid holds.
    pub(super) fn bytes(&self) -> usize {
        self.codes.len() * 8 + self.rank.len() * 4 + self.blocks.len() * std::mem::size_of::<Block>()
    }

    /// Coarse cells with blocks of fine labels.
    pub(super) fn block_count(&self) -> usize {
        self.blocks.len()
    }

    /// The label of the fine cell holding `p` (its coarse cell's, where that lies on
    /// one side): [`MIXED`] where the cell is, and where `p` lies within rounding of a
    /// fine cell's face (so the rounding cannot move it into the neighbour).
    #[inline(always)]
    pub(super) fn label(&self, p: [f32; 3]) -> u8 {
        if self.codes.is_empty() {
            return MIXED;
        }
        let side = (1usize << self.level) * SUB;
        let mut fine = [0usize; 3];
        for k in 0..3 {
            let x = (p[k] as f64 - self.lo[k]) * self.scale;
            if !(x >= 0.0 && x < side as f64) {
                return MIXED; // (or NaN)
            }
            // Truncation is the floor here (and needs no call to libm's floor).
            fine[k] = x as usize;
            let within = x - fine[k] as f64;
            if !(within > 1e-9 && within < 1.0 - 1e-9) {
                return MIXED;
            }
        }
        let coarse = 1usize << self.level;
        let [x, y, z] = fine.map(|f| f >> SUB_BITS);
        let cell = (z * coarse + y) * coarse + x;
        let (Some(&word), Some(&rank)) = (self.codes.get(cell >> 5), self.rank.get(cell >> 5)) else { return MIXED };
        let at = 2 * (cell & 31);
        let b = match (word >> at) & 3 {
            0 => return OUTSIDE,
            1 => return INSIDE,
            CODE_MIXED => return MIXED,
            _ => {
                let below = word & ((1u64 << at) - 1);
                rank as usize + (below & (below >> 1) & LOW_BITS).count_ones() as usize
            }
        };
        let Some(block) = self.blocks.get(b) else { return MIXED };
        let [x, y, z] = fine.map(|f| f & (SUB - 1));
        match (block[z] >> (2 * (y * SUB + x))) & 3 {
            0 => OUTSIDE,
            1 => INSIDE,
            _ => MIXED,
        }
    }
}

/// The cells of a grid (`scale` cells a unit from `lo`, `side` a side) that box `bx`
/// covers or lies in. Boxes and cells are cells of the same power-of-two cube, but a
/// box's corners are rounded to `f32`: a box of a cell or more spans the grid lines
/// nearest its faces, a smaller one the cell of its centre.
fn span(bx: &[f32], lo: [f64; 3], scale: f64, side: usize) -> ([usize; 3], [usize; 3]) {
    let last = (side - 1) as f64;
    let mut from = [0usize; 3];
    let mut to = [0usize; 3];
    for k in 0..3 {
        let a = (bx[k] as f64 - lo[k]) * scale;
        let b = (bx[k + 3] as f64 - lo[k]) * scale;
        let (f, t) = if b - a >= 0.75 { (a.round(), b.round()) } else { (((a + b) * 0.5).floor(), f64::NAN) };
        from[k] = f.clamp(0.0, last) as usize; // NaN clamps to NaN, cast to 0
        to[k] = if t.is_nan() { from[k] + 1 } else { (t.clamp(0.0, side as f64) as usize).max(from[k] + 1) }.min(side);
    }
    (from, to)
}

/// The fine cells of a block on each of its faces: low x, high x, low y, high y, low
/// z, high z.
const FACES: [Bits; 6] = {
    const ROW: u64 = 0xff;
    const COLUMN: u64 = 0x0101_0101_0101_0101;
    let mut top = NONE;
    top[SUB - 1] = u64::MAX;
    let mut bottom = NONE;
    bottom[0] = u64::MAX;
    [[COLUMN; SUB], [COLUMN << 7; SUB], [ROW; SUB], [ROW << 56; SUB], bottom, top]
};

fn and(a: Bits, b: Bits) -> Bits {
    std::array::from_fn(|z| a[z] & b[z])
}

fn or(a: Bits, b: Bits) -> Bits {
    std::array::from_fn(|z| a[z] | b[z])
}

/// The coarse cells next to coarse cell `c` (of a grid `side` a side) through faces.
fn neighbours(c: usize, side: usize) -> impl Iterator<Item = usize> {
    let at = [c % side, (c / side) % side, c / (side * side)];
    let strides = [1, side, side * side];
    (0..6).filter_map(move |face| {
        let k = face / 2;
        if face % 2 == 0 {
            (at[k] > 0).then(|| c - strides[k])
        } else {
            (at[k] + 1 < side).then(|| c + strides[k])
        }
    })
}

/// `centre` rounded to `f32`, where that still lies within `half` of it along each
/// axis (inside its cell): not where the cell is a few `f32` ulps wide.
fn within(centre: [f64; 3], half: f64) -> Option<[f32; 3]> {
    let point = centre.map(|c| c as f32);
    (0..3).all(|k| (point[k] as f64 - centre[k]).abs() < half).then_some(point)
}

/// `x`'s bits at even places: bit `i` at bit `2 i` (each fine cell's low label bit).
fn spread(x: u64) -> u128 {
    let mut x = x as u128;
    x = (x | x << 32) & 0x0000_0000_FFFF_FFFF_0000_0000_FFFF_FFFF;
    x = (x | x << 16) & 0x0000_FFFF_0000_FFFF_0000_FFFF_0000_FFFF;
    x = (x | x << 8) & 0x00FF_00FF_00FF_00FF_00FF_00FF_00FF_00FF;
    x = (x | x << 4) & 0x0F0F_0F0F_0F0F_0F0F_0F0F_0F0F_0F0F_0F0F;
    x = (x | x << 2) & 0x3333_3333_3333_3333_3333_3333_3333_3333;
    (x | x << 1) & 0x5555_5555_5555_5555_5555_5555_5555_5555
}

/// `x` rounded down to an integer (NaN stays NaN); without a call to libm's `floor`
/// where the target has no rounding instruction. Exact: `x` past 2^62 is an integer.
#[inline]
fn floor(x: f64) -> f64 {
    if x.is_nan() || x.abs() >= (1u64 << 62) as f64 {
        return x;
    }
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// The fine cells of a block next to those of `bits` through a face.
fn step(bits: Bits) -> Bits {
    std::array::from_fn(|z| {
        let w = bits[z];
        let mut out = (w & !FACES[1][z]) << 1 | (w & !FACES[0][z]) >> 1 | w << SUB | w >> SUB;
        if z > 0 {
            out |= bits[z - 1];
        }
        if z + 1 < SUB {
            out |= bits[z + 1];
        }
        out
    })
}

/// A triangle made ready for [`Probe::touches`]: its normal.
struct Probe {
    tri: [[f64; 3]; 3],
    /// The normal, where it is well measured (not a sliver's).
    n: Option<[f64; 3]>,
}

impl Probe {
    fn new(tri: [[f64; 3]; 3]) -> Probe {
        let e = [0, 1].map(|i| [0, 1, 2].map(|k| tri[i + 1][k] - tri[0][k]));
        let n = [
            e[0][1] * e[1][2] - e[0][2] * e[1][1],
            e[0][2] * e[1][0] - e[0][0] * e[1][2],
            e[0][0] * e[1][1] - e[0][1] * e[1][0],
        ];
        let well = l1(n) >= l1(e[0]) * l1(e[1]) * (1.0 / 1024.0);
        Probe { tri, n: well.then_some(n) }
    }

    /// Whether the triangle may touch the closed cube of half edge `h` around
    /// `centre`: `false` where its plane or its box lies apart from the cube (the
    /// separating-axis test without the nine axes across edges, which the surface's
    /// neighbouring triangles mostly make moot). `h` must already be grown by far
    /// more than the rounding of the products ([`slack`]), so that `false` is certain.
    #[inline]
    fn touches(&self, centre: [f64; 3], h: f64) -> bool {
        let v = self.tri.map(|x| [x[0] - centre[0], x[1] - centre[1], x[2] - centre[2]]);
        if let Some(n) = self.n {
            if (n[0] * v[0][0] + n[1] * v[0][1] + n[2] * v[0][2]).abs() > h * l1(n) {
                return false;
            }
        }
        (0..3).all(|k| v[0][k].min(v[1][k]).min(v[2][k]) <= h && v[0][k].max(v[1][k]).max(v[2][k]) >= -h)
    }
}

fn l1(x: [f64; 3]) -> f64 {
    x[0].abs() + x[1].abs() + x[2].abs()
}

/// What a cube's half edge grows by for [`Probe::touches`] to be certain, for cubes
/// and triangles whose coordinates are at most `big`: the products' rounding is some
/// `2^-50 big` a unit of the axis, `2^-30` is ample.
fn slack(big: f64) -> f64 {
    big * (1.0 / (1u64 << 30) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_puts_each_bit_at_twice_its_place() {
        for x in [0u64, 1, 0x8000_0000_0000_0000, 0xdead_beef_0123_4567, u64::MAX] {
            let want = (0..64).filter(|i| x >> i & 1 == 1).fold(0u128, |w, i| w | 1 << (2 * i));
            assert_eq!(spread(x), want, "{x:x}");
        }
    }

    #[test]
    fn floor_is_the_floor() {
        for x in [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.999, -2.999, 1e17, -1e17, 4.6e18, f64::INFINITY, -f64::INFINITY] {
            assert_eq!(floor(x), x.floor(), "{x}");
        }
        assert!(floor(f64::NAN).is_nan());
    }

    /// Steps reach the six face neighbours of a cell and nothing across a block's
    /// faces.
    #[test]
    fn steps_join_faces_only() {
        let mut one = NONE;
        one[3] = 1 << (2 * SUB + 7); // x 7, y 2, z 3
        let next = step(one);
        let mut want = NONE;
        want[3] = 1 << (2 * SUB + 6) | 1 << (SUB + 7) | 1 << (3 * SUB + 7);
        want[2] = 1 << (2 * SUB + 7);
        want[4] = 1 << (2 * SUB + 7);
        assert_eq!(next, want);
    }
}
