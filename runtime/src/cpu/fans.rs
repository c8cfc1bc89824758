//! Fans: the leaves whose triangles share one vertex, where a ray's work is bounded by
//! a small hierarchy rather than by the leaf's triangle count.
//!
//! # Why a leaf stays overfull
//! Triangles that share a vertex share every cell around it, at every depth: a fan of
//! `n` triangles (a tessellated cone's tip, a UV sphere's pole, a disk fanned from its
//! centre) leaves a leaf at the depth limit holding nearly all `n`, and every ray
//! through that leaf tests them all. No subdivision can split them (they meet at the
//! point), and a hierarchy of their boxes cannot either: every box holds the vertex.
//!
//! # What splits them: the wedge each triangle makes at the vertex
//! Seen from the shared vertex `v`, triangle `(v, a, b)` is a wedge between the spoke
//! directions `â = (a - v) / |a - v|` and `b̂`, an arc of the unit sphere. The
//! watertight test shears the ray onto `+z` and asks whether the origin lies inside
//! the sheared triangle; the two edges at `v` share the sheared vertex `v'`, and the
//! origin is inside only if it lies between the two spokes as seen from `v'`: the
//! signs of `g(â) = n · â` and `g(b̂)` differ, with `n` the normal of the plane
//! through the sheared `v'` and the ray. So a ray can hit only the triangles whose arc
//! the plane `g = 0` crosses: a bounding-volume hierarchy over the arcs' boxes, asked
//! with that plane, finds them in about `log n` node visits and a few arcs where the
//! plane crosses the fan (twice for a flat disk, whatever the ray).
//!
//! # Exactly the answers of testing them all
//! The filter only chooses which triangles the usual test runs on, in the leaf's order,
//! so the answer is that of testing the whole leaf as long as no triangle the test
//! would accept is left out. It works with the test's own numbers: `v'` is computed
//! by the same `f32` operations as in `Shear`'s test (the same bits), so the only gap
//! between the test's decision and the arc's is the rounding of the spokes' sheared
//! ends (`2^-22` of their distance to the origin, a few times) and of the edge
//! functions: an angle of about `2^-19 (|v - o|_1 + 3 r) / l` for spokes of length `l`
//! and the longest `r`, which each node's test allows four times over
//! ([`SLACK`]). A ray through `v'` itself (`n = 0`) meets every triangle of the fan
//! there: the nearest-hit test (edges closed) accepts them all, and the nearest of
//! their rounded distances, then the lowest input id, is the answer, so it tests the
//! whole leaf (a 200,000-triangle disk: milliseconds a ray; rays that pass exactly
//! through `v'` in `f32` are mostly axis-aligned ones through it). The crossing
//! queries' test (edges owned) accepts only the triangles that own both edges at `v'`:
//! those whose arc crosses the plane where the sheared `y` is 0, which the hierarchy
//! finds as it finds any other plane's. A ray whose numbers overflow keeps every
//! triangle; more than [`MAX_CANDIDATES`] candidates test the whole leaf. Tests that do not run that arithmetic (Möller-Trumbore, `f64`, the exact
//! exit rule's) test every triangle.
//!
//! # When and what it costs
//! Only leaves of [`MIN_REFERENCES`] references or more are looked at (below that,
//! eight triangles at a time cost less than the hierarchy's nodes: with 64, random
//! rays through a 20,000-triangle disk ran at 0.85 against 1.28 Mrays/s), on a ray's
//! first visit: the first tracer lists them (one pass over the leaf records), and each
//! leaf's hierarchy is made when a ray first crosses it, 12 to 20 bytes a reference,
//! within a budget (the larger of 16 MiB and the scene's reference array) past which
//! leaves are tested whole. Measured on disks of 2,000 to 200,000 triangles
//! (`cargo bench -p octrace-runtime --bench fans`, BENCHMARKS.md): rays aimed near the
//! centre 8 to 70 times faster, random rays unchanged within noise.
//!
//! # On the GPU
//! The tracer uploads every crowded leaf's hierarchy ([`FanIndex::gpu_words`]) and
//! the kernels run the same filter (`fan_pick` in trace.wgsl), up to 64 picks.

use octrace_format::layout::TRIANGLE_FLOATS;
use octrace_format::SceneView;

use super::watertight::Shear;

