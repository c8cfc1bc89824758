//! Rays the octree's own grid makes hard, for tests, `octrace soak` and the report.
//!
//! Random directions never have a zero component, and random origins never lie on a
//! cell plane, so rays that do are never drawn by chance, yet cameras with axis-aligned
//! views, reflections about axis-aligned normals (`-0.0` components) and scenes far
//! from the origin (where the `f32` grid is coarse) make them all the time. This
//! generator builds them on purpose, on the planes of the bake they are shot at
//! ([`GridPlanes::of`]), and cycles through every case so that none is left out by
//! chance: each kind ([`HardKind`]) on each axis, with each sign of every component
//! (`+0.0` and `-0.0` for zero ones), at every level of the tree.
//!
//! Each ray is also twisted ([`Twist`]), in turn: zero components become the
//! smallest subnormal or tiny numbers of their sign (a reflection about a nearly
//! axis-aligned normal, a cross product of nearly parallel vectors: an `f32` product
//! with them underflows), the origin moves a few ulps off its planes, or the whole
//! direction is scaled to a tiny or a huge length (its hits' distances stay within
//! `f32`).

use octrace_format::layout::grid_plane;
use octrace_format::SceneView;

use crate::procedural::SplitMix;

/// The planes of an octree's cells: the root cube and the depth, as the walk derives
/// every cell's planes (`layout::grid_plane`, rounded to `f32` once).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridPlanes {
    /// The root cube's low corner.
    pub root_lo: [f32; 3],
    /// The root cube's edge.
    pub root_size: f32,
    /// The finest level.
    pub depth: u32,
}

impl GridPlanes {
    /// The planes of a baked scene.
    pub fn of(view: &SceneView<'_>) -> GridPlanes {
        GridPlanes { root_lo: view.bounds.root_lo, root_size: view.bounds.root_size, depth: view.params.max_depth }
    }

    /// Plane `index` of `level` on `axis`.
    pub fn plane(&self, axis: usize, level: u32, index: u32) -> f32 {
        grid_plane(self.root_lo[axis], self.root_size, level, index)
    }

    /// The plane of `level` on `axis` nearest to `x` (within the root).
    pub fn snap(&self, axis: usize, level: u32, x: f32) -> f32 {
        let cells = (1u64 << level) as f64;
        let at = (x as f64 - self.root_lo[axis] as f64) / self.root_size as f64 * cells;
        self.plane(axis, level, at.round().clamp(0.0, cells) as u32)
    }
}

/// What makes a [`HardRay`] hard.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum HardKind {
    /// Lies in a cell plane: one zero direction component (`+0.0` or `-0.0`), on the
    /// axis of the plane its origin lies on.
    InPlane,
    /// Runs along a cell edge: two zero components, the origin on a plane of each.
    AlongEdge,
    /// Starts on a cell corner (three planes), in any direction, one or two zero
    /// components included.
    FromCorner,
    /// Passes through a cell corner at `t > 0`, exactly where the arithmetic allows
    /// (power-of-two steps), with or without a zero component.
    ThroughCorner,
}

impl HardKind {
    /// Every kind, in order.
    pub const ALL: [HardKind; 4] =
        [HardKind::InPlane, HardKind::AlongEdge, HardKind::FromCorner, HardKind::ThroughCorner];

    /// A short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            HardKind::InPlane => "in-plane",
            HardKind::AlongEdge => "along-edge",
            HardKind::FromCorner => "from-corner",
            HardKind::ThroughCorner => "through-corner",
        }
    }
}

/// How a [`HardRay`] is bent from its case: the arithmetic's edges rather than the
/// grid's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Twist {
    /// As built.
    Plain,
    /// The zero components (or, where there is none, the case's axis) become `±2^-149`,
    /// the smallest subnormal, with their sign: every product with them underflows.
    Subnormal,
    /// The same components become `±m 2^e`, `e` from -149 to -40 (subnormals up to
    /// well past where the walk's `f32` products can serve them).
    Tiny,
    /// As [`Twist::Tiny`], and every origin coordinate moved `±2^j` ulps (`j` from 0
    /// to 20) off its plane.
    OffPlane,
    /// The whole direction scaled by a power of two, to a largest component from
    /// `2^-120` to `2^100` times the root's edge (so its hits' distances stay within
    /// `f32`'s range); the zero components stay zero.
    Scaled,
}

impl Twist {
    /// Every twist, in the order the generator cycles through them.
    pub const ALL: [Twist; 5] = [Twist::Plain, Twist::Subnormal, Twist::Tiny, Twist::OffPlane, Twist::Scaled];