/// Leaves with at least this many references are looked at for a fan.
pub const MIN_REFERENCES: u32 = 256;
/// Fewest triangles around one vertex that make a fan.
pub const MIN_TRIANGLES: usize = 24;
/// The most triangles a ray tests in a fan's leaf through the hierarchy; past it
/// the whole leaf is tested (a ray through the vertex itself, or along the fan's
/// plane, where the test's rounding decides between most of its triangles).
pub(crate) const MAX_CANDIDATES: usize = 2048;

/// Room for a ray's candidates ([`FanIndex::candidates`]), left uninitialised: the
/// walk makes one in each crowded leaf it visits.
pub(crate) type Candidates = [std::mem::MaybeUninit<u32>; MAX_CANDIDATES];

/// An empty [`Candidates`] (nothing written: free).
#[inline(always)]
pub(crate) fn candidates_room() -> Candidates {
    [const { std::mem::MaybeUninit::uninit() }; MAX_CANDIDATES]
}
/// Arcs in a hierarchy leaf.
const NODE_ARCS: usize = 8;
/// `Node::count` of the empty second half of a root's pair.
const EMPTY: u32 = u32::MAX;
/// The angle a node's test allows, per unit of `(|v - o|_1 + 3 r) / l` (module docs):
/// `2^-17`, four times the error bound.
const SLACK: f64 = 1.0 / (1u64 << 17) as f64;
/// Wedges wider than this cosine (at the vertex) stay with the leaf's other triangles:
/// their arcs' boxes grow without bound as the angle nears a half turn.
const WIDEST_COS: f64 = -0.9;

/// The leaves of a scene crowded enough for a fan ([`MIN_REFERENCES`] or more
/// references), each with its hierarchy made on the first ray through it
/// ([`FanIndex::new`]; [`crate::Scene::tracer`] makes one with the first tracer and
/// the walks use it). Hierarchies take 12 to 20 bytes a reference; past the budget
/// (the larger of 16 MiB and the scene's reference array) leaves are tested whole.
#[derive(Debug, Default)]
pub struct FanIndex {
    /// `(box index, slot)` of the crowded leaves, sorted by box index.
    by_box: Vec<(u32, u32)>,
    /// Each slot's references: `(offset, count)` (for the GPU's upload).
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    records: Vec<(u32, u32)>,
    /// Each crowded leaf's fan, once asked for: `None` when it has none (or the
    /// budget was spent).
    slots: Vec<std::sync::OnceLock<Option<Box<Fan>>>>,
    /// Bytes the hierarchies made so far take, and the most they may.
    spent: std::sync::atomic::AtomicUsize,
    budget: usize,
}

/// How many crowded leaves are fans and how many references they hold
/// ([`FanIndex::survey`]: what `octrace inspect` prints).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FanSummary {
    /// Leaves whose triangles share a vertex.
    pub leaves: u64,
    /// Their references to triangles around it.
    pub fan_references: u64,
    /// Their other references (tested by every ray through the leaf).
    pub other_references: u64,
    /// Most triangles around one vertex in one leaf.
    pub largest: u64,
}

impl FanSummary {
    /// The counts by name, as `octrace inspect --json` (and Python's `Scene.inspect`)
    /// list them under `fans`.
    pub fn named(&self) -> [(&'static str, u64); 4] {
        [
            ("leaves", self.leaves),
            ("fan_references", self.fan_references),
            ("other_references", self.other_references),
            ("largest", self.largest),
        ]
    }
}

/// One leaf's fan: the shared vertex, the scale of its slack, its hierarchy.
#[derive(Debug)]
struct Fan {
    /// The leaf's references, to recognise its record.
    offset: u32,
    count: u32,
    vertex: [f32; 3],
    /// Three times the longest spoke.
    reach: f32,
    /// [`SLACK`] over the shortest spoke.
    slack: f32,
    /// The root is `pairs[0].0[0]`.
    pairs: Box<[Pair]>,
    /// The fan triangles' positions in the leaf's references, in hierarchy order.
    arcs: Box<[u32]>,
    /// The other triangles' positions, ascending.
    rest: Box<[u32]>,
}

/// A hierarchy node: the box of its arcs, and its arcs (`count > 0`: `first ..
/// first + count` in `arcs`) or its children (`count == 0`: the pair `first`).
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    first: u32,
    count: u32,
}

impl Node {
    /// The second half of the root's pair.
    const EMPTY: Node = Node { lo: [0.0; 3], hi: [0.0; 3], first: 0, count: EMPTY };
}

/// Two sibling nodes, one cache line.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Pair([Node; 2]);

/// A fan triangle while the hierarchy is made.
#[derive(Clone, Copy)]
struct Arc {
    position: u32,
    lo: [f32; 3],
    hi: [f32; 3],
    centre: [f64; 3],
    shortest: f64,
    longest: f64,
}

impl FanIndex {
    /// The crowded leaves of `view` (reads every leaf record once; no hierarchy is
    /// made yet).
    pub fn new(view: &SceneView<'_>) -> FanIndex {
        let (mut by_box, mut records) = (Vec::<(u32, u32)>::new(), Vec::<(u32, u32)>::new());
        for rec in view.leaves() {
            if rec.tri_count >= MIN_REFERENCES {
                by_box.push((rec.box_index, by_box.len() as u32));
                records.push((rec.tri_offset, rec.tri_count));
            }
        }
        by_box.sort_unstable();
        let slots = (0..by_box.len()).map(|_| std::sync::OnceLock::new()).collect();
        let budget = (16usize << 20).max(4 * view.tri_refs.len());
        FanIndex { by_box, records, slots, spent: Default::default(), budget }
    }

    /// Whether no leaf is crowded.
    pub fn is_empty(&self) -> bool {
        self.by_box.is_empty()
    }

    /// The crowded leaves of `view` that are fans, counted (every leaf's shared
    /// vertex found; no hierarchy made).
    ///
    /// # Example
    /// A disk of 300 triangles fanned from its centre: the leaf at the centre lists
    /// them all, around one vertex.
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{cpu::FanIndex, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::fan(300, 1.0), &BuildParams::auto())?)?;
    /// let fans = FanIndex::survey(&scene.view());
    /// assert_eq!((fans.largest, fans.other_references), (300, 0));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn survey(view: &SceneView<'_>) -> FanSummary {
        let mut s = FanSummary::default();
        for rec in view.leaves() {
            if rec.tri_count < MIN_REFERENCES {
                continue;
            }
            let Some((refs, vertex)) = leaf_vertex(view, rec.tri_offset, rec.tri_count) else { continue };
            let around = refs.iter().filter(|&&r| triangle(view, r).and_then(|t| wedge(t, vertex)).is_some()).count();
            if around >= MIN_TRIANGLES {
                s.leaves += 1;
                s.fan_references += around as u64;
                s.other_references += (refs.len() - around) as u64;
                s.largest = s.largest.max(around as u64);
            }
        }
        s
    }

    /// The fan of the leaf with box index `box_index` and references `offset ..
    /// offset + count`, made on the first call.
    #[inline]
    fn fan_of(&self, view: &SceneView<'_>, box_index: u32, offset: u32, count: u32) -> Option<&Fan> {
        let i = self.by_box.binary_search_by_key(&box_index, |&(b, _)| b).ok()?;
        let slot = self.slots.get(self.by_box[i].1 as usize)?;
        slot.get_or_init(|| self.make(view, offset, count)).as_deref()
    }

    /// Makes the fan of the leaf whose references are `offset .. offset + count`,
    /// if its triangles share a vertex and the budget allows.
    #[cold]
    fn make(&self, view: &SceneView<'_>, offset: u32, count: u32) -> Option<Box<Fan>> {
        use std::sync::atomic::Ordering;
        let (refs, vertex) = leaf_vertex(view, offset, count)?;
        let (mut arcs, mut rest) = (Vec::new(), Vec::new());
        for (position, &r) in refs.iter().enumerate() {
            match triangle(view, r).and_then(|t| wedge(t, vertex)) {
                Some(arc) => arcs.push(Arc { position: position as u32, ..arc }),
                None => rest.push(position as u32),
            }
        }
        if arcs.len() < MIN_TRIANGLES {
            return None;
        }
        // About one pair for every NODE_ARCS / 2 arcs, and four bytes a reference.
        let bytes = 64 * (2 * arcs.len() / NODE_ARCS + 1) + 4 * refs.len();
        if self.spent.fetch_add(bytes, Ordering::Relaxed) + bytes > self.budget {
            self.spent.fetch_sub(bytes, Ordering::Relaxed);
            return None;
        }
        let longest = arcs.iter().map(|a| a.longest).fold(0.0f64, f64::max);
        let shortest = arcs.iter().map(|a| a.shortest).fold(f64::INFINITY, f64::min);
        let mut tree = Tree { pairs: vec![Pair([Node::EMPTY; 2])], arcs: Vec::with_capacity(arcs.len()) };
        tree.pairs[0].0[0] = tree.subtree(&mut arcs);
        Some(Box::new(Fan {
            offset,
            count,
            vertex,
            reach: (3.0 * longest * (1.0 + 1e-6)) as f32,
            slack: ((SLACK / shortest) * (1.0 + 1e-6)) as f32,
            pairs: tree.pairs.into_boxed_slice(),
            arcs: tree.arcs.into_boxed_slice(),
            rest: rest.into_boxed_slice(),
        }))
    }

    /// The references of the leaf (`refs` from `offset`, box index `box_index`, in
    /// `view`) that a ray with `shear` may hit, in the leaf's order, into `out`;
    /// `None` when it has no fan or the ray must test them all (module docs). `owned`:
    /// the test is [`Shear::intersect_owned`] (the crossing queries'), whose edge rule
    /// picks among a fan's triangles even for a ray through the shared vertex.
    #[inline(never)]
    pub(crate) fn candidates<'b>(
        &self,
        view: &SceneView<'_>,
        (box_index, offset, refs): (u32, u32, &[u32]),
        shear: &Shear,
        owned: bool,
        out: &'b mut Candidates,
    ) -> Option<&'b [u32]> {
        let fan = self.fan_of(view, box_index, offset, refs.len() as u32)?;
        if fan.offset != offset || fan.count as usize != refs.len() {
            return None; // another record with this box index (a hostile file, trusted)
        }
        let (o, v) = (shear.origin(), fan.vertex);
        // The sheared vertex, as `Shear`'s test computes it (the same operations).
        let r = [v[0] - o[0], v[1] - o[1], v[2] - o[2]];
        let [kx, ky, kz] = shear.axes();
        let [sx, sy, _] = shear.scales();
        let (vx, vy) = (r[kx] - sx * r[kz], r[ky] - sy * r[kz]);
        let mut n = [0.0f32; 3];
        // `n`, and its size in the units of the angle `fan.slack` allows.
        let scale = if vx == 0.0 && vy == 0.0 && owned {
            // A ray through the shared vertex itself: both of a triangle's edges at
            // `v'` have a zero function there, and the owned test accepts the
            // triangle only if it owns both (`owns64`): its spokes' sheared ends lie on
            // either side of the sheared x axis (one with y > 0, or y = 0 and x > 0; the
            // other the reverse). So its arc crosses the plane through `v` where the
            // sheared y is 0: `g(p) = p_ky - sy p_kz`, whose rounding in the test is
            // that of a spoke's end alone, a fraction of what `slack` allows.
            n[ky] = 1.0;
            n[kz] = -sy;
            1.0 + sy.abs()
        } else {
            n[kx] = -vy;
            n[ky] = vx;
            n[kz] = sx * vy - sy * vx;
            vx.abs() + vy.abs()
        };
        let slack = scale * (r[0].abs() + r[1].abs() + r[2].abs() + fan.reach) * fan.slack * 1.001;
        if slack == 0.0 || !slack.is_finite() || !n.iter().all(|c| c.is_finite()) {
            return None;
        }
        let limit = MAX_CANDIDATES.min(refs.len() / 2);
        if fan.rest.len() >= limit {
            return None;
        }
        // Positions first (the rest, then the arcs the plane may cross), sorted below.
        let mut found = 0;
        for &p in fan.rest.iter() {
            out[found].write(p);
            found += 1;
        }
        let mut stack = [0u32; 64];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let pair = fan.pairs.get(stack[top] as usize)?;
            for node in &pair.0 {
                if node.count == EMPTY {
                    continue;
                }
                let (mut lo, mut hi) = (0.0f32, 0.0f32);
                for k in 0..3 {
                    let (a, b) = (n[k] * node.lo[k], n[k] * node.hi[k]);
                    lo += a.min(b);
                    hi += a.max(b);
                }
                if lo > slack || hi < -slack {
                    continue;
                }
                if node.count > 0 {
                    let (first, count) = (node.first as usize, node.count as usize);
                    if found + count > limit {
                        return None;
                    }
                    for &p in fan.arcs.get(first..first + count)? {
                        out[found].write(p);
                        found += 1;
                    }
                } else {
                    if top == stack.len() {
                        return None;
                    }
                    stack[top] = node.first;
                    top += 1;
                }
            }
        }
        // SAFETY: the first `found` entries were written above (`u32` has no invalid
        // values, and `MaybeUninit<u32>` the same layout).
        let picked = unsafe { std::slice::from_raw_parts_mut(out.as_mut_ptr().cast::<u32>(), found) };
        picked.sort_unstable();
        for p in picked.iter_mut() {
            *p = *refs.get(*p as usize)?;
        }
        Some(picked)
    }
}