    /// A short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Twist::Plain => "plain",
            Twist::Subnormal => "subnormal",
            Twist::Tiny => "tiny",
            Twist::OffPlane => "off-plane",
            Twist::Scaled => "scaled",
        }
    }
}

/// A ray of [`grid_rays`] and the case it covers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HardRay {
    /// What makes it hard.
    pub kind: HardKind,
    /// How it is bent from its case.
    pub twist: Twist,
    /// The axis of the case: the zero component of an in-plane ray, the moving one of
    /// a ray along an edge, the zero component (if any) of a corner ray.
    pub axis: usize,
    /// The level whose planes the origin was snapped to.
    pub level: u32,
    /// Sign bits of the direction's components (bit `a` for axis `a`; zero components
    /// included: set for `-0.0`).
    pub signs: u32,
    /// Origin.
    pub origin: [f32; 3],
    /// Direction.
    pub dir: [f32; 3],
}

/// Cases a cycle goes through before the levels: kinds x axes x sign octants.
const CASES: u64 = 4 * 3 * 8;

/// Origins tried a case before it is given up (the point sampler's points, snapped,
/// may all fall outside what `keep` accepts: coarse planes outside a solid).
const TRIES: usize = 32;

/// `n` rays built on the planes of `grid` from points `point` draws (snapped onto the
/// planes), cycling through every case: [`HardKind`] x axis x the signs of the three
/// components x level (1 to the depth), each [`Twist`] in turn (the twist cycles with
/// period 5, the cases with 96: every twist meets every case). An origin `keep`
/// rejects is drawn again; a case whose origins it keeps rejecting is skipped.
///
/// Without `aim`, the moving components are random; with it, they point at the point
/// `aim` draws (the zero components stay zero), so that rays meet a mesh.
///
/// # Example
/// ```
/// use octrace_bake::hard_rays::{grid_rays, GridPlanes, HardKind, Twist};
/// let grid = GridPlanes { root_lo: [-1.0; 3], root_size: 2.0, depth: 6 };
/// let rays = grid_rays(&grid, 960, 1, |r| [r.unit() - 0.5; 3], None::<fn(&mut _) -> [f32; 3]>, |_| true);
/// assert_eq!(rays.len(), 960);
/// // Every in-plane ray (but those moved off it) lies in a plane of its level, with a
/// // zero component there (plain) or the smallest subnormal (subnormal).
/// for r in rays.iter().filter(|r| r.kind == HardKind::InPlane && r.twist != Twist::OffPlane) {
///     assert_eq!(r.origin[r.axis], grid.snap(r.axis, r.level, r.origin[r.axis]));
///     match r.twist {
///         Twist::Plain => assert_eq!(r.dir[r.axis], 0.0),
///         Twist::Subnormal => assert_eq!(r.dir[r.axis].abs(), f32::from_bits(1)),
///         _ => {}
///     }
/// }
/// ```
pub fn grid_rays<A: FnMut(&mut SplitMix) -> [f32; 3]>(
    grid: &GridPlanes,
    n: usize,
    seed: u64,
    mut point: impl FnMut(&mut SplitMix) -> [f32; 3],
    mut aim: Option<A>,
    keep: impl Fn([f32; 3]) -> bool,
) -> Vec<HardRay> {
    let mut rng = SplitMix(seed);
    let levels = grid.depth.max(1) as u64;
    let mut rays = Vec::with_capacity(n);
    // Every case is tried in turn; the guard ends a generator whose `keep` accepts
    // nothing.
    let mut case = 0u64;
    while rays.len() < n && case < 64 * n as u64 + CASES * levels {
        let kind = HardKind::ALL[(case % 4) as usize];
        let axis = (case / 4 % 3) as usize;
        let signs = (case / 12 % 8) as u32;
        let level = 1 + (case / CASES % levels) as u32;
        let twist = Twist::ALL[(case % Twist::ALL.len() as u64) as usize];
        case += 1;
        for _ in 0..TRIES {
            let p = point(&mut rng);
            let target = aim.as_mut().map(|aim| aim(&mut rng));
            let ray = twisted(grid, build(grid, kind, axis, signs, level, p, target, &mut rng), twist, &mut rng);
            if keep(ray.origin) {
                rays.push(ray);
                break;
            }
        }
    }
    rays
}