impl super::Tracer<'_> {
    /// In a crowded leaf (`refs` from `offset`, box index `box_index`) with a fan, the
    /// references a ray with the shear `shear()` gives may hit, into `room`; `None`
    /// to test them all (no fans, a leaf under [`MIN_REFERENCES`], no shear: a test
    /// other than the watertight one in `f32`). What every walk that tests a leaf asks
    /// first; `shear` is asked last, in crowded leaves only.
    #[inline(always)]
    pub(crate) fn fan_refs<'r, 's>(
        &self,
        leaf: (u32, u32, &[u32]),
        shear: impl FnOnce() -> Option<&'s Shear>,
        owned: bool,
        room: &'r mut Candidates,
    ) -> Option<&'r [u32]> {
        let index = self.fans?;
        if (leaf.2.len() as u32) < MIN_REFERENCES {
            return None;
        }
        index.candidates(&self.view, leaf, shear()?, owned, room)
    }
}

/// Words of a fan record's header in [`FanIndex::gpu_words`].
#[cfg(feature = "gpu")]
const GPU_HEADER_WORDS: usize = 12;

#[cfg(feature = "gpu")]
impl FanIndex {
    /// Every crowded leaf's fan (within the budget) as the GPU kernels read them
    /// (`fan_pick` in trace.wgsl): empty when there is none; else one word a leaf
    /// (its record's offset in these words, or `u32::MAX`), then the records:
    /// `offset, count, vertex xyz, reach, slack, rest count, rest at, arcs at, pairs
    /// at, 0`, the pairs (two nodes of `lo xyz, hi xyz, first, count`), the arcs'
    /// positions, the rest's. Offsets are in words from the start.
    pub(crate) fn gpu_words(view: &SceneView<'_>) -> Vec<u32> {
        let index = FanIndex::new(view);
        let mut words = vec![u32::MAX; view.leaf_count()];
        let mut any = false;
        for &(box_index, slot) in &index.by_box {
            let (offset, count) = index.records[slot as usize];
            let Some(fan) = index.make(view, offset, count) else { continue };
            if box_index as usize >= view.leaf_count() {
                continue;
            }
            any = true;
            let at = words.len();
            // Overwrites a duplicate box index's (a hostile file, trusted): the kernel
            // then finds another record's references and tests the leaf whole.
            words[box_index as usize] = at as u32;
            let pairs_at = at + GPU_HEADER_WORDS;
            let arcs_at = pairs_at + 16 * fan.pairs.len();
            let rest_at = arcs_at + fan.arcs.len();
            let v = fan.vertex.map(f32::to_bits);
            words.extend([offset, count, v[0], v[1], v[2], fan.reach.to_bits(), fan.slack.to_bits()]);
            words.extend([fan.rest.len() as u32, rest_at as u32, arcs_at as u32, pairs_at as u32, 0]);
            for pair in fan.pairs.iter() {
                for node in &pair.0 {
                    words.extend(node.lo.map(f32::to_bits));
                    words.extend(node.hi.map(f32::to_bits));
                    words.extend([node.first, node.count]);
                }
            }
            words.extend(fan.arcs.iter());
            words.extend(fan.rest.iter());
        }
        if any {
            words
        } else {
            Vec::new()
        }
    }
}

/// A hierarchy while it is made: nodes in pairs (each pair before its descendants),
/// arcs' positions in hierarchy order.
struct Tree {
    pairs: Vec<Pair>,
    arcs: Vec<u32>,
}

impl Tree {
    /// The node over `arcs` (their positions appended), its descendants' pairs
    /// appended: split at the median of the longest axis of their centres.
    fn subtree(&mut self, arcs: &mut [Arc]) -> Node {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        let (mut clo, mut chi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for a in arcs.iter() {
            for k in 0..3 {
                lo[k] = lo[k].min(a.lo[k]);
                hi[k] = hi[k].max(a.hi[k]);
                clo[k] = clo[k].min(a.centre[k]);
                chi[k] = chi[k].max(a.centre[k]);
            }
        }
        if arcs.len() <= NODE_ARCS {
            let first = self.arcs.len() as u32;
            self.arcs.extend(arcs.iter().map(|a| a.position));
            return Node { lo, hi, first, count: arcs.len() as u32 };
        }
        let axis = (0..3).max_by(|&i, &j| (chi[i] - clo[i]).total_cmp(&(chi[j] - clo[j]))).unwrap_or(0);
        let mid = arcs.len() / 2;
        arcs.select_nth_unstable_by(mid, |a, b| a.centre[axis].total_cmp(&b.centre[axis]));
        let pair = self.pairs.len();
        self.pairs.push(Pair([Node::EMPTY; 2]));
        let (left, right) = arcs.split_at_mut(mid);
        let l = self.subtree(left);
        let r = self.subtree(right);
        self.pairs[pair] = Pair([l, r]);
        Node { lo, hi, first: pair as u32, count: 0 }
    }
}

/// Stored triangle `r` of `view` (nine floats), if there is one.
fn triangle<'v>(view: &SceneView<'v>, r: u32) -> Option<&'v [f32]> {
    view.triangles.get(r as usize * TRIANGLE_FLOATS..)?.get(..TRIANGLE_FLOATS)
}