/// One ray of a case from point `p` (and towards `target`, where given).
#[allow(clippy::too_many_arguments)]
fn build(
    grid: &GridPlanes,
    kind: HardKind,
    axis: usize,
    signs: u32,
    level: u32,
    p: [f32; 3],
    target: Option<[f32; 3]>,
    rng: &mut SplitMix,
) -> HardRay {
    let sign = |a: usize| if signs >> a & 1 == 1 { -1.0f32 } else { 1.0 };
    // A moving component: random in [1/16, 1], or towards the target.
    let moving = |a: usize, o: [f32; 3], rng: &mut SplitMix| match target {
        Some(t) if t[a] != o[a] => (t[a] - o[a]).abs() * sign(a),
        _ => (0.0625 + 0.9375 * rng.unit()) * sign(a),
    };
    let zero = |a: usize| 0.0 * sign(a);
    let snap = |o: &mut [f32; 3], a: usize| o[a] = grid.snap(a, level, o[a]);
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut o = p;
    let mut d = [0.0f32; 3];
    match kind {
        HardKind::InPlane => {
            snap(&mut o, axis);
            d[axis] = zero(axis);
            d[u] = moving(u, o, rng);
            d[v] = moving(v, o, rng);
        }
        HardKind::AlongEdge => {
            snap(&mut o, u);
            snap(&mut o, v);
            d[axis] = moving(axis, o, rng);
            d[u] = zero(u);
            d[v] = zero(v);
        }
        HardKind::FromCorner => {
            (0..3).for_each(|a| snap(&mut o, a));
            // One zero component, two, or none, in turn.
            let zeros = (rng.next_u64() % 3) as usize;
            for a in 0..3 {
                let k = (a + 3 - axis) % 3;
                d[a] = if k < zeros { zero(a) } else { moving(a, o, rng) };
            }
        }
        HardKind::ThroughCorner => {
            // A grid vertex, then back from it along a direction of power-of-two
            // components by a power-of-two step: the ray passes through the vertex.
            let mut c = p;
            (0..3).for_each(|a| snap(&mut c, a));
            let step = grid.root_size / (1u64 << level) as f32 * [0.5, 0.25, 0.125][(rng.next_u64() % 3) as usize];
            for a in 0..3 {
                d[a] = [1.0, 0.5, 0.25, 0.75][(rng.next_u64() % 4) as usize] * sign(a);
            }
            if rng.next_u64().is_multiple_of(2) {
                d[axis] = zero(axis);
            }
            o = [0, 1, 2].map(|a| c[a] - step * d[a]);
        }
    }
    HardRay { kind, twist: Twist::Plain, axis, level, signs, origin: o, dir: d }
}

/// `ray` bent by `twist` (see [`Twist`]).
fn twisted(grid: &GridPlanes, mut ray: HardRay, twist: Twist, rng: &mut SplitMix) -> HardRay {
    ray.twist = twist;
    let d = &mut ray.dir;
    // The components a twist makes tiny: the zero ones, else the case's axis.
    let zeros: Vec<usize> = (0..3).filter(|&a| d[a] == 0.0).collect();
    let tiny = if zeros.is_empty() { vec![ray.axis] } else { zeros };
    let sign = |a: usize| if ray.signs >> a & 1 == 1 { -1.0f32 } else { 1.0 };
    match twist {
        Twist::Plain => {}
        Twist::Subnormal => tiny.iter().for_each(|&a| d[a] = f32::from_bits(1) * sign(a)),
        Twist::Tiny | Twist::OffPlane => {
            for &a in &tiny {
                d[a] = tiny_number(rng) * sign(a);
            }
            if twist == Twist::OffPlane {
                for c in &mut ray.origin {
                    *c = off_by_ulps(*c, rng);
                }
            }
        }
        Twist::Scaled => {
            let largest = d.iter().fold(0.0f32, |m, c| m.max(c.abs()));
            let root = (grid.root_size as f64).log2().floor() as i32;
            // A largest component of 2^-120 to 2^100 root edges, within f32's range.
            let target = (root - 120 + (rng.next_u64() % 221) as i32).clamp(-126, 126);
            let by = target - (largest as f64).log2().floor() as i32;
            *d = d.map(|c| (c as f64 * 2f64.powi(by)) as f32);
        }
    }
    ray
}

/// `m 2^e`, `m` in `[1, 2)` and `e` from -149 to -40, rounded to `f32` (a subnormal
/// below `2^-126`).
fn tiny_number(rng: &mut SplitMix) -> f32 {
    let e = -149 + (rng.next_u64() % 110) as i32;
    ((1.0 + rng.unit() as f64) * 2f64.powi(e)) as f32
}