/// A leaf's references (`offset .. offset + count`) and the vertex most of its
/// triangles share, when at least [`MIN_TRIANGLES`] do.
fn leaf_vertex<'v>(view: &SceneView<'v>, offset: u32, count: u32) -> Option<(&'v [u32], [f32; 3])> {
    let start = offset as usize;
    let refs = view.tri_refs.get(start..start.checked_add(count as usize)?)?;
    let vertex = shared_vertex(refs.iter().filter_map(|&r| triangle(view, r)))?;
    Some((refs, vertex))
}

/// The vertex the most triangles (nine floats each) list, by its bits, when at least
/// [`MIN_TRIANGLES`] do (the lowest bits among equals, so the choice is the same on
/// every run).
fn shared_vertex<'t>(triangles: impl Iterator<Item = &'t [f32]>) -> Option<[f32; 3]> {
    let mut seen: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    for t in triangles {
        let corners = [0, 1, 2].map(|i| [t[3 * i].to_bits(), t[3 * i + 1].to_bits(), t[3 * i + 2].to_bits()]);
        for (i, c) in corners.iter().enumerate() {
            if !corners[..i].contains(c) {
                *seen.entry(*c).or_insert(0) += 1;
            }
        }
    }
    let (bits, count) = seen.into_iter().max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))?;
    (count as usize >= MIN_TRIANGLES).then(|| bits.map(f32::from_bits))
}