/// `x` moved `±2^j` of its ulps (`j` from 0 to 20); a coordinate of zero moves by
/// subnormals.
fn off_by_ulps(x: f32, rng: &mut SplitMix) -> f32 {
    let steps = (1u32 << (rng.next_u64() % 21)) as f32;
    let ulp = f32::from_bits(x.abs().to_bits() + 1) - x.abs();
    if rng.next_u64().is_multiple_of(2) {
        x + ulp * steps
    } else {
        x - ulp * steps
    }
}

/// `d` with the sign of every zero component flipped (`+0.0` to `-0.0` and back): the
/// same line, and a different walk. Property tests run both.
pub fn flip_zero_signs(d: [f32; 3]) -> [f32; 3] {
    d.map(|c| if c == 0.0 { -c } else { c })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every case comes out: each kind on each axis, with each sign octant, at each
    /// level, and each twist with every kind, axis and sign; zero components are zero
    /// (or tiny, twisted), with the case's sign.
    #[test]
    fn every_case_is_generated() {
        let grid = GridPlanes { root_lo: [-1.5, -0.25, 3.0], root_size: 4.0, depth: 7 };
        let rays = grid_rays(
            &grid,
            CASES as usize * 7 * 3 * 5,
            5,
            |r| [r.unit() * 4.0 - 1.5, r.unit() * 4.0 - 0.25, r.unit() * 4.0 + 3.0],
            None::<fn(&mut SplitMix) -> [f32; 3]>,
            |_| true,
        );
        let mut seen = std::collections::HashSet::new();
        let mut twisted = std::collections::HashSet::new();
        for r in &rays {
            seen.insert((r.kind, r.axis, r.signs, r.level));
            twisted.insert((r.kind, r.axis, r.signs, r.twist));
            let bent = matches!(r.twist, Twist::Subnormal | Twist::Tiny | Twist::OffPlane);
            let on_plane = |a: usize| r.twist == Twist::OffPlane || r.origin[a] == grid.snap(a, r.level, r.origin[a]);
            // Zero components, or what a twist made of them: tiny, of the case's sign.
            let flat = |a: usize| if bent { r.dir[a].abs() < 2f32.powi(-39) } else { r.dir[a] == 0.0 };
            let zeros: Vec<usize> = (0..3).filter(|&a| flat(a)).collect();
            for &a in &zeros {
                assert_eq!(r.dir[a].is_sign_negative(), r.signs >> a & 1 == 1, "{r:?}");
            }
            if r.twist == Twist::Subnormal {
                assert!(zeros.iter().all(|&a| r.dir[a].abs() == f32::from_bits(1)), "{r:?}");
            }
            if r.twist == Twist::Scaled {
                let largest = r.dir.iter().fold(0.0f32, |m, c| m.max(c.abs()));
                assert!(largest >= 2f32.powi(-119) && largest < 2f32.powi(103), "{r:?}");
            }
            match r.kind {
                HardKind::InPlane => assert!(zeros == [r.axis] && on_plane(r.axis), "{r:?}"),
                HardKind::AlongEdge => {
                    assert_eq!(zeros.len(), 2, "{r:?}");
                    assert!(zeros.iter().all(|&a| a != r.axis && on_plane(a)), "{r:?}");
                }
                HardKind::FromCorner => assert!((0..3).all(on_plane) && zeros.len() < 3, "{r:?}"),
                HardKind::ThroughCorner if r.twist == Twist::Plain => {
                    // Some step of the three takes the origin onto a grid vertex.
                    let cell = grid.root_size / (1u64 << r.level) as f32;
                    let through = [0.5, 0.25, 0.125].iter().any(|s| {
                        let c = [0, 1, 2].map(|a| r.origin[a] + cell * s * r.dir[a]);
                        (0..3).all(|a| c[a] == grid.snap(a, r.level, c[a]))
                    });
                    assert!(through, "{r:?}");
                }
                HardKind::ThroughCorner => {}
            }
        }
        assert_eq!(seen.len(), CASES as usize * 7, "some case never came out");
        assert_eq!(twisted.len(), CASES as usize * Twist::ALL.len(), "some twist never met some case");
    }

    #[test]
    fn flipping_zero_signs_keeps_the_line() {
        let d = flip_zero_signs([0.0, -0.0, 0.5]);
        assert!(d[0].is_sign_negative() && d[1].is_sign_positive() && d[2] == 0.5);
    }
}