/// Triangle `t`'s wedge at `vertex` (one of its corners, by bits): the box of its arc
/// of unit directions, rounded outwards. `None` when the vertex is not a corner, a
/// spoke has no length or the wedge is too wide ([`WIDEST_COS`]).
fn wedge(t: &[f32], vertex: [f32; 3]) -> Option<Arc> {
    let corner = |i: usize| [t[3 * i], t[3 * i + 1], t[3 * i + 2]];
    let at = (0..3).find(|&i| corner(i).map(f32::to_bits) == vertex.map(f32::to_bits))?;
    let spoke = |i: usize| {
        let c = corner(i);
        let w = [0, 1, 2].map(|k| c[k] as f64 - vertex[k] as f64);
        let len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        (w.map(|x| x / len), len)
    };
    let ((a, la), (b, lb)) = (spoke((at + 1) % 3), spoke((at + 2) % 3));
    if !(la > 0.0 && lb > 0.0 && la.is_finite() && lb.is_finite()) {
        return None;
    }
    let cos = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    if cos < WIDEST_COS {
        return None;
    }
    // The arc lies in the triangle of its ends and the meeting point of its tangents
    // there, (a + b) / (1 + cos).
    let m = [0, 1, 2].map(|k| (a[k] + b[k]) / (1.0 + cos));
    let (mut lo, mut hi) = ([0.0f32; 3], [0.0f32; 3]);
    for k in 0..3 {
        let (l, h) = (a[k].min(b[k]).min(m[k]), a[k].max(b[k]).max(m[k]));
        // Outwards by far more than the f64 arithmetic and the rounding to f32.
        lo[k] = (l - 1e-6) as f32;
        hi[k] = (h + 1e-6) as f32;
    }
    let centre = [0, 1, 2].map(|k| (a[k] + b[k]) / 2.0);
    Some(Arc { position: 0, lo, hi, centre, shortest: la.min(lb), longest: la.max(lb) })
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::FanIndex;
    use crate::{Ray, Scene, WalkStats};
    use octrace_bake::{bake, procedural, BuildParams, Mesh};

    /// Rays from a box three times the mesh's around `centre`: `n` random, `n` aimed at
    /// the centre, `n` aimed at points within `1e-6` to `1e-2` of it, and the six
    /// axis rays through it.
    fn rays(seed: u64, n: usize, centre: [f32; 3], size: f32) -> [Vec<Ray>; 3] {
        let mut rng = procedural::SplitMix(seed);
        let c = Vec3::from(centre);
        let origin =
            |rng: &mut procedural::SplitMix| c + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 3.0 * size;
        let random = (0..n)
            .map(|_| {
                let o = origin(&mut rng);
                let d = Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5;
                Ray::new(o, d)
            })
            .collect();
        let mut aimed: Vec<Ray> = (0..n)
            .map(|_| {
                let o = origin(&mut rng);
                Ray::new(o, (c - o).normalize())
            })
            .collect();
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            aimed.push(Ray::new(c - axis * size, axis));
            aimed.push(Ray::new(c + axis * size, -axis));
        }
        let near = (0..n)
            .map(|_| {
                let o = origin(&mut rng);
                let off = Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5;
                let at = c + off * size * 10f32.powf(-2.0 - 4.0 * rng.unit());
                Ray::new(o, at - o)
            })
            .collect();
        [random, aimed, near]
    }

    /// Every query answers the same bits with the fans' hierarchies as without; returns
    /// the triangle tests of each ray set, with and without.
    fn same_answers(name: &str, mesh: &Mesh, centre: [f32; 3], size: f32) -> Vec<(u64, u64)> {
        let scene = Scene::from_baked(bake(mesh, &BuildParams::auto()).unwrap()).unwrap();
        assert!(FanIndex::survey(&scene.view()).leaves > 0, "{name}: no fan found");
        let (with, without) = (scene.tracer(), scene.tracer().with_fans(None));
        let mut tests = Vec::new();
        for (set, rays) in rays(7, 1500, centre, size).iter().enumerate() {
            let (mut a, mut b) = (0u64, 0u64);
            for (i, ray) in rays.iter().enumerate() {
                let ((h1, s1), (h2, s2)): ((_, WalkStats), (_, WalkStats)) =
                    (with.intersect_with_stats(ray), without.intersect_with_stats(ray));
                assert_eq!(h1, h2, "{name}: set {set} ray {i} {ray:?}");
                assert_eq!(with.occluded(ray), without.occluded(ray), "{name}: set {set} ray {i} occluded");
                let (mut c1, mut c2) = (Vec::new(), Vec::new());
                with.crossings(ray, |c| {
                    c1.push(c);
                    std::ops::ControlFlow::Continue(())
                });
                without.crossings(ray, |c| {
                    c2.push(c);
                    std::ops::ControlFlow::Continue(())
                });
                assert_eq!(c1, c2, "{name}: set {set} ray {i} crossings");
                a += s1.triangle_tests as u64;
                b += s2.triangle_tests as u64;
            }
            // The batch forms (eight lanes where the processor has them).
            let (mut b1, mut b2) = (vec![None; rays.len()], vec![None; rays.len()]);
            with.intersect_batch(rays, &mut b1);
            without.intersect_batch(rays, &mut b2);
            assert_eq!(b1, b2, "{name}: set {set} batch");
            let (x1, x2) = (with.crossings_batch(rays, usize::MAX), without.crossings_batch(rays, usize::MAX));
            assert_eq!((x1.splits, x1.crossings), (x2.splits, x2.crossings), "{name}: set {set} batch crossings");
            tests.push((a, b));
        }
        tests
    }

    #[test]
    fn a_fans_hierarchy_answers_as_testing_every_triangle_and_tests_few() {
        let cases = [
            ("disk", procedural::cone(2000, [0.0; 3], 1.0, 0.0), [0.0f32; 3]),
            ("disk off the grid", procedural::cone(3000, [0.1234, -0.377, 0.05], 1.0, 0.0), [0.1234, -0.377, 0.05]),
            ("cone", procedural::cone(2000, [0.0; 3], 1.0, 0.7), [0.0, 0.7, 0.0]),
            ("flat cone", procedural::cone(1000, [0.3; 3], 2.0, 0.01), [0.3, 0.31, 0.3]),
        ];
        for (name, mesh, centre) in &cases {
            let tests = same_answers(name, mesh, *centre, 1.0);
            let n = mesh.triangles.len() as u64;
            for (set, (with, without)) in tests.iter().enumerate() {
                eprintln!("{name} set {set}: {with} tests with the hierarchy, {without} without");
            }
            // Rays aimed at the centre, or near it: each tested every triangle of the
            // leaves around it; now those of leaves under 256 references and a few in
            // the others (the disk's near rays 125 times fewer, the cone's 9).
            let (aimed, near) = (tests[1], tests[2]);
            assert!(aimed.1 >= 1500 * n / 2, "{name}: the centre's leaf was not crowded");
            assert!(near.0 * 5 < near.1 && aimed.0 * 5 / 4 < aimed.1, "{name}: {tests:?}");
        }
    }

    /// Rays exactly through a fan's shared vertex (its sheared position 0 in `f32`:
    /// directions whose dominant component is a power of two, from points at a power
    /// of two times them) list the crossings of testing the whole leaf, bit for bit,
    /// and the crossing test now tests a few of the fan's triangles, not all (issue 46:
    /// a 200,000-triangle disk took 12 s for 1,000 such rays' counts).
    #[test]
    fn crossings_through_the_shared_vertex_test_few_triangles() {
        use super::super::watertight::Shear;
        use octrace_format::layout::LEAF_HEADER_WORDS;
        for (name, height) in [("disk", 0.0f32), ("cone", 0.5)] {
            let mesh = procedural::cone(2000, [0.0; 3], 1.0, height);
            let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
            let index = FanIndex::new(&scene.view());
            let (with, without) = (scene.tracer(), scene.tracer().with_fans(None));
            let view = scene.view();
            // The crowded leaves: (box index, offset, references).
            let mut crowded = Vec::new();
            let mut a = 0usize;
            while crowded.len() + 1 < view.leaf_count() && a + LEAF_HEADER_WORDS <= view.octree.len() {
                let rec = &view.octree[a..a + LEAF_HEADER_WORDS];
                if rec[0] >= super::MIN_REFERENCES {
                    crowded.push((rec[2], rec[1], &view.tri_refs[rec[1] as usize..][..rec[0] as usize]));
                }
                a += LEAF_HEADER_WORDS + octrace_format::layout::total_links(rec[3]) as usize;
                if crowded.len() > 64 {
                    break;
                }
            }
            assert!(!crowded.is_empty(), "{name}");
            let (mut through, mut crossed, mut picked) = (0, 0, 0usize);
            for i in -6i32..=6 {
                for j in -6i32..=6 {
                    for (axis, sign) in [(0, 1.0f32), (1, -1.0), (2, 1.0), (2, -1.0)] {
                        let mut d = [i as f32, j as f32, i as f32];
                        d[(axis + 1) % 3] = j as f32;
                        d[axis] = 8.0 * sign;
                        // From the apex, back a quarter of the direction (exact).
                        let o = [-0.25 * d[0], height - 0.25 * d[1], -0.25 * d[2]];
                        let ray = Ray::new(o.into(), d.into());
                        let mut room = super::candidates_room();
                        let shear = Shear::new(o, d);
                        let (mut c1, mut c2) = (Vec::new(), Vec::new());
                        with.crossings(&ray, |c| {
                            c1.push(c);
                            std::ops::ControlFlow::Continue(())
                        });
                        without.crossings(&ray, |c| {
                            c2.push(c);
                            std::ops::ControlFlow::Continue(())
                        });
                        assert_eq!(c1, c2, "{name}: {ray:?}");
                        crossed += c1.len();
                        // A ray in the disk's plane meets every arc there (and crosses
                        // nothing): the whole leaf is tested, as the docs say.
                        if height == 0.0 && d[1] == 0.0 {
                            continue;
                        }
                        for &leaf in &crowded {
                            // Nearest-hit's test (edges closed) still tests them all.
                            assert!(index.candidates(&view, leaf, &shear, false, &mut room).is_none());
                            let Some(few) = index.candidates(&view, leaf, &shear, true, &mut room) else {
                                panic!("{name}: {ray:?} tests the whole leaf");
                            };
                            picked = picked.max(few.len());
                            through += 1;
                        }
                    }
                }
            }
            assert!(through >= 12 * 13 * 3, "{name}: {through}");
            // Rays in the disk's plane cross nothing, the others once at the apex; rays
            // that touch the cone's apex from outside cross it 0 or 2 times.
            assert!(crossed >= 13 * 13, "{name}: {crossed} crossings");
            assert!(picked <= 64, "{name}: up to {picked} candidates of {}", mesh.triangles.len());
        }
    }

    #[test]
    fn a_uv_spheres_poles_are_fans() {
        let mesh = procedural::sphere([0.0; 3], 1.0, 40, 900);
        let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
        let summary = FanIndex::survey(&scene.view());
        assert!(summary.leaves >= 2 && summary.largest >= 900, "{summary:?}");
        same_answers("sphere's north pole", &mesh, [0.0, 1.0, 0.0], 0.5);
    }
}
