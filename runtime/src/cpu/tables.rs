//! The exit-face table and its conventions (replacing the paper's lost Figure 4).
//!
//! Portalez & Duguet 2016, section 4.2.1: inside a cell, a ray leaves through one of
//! the three faces its direction's signs point at. Which one is decided by the signs
//! of the ray's Plücker products with the three cell edges that meet at the *exit
//! corner* `c` (per axis, the high plane if the direction is positive, else the low).
//!
//! # Conventions
//! * Faces: `2 * axis + side`, see `octrace_format::layout`.
//! * Octant: bit `a` set when the direction's component `a` has its sign bit set
//!   (so `-0.0` counts as negative, consistently with the exit corner).
//! * With `a_i = c_i - o_i`, the Plücker product of the ray with the corner edge
//!   parallel to axis `k` (the other two being `i`, `j`) is
//!   `P_ij = a_i * d_j - a_j * d_i`. Since `t_i = a_i / d_i`,
//!   `t_i - t_j = P_ij / (d_i * d_j)`: the ray leaves across `i` before `j` exactly
//!   when `P_ij * sign(d_i) * sign(d_j) < 0`.
//! * Code: bit 0 is `P_xy > 0` (edge along z), bit 1 `P_yz > 0` (edge along x),
//!   bit 2 `P_zx > 0` (edge along y).
//!
//! `EXIT_FACE[octant][code]` is the face whose axis leaves first. Two codes per octant
//! are cyclic (x before y before z before x): exact arithmetic never produces them,
//! rounding might, and they map to the octant's x face, a face the ray can leave by.
//! A zero direction component is never chosen while the origin lies strictly inside the
//! cell along that axis, since its product then has the sign that says "later"; on the
//! cell's plane both its products are zero and the code says nothing, so the walks
//! decide every ray with a zero component by slab distances instead
//! (`walk::exit_along_moving_axes` states the rule).
//!
//! # Which rule a ray follows
//! The table is read from `f32` products of corner offsets and direction components,
//! and a product whose exact value falls below `f32`'s normal range keeps only its
//! absolute error (`2^-150`), not a relative one: with a component of `1e-45` next to
//! one of `1`, every product with it is zero and the code is as blind as on a cell
//! plane with `±0`. And `1 / d` overflows for `|d| < 2^-128`, so an exit distance
//! computed as `offset * (1 / d)` becomes infinite. [`exit_rule`] decides once a ray,
//! from exponents alone, which of three rules its walk follows ([`ExitRule`]): the
//! table, the slab rule among the moving axes (components of `±0`), or exact
//! decisions in `f64` for every direction the `f32` arithmetic cannot serve. Every
//! walk (scalar, SSE, the eight lanes, both WGSL kernels) takes its rule from here.

/// Exit face by direction octant and Plücker sign code.
pub const EXIT_FACE: [[u8; 8]; 8] = [
    [1, 3, 5, 5, 1, 3, 1, 1],
    [3, 0, 0, 0, 3, 0, 5, 5],
    [5, 5, 2, 1, 1, 1, 2, 1],
    [0, 0, 0, 2, 5, 5, 0, 2],
    [1, 1, 1, 3, 4, 4, 1, 3],
    [4, 4, 3, 0, 0, 0, 3, 0],
    [2, 1, 1, 1, 2, 1, 4, 4],
    [0, 2, 4, 4, 0, 2, 0, 0],
];

/// The rows of [`EXIT_FACE`] packed four bits a code (code `c` in bits `4c..4c + 4`),
/// for the vector step's lane-by-lane lookup.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) const EXIT_ROWS: [u32; 8] = {
    let mut rows = [0u32; 8];
    let mut oct = 0;
    while oct < 8 {
        let mut code = 0;
        while code < 8 {
            rows[oct] |= (EXIT_FACE[oct][code] as u32) << (4 * code);
            code += 1;
        }
        oct += 1;
    }
    rows
};

/// The exit code of a ray in a cell: the three Plücker sign bits.
#[inline(always)]
pub fn exit_code(a: [f32; 3], d: [f32; 3]) -> usize {
    let p_xy = a[0] * d[1] - a[1] * d[0];
    let p_yz = a[1] * d[2] - a[2] * d[1];
    let p_zx = a[2] * d[0] - a[0] * d[2];
    (p_xy > 0.0) as usize | ((p_yz > 0.0) as usize) << 1 | ((p_zx > 0.0) as usize) << 2
}

/// The octant of a direction: sign bits.
#[inline(always)]
pub fn octant(d: [f32; 3]) -> usize {
    (d[0].is_sign_negative() as usize)
        | (d[1].is_sign_negative() as usize) << 1
        | (d[2].is_sign_negative() as usize) << 2
}

/// How a ray's walk decides the face it leaves each leaf by ([`exit_rule`] picks it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExitRule {
    /// The Plücker signs into [`EXIT_FACE`], in `f32`: every component nonzero and
    /// within the range where `f32` products keep their relative precision.
    Table,
    /// Some components are `+0.0` or `-0.0`, the others as for [`ExitRule::Table`]:
    /// the nearest exit among the moving axes, in `f32` (`walk::exit_along_moving_axes`).
    Flat,
    /// A nonzero component so small (against the others, or against the scene's
    /// scale), or a direction or origin so large, that an `f32` product could underflow
    /// or overflow: every decision of every step (exit face, exit distance, the sides
    /// of the face's median lines) is taken from exact `f64` products of the same `f32`
    /// offsets and components ([`exact_exit`], [`exact_side`]), and components of `±0`
    /// do not move. Rare; the CPU walks such rays with its scalar step.
    Exact,
}

/// What [`exit_rule`] reads of a scene: binary exponents of its root cube's edge and
/// of its largest corner coordinate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RuleScale {
    /// `exponent(root edge)`.
    pub root: i32,
    /// `exponent(largest |coordinate| of the root's corners)`.
    pub reach: i32,
}

impl RuleScale {
    /// The scale of a root cube.
    pub fn of(root_lo: [f32; 3], root_hi: [f32; 3], root_size: f32) -> RuleScale {
        let largest = root_lo.iter().chain(&root_hi).fold(0.0f32, |m, c| m.max(c.abs()));
        RuleScale { root: exponent(root_size), reach: exponent(largest) }
    }
}

/// The unbiased binary exponent of `|x|` read from its bits: `e` with
/// `2^e <= |x| < 2^(e + 1)` for normal `x`; `-127` for zero and subnormals, `128` for
/// infinities and NaN. Integer arithmetic on the bits, so that every walk (and the
/// kernels, whatever their float modes) reads the same value.
#[inline(always)]
pub fn exponent(x: f32) -> i32 {
    ((x.to_bits() >> 23) & 0xFF) as i32 - 127
}

/// Smallest exponent of a moving component the `f32` rules accept: `1 / d` and the
/// exit distances stay far inside `f32`'s range.
pub const RULE_MIN_EXPONENT: i32 = -100;
/// The `f32` rules accept a direction when `2 e_min + e_root >= e_max - RULE_SPREAD`
/// (exponents of its smallest moving component, the root edge and its largest
/// component; see [`exit_rule`]).
pub const RULE_SPREAD: i32 = 119;
/// The `f32` rules accept a direction when `e_max + max(e_origin, e_reach) <=
/// RULE_MAX_PRODUCT`: every product of an offset and a component below `2^103`.
pub const RULE_MAX_PRODUCT: i32 = 100;

/// The rule a ray's walk follows, from the exponents of its origin and direction and
/// the scene's [`RuleScale`].
///
/// The `f32` rules ([`ExitRule::Table`], [`ExitRule::Flat`]) compare products
/// `a_i d_j` of corner offsets and components. With `δ` the smallest moving component,
/// `D` the largest and `R` the root edge, they are accepted when
/// * `δ >= 2^-100`: `1 / δ` is finite and so is every exit distance's reciprocal;
/// * `δ² R >= 2^-120 D` (as `2 e_min + e_root >= e_max - 119`): a product can
///   underflow only where an offset is tiny, and an underflowed product is off by at
///   most `2^-150`; in exit distances that is `2^-149 / (d_i d_j)`, a point off by at
///   most `2^-148 D / δ²` along the ray, which this bounds by `2^-28 R`, far inside the
///   bake's margin (`2^-20 R` by default), which already absorbs the table's rounding;
/// * `D (|o| + reach) < 2^103`: no product overflows.
///
/// A ray failing any of them follows [`ExitRule::Exact`], whose products are exact in
/// `f64` whatever the exponents (an `f32` product needs 48 bits and exponents from
/// `-298` to `256`). The exponents are integers read from the bits ([`exponent`]), so
/// every walk, CPU or GPU, picks the same rule for the same ray.
#[inline(always)]
pub fn exit_rule(o: [f32; 3], d: [f32; 3], scale: RuleScale) -> ExitRule {
    let e = [exponent(d[0]), exponent(d[1]), exponent(d[2])];
    let zero = [d[0] == 0.0, d[1] == 0.0, d[2] == 0.0];
    // Exponents of the moving components; a zero one is left out of the minimum (it
    // does not move: 200 is past every exponent) and counts as -127 in the maximum.
    let moving_min = |k: usize| if zero[k] { 200 } else { e[k] };
    let e_min = moving_min(0).min(moving_min(1)).min(moving_min(2));
    let e_max = e[0].max(e[1]).max(e[2]);
    let e_origin = exponent(o[0]).max(exponent(o[1])).max(exponent(o[2]));
    let served = e_min >= RULE_MIN_EXPONENT
        && 2 * e_min + scale.root >= e_max - RULE_SPREAD
        && e_max + e_origin.max(scale.reach) <= RULE_MAX_PRODUCT;
    if !served {
        ExitRule::Exact
    } else if zero[0] || zero[1] || zero[2] {
        ExitRule::Flat
    } else {
        ExitRule::Table
    }
}

/// Whether the ray leaves across axis `i`'s plane strictly before axis `j`'s (both
/// moving): `off_i / d_i < off_j / d_j`, decided exactly. With
/// `p = off_i d_j - off_j d_i = d_i d_j (t_i - t_j)`, in `f64`: the products of `f32`
/// values are exact and the difference's sign is the exact one.
#[inline(always)]
fn exits_before(off: [f32; 3], d: [f32; 3], i: usize, j: usize) -> bool {
    let p = off[i] as f64 * d[j] as f64 - off[j] as f64 * d[i] as f64;
    if d[i].is_sign_negative() == d[j].is_sign_negative() {
        p < 0.0
    } else {
        p > 0.0
    }
}

/// The exit face and exit distance of a walk under [`ExitRule::Exact`]: the moving
/// axis whose exit plane (offset `off`, from the origin to the exit corner) the ray
/// meets first, decided exactly (ties to the lowest axis; components of `±0` never
/// leave, as in the slab rule), and `off / d` along it rounded once to `f32` (an
/// overflow is `±inf`: an exit beyond every representable distance).
#[cold]
#[inline(never)]
pub fn exact_exit(off: [f32; 3], d: [f32; 3]) -> (usize, f32) {
    let mut axis = 3;
    for k in 0..3 {
        if d[k] != 0.0 && (axis == 3 || exits_before(off, d, k, axis)) {
            axis = k;
        }
    }
    // A traceable ray moves along some axis; a zero direction (never walked) leaves by x.
    let axis = axis % 3;
    let t = (off[axis] as f64 / d[axis] as f64) as f32;
    (2 * axis + !d[axis].is_sign_negative() as usize, t)
}

/// The side bit of axis `k` under [`ExitRule::Exact`]: the sign of the Plücker product
/// with the median line through the exit face's centre, `off_a d_k - m_k d_a` (`m_k`
/// the centre's offset from the origin along `k`, `off_a` and `d_a` the exit axis's
/// offset and component), exact in `f64`; set when positive, flipped on a low face,
/// as the `f32` step's side bits are.
#[inline(always)]
pub fn exact_side(off_a: f32, d_a: f32, m_k: f32, d_k: f32, negative_a: bool) -> u32 {
    let p = off_a as f64 * d_k as f64 - m_k as f64 * d_a as f64;
    ((p > 0.0) ^ negative_a) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exit face by slab distances: the axis whose exit plane is nearest.
    fn slab_exit(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> usize {
        let t = [0, 1, 2].map(|a| {
            let c = if d[a].is_sign_negative() { lo[a] } else { hi[a] };
            if d[a] == 0.0 {
                f64::INFINITY
            } else {
                (c as f64 - o[a] as f64) / d[a] as f64
            }
        });
        let axis = (0..3).min_by(|&i, &j| t[i].total_cmp(&t[j])).unwrap();
        2 * axis + !d[axis].is_sign_negative() as usize
    }

    fn corner_offsets(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> [f32; 3] {
        [0, 1, 2].map(|a| if d[a].is_sign_negative() { lo[a] } else { hi[a] } - o[a])
    }

    /// Deterministic pseudo-random numbers in [0, 1).
    fn rng(seed: &mut u64) -> f32 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn the_table_matches_slab_exits_for_every_octant_and_every_code() {
        let (lo, hi) = ([0.0f32; 3], [1.0f32; 3]);
        let mut seen = [[false; 8]; 8];
        let mut seed = 7u64;
        for _ in 0..200_000 {
            let o = [0; 3].map(|_| 0.05 + 0.9 * rng(&mut seed));
            let d = [0; 3].map(|_| 2.0 * rng(&mut seed) - 1.0);
            let a = corner_offsets(o, d, lo, hi);
            let (oct, code) = (octant(d), exit_code(a, d));
            seen[oct][code] = true;
            assert_eq!(EXIT_FACE[oct][code] as usize, slab_exit(o, d, lo, hi), "o {o:?} d {d:?}");
        }
        for oct in 0..8 {
            let reached = seen[oct].iter().filter(|&&s| s).count();
            // Six of the eight codes are geometrically possible in each octant.
            assert_eq!(reached, 6, "octant {oct}: {:?}", seen[oct]);
            for code in 0..8 {
                let face = EXIT_FACE[oct][code] as usize;
                let axis = face >> 1;
                // Every entry, reachable or not, is a face the octant can leave by.
                assert_eq!(face & 1, ((oct >> axis) & 1) ^ 1, "octant {oct} code {code}");
                if !seen[oct][code] {
                    assert_eq!(axis, 0, "unreachable codes map to the x face");
                }
            }
        }
    }

    #[test]
    fn the_rule_follows_the_exponents() {
        let unit = RuleScale::of([-1.0; 3], [1.0; 3], 2.0);
        let o = [0.25, -0.5, 0.0];
        let sub = f32::from_bits(1);
        assert_eq!(exit_rule(o, [0.3, -0.5, 0.8], unit), ExitRule::Table);
        assert_eq!(exit_rule(o, [0.3, -0.0, 0.8], unit), ExitRule::Flat);
        assert_eq!(exit_rule(o, [0.0, -0.0, 0.8], unit), ExitRule::Flat);
        // The reproductions: subnormal components, and a whole direction of
        // magnitude 1e-37 (1 / d overflows).
        assert_eq!(exit_rule([-0.875, -0.5, 0.0], [-sub, -sub, -1.0], unit), ExitRule::Exact);
        assert_eq!(exit_rule(o, [-9.854e-38, -1.690e-38, 1.946e-39], unit), ExitRule::Exact);
        // A component 2^-60 next to 1 in a unit scene: the products' underflow stays
        // below 2^-28 of the root (the rule's bound); 2^-61 does not.
        assert_eq!(exit_rule(o, [2f32.powi(-59), 0.5, 1.0], unit), ExitRule::Table);
        assert_eq!(exit_rule(o, [2f32.powi(-61), 0.5, 1.0], unit), ExitRule::Exact);
        // 1e-20 is served in a scene 2^40 times larger, not in the unit one; in a scene
        // 2^40 times smaller, 1e-8 is (its products stay normal), 1e-30 not.
        let large = RuleScale::of([-1e12; 3], [1e12; 3], 2e12);
        let small = RuleScale::of([-1e-12; 3], [1e-12; 3], 2e-12);
        assert_eq!(exit_rule([0.0; 3], [1e-20, 0.5, 1.0], large), ExitRule::Table);
        assert_eq!(exit_rule([0.0; 3], [1e-20, 0.5, 1.0], unit), ExitRule::Exact);
        assert_eq!(exit_rule([0.0; 3], [1e-8, 0.5, 1.0], small), ExitRule::Table);
        assert_eq!(exit_rule([0.0; 3], [1e-30, 0.5, 1.0], small), ExitRule::Exact);
        // Huge directions, or origins far out, whose products would overflow.
        assert_eq!(exit_rule(o, [1e30, 0.5, 1.0], unit), ExitRule::Table);
        assert_eq!(exit_rule(o, [1e35, 0.5, 1.0], unit), ExitRule::Exact);
        assert_eq!(exit_rule([1e30, 0.0, 0.0], [1e2, 0.5, 1.0], unit), ExitRule::Exact);
        assert_eq!(exit_rule([1e20, 0.0, 0.0], [1.0, 0.5, 1.0], unit), ExitRule::Table);
        assert_eq!(exponent(0.0), -127);
        assert_eq!(exponent(-0.0), -127);
        assert_eq!(exponent(sub), -127);
        assert_eq!(exponent(1.5), 0);
        assert_eq!(exponent(-0.75), -1);
    }

    /// The exact rule's face is the slab exit computed in exact rational arithmetic
    /// (here: `f64` quotients compared, which decide every case below apart from exact
    /// ties, which go to the lowest axis in both), whatever the exponents; where `f32`
    /// products underflow, the table's code is wrong on a sizeable share of them.
    #[test]
    fn the_exact_rule_leaves_by_the_nearest_plane_where_the_table_cannot() {
        let mut seed = 13u64;
        let mut table_wrong = 0;
        for i in 0..100_000 {
            let mut o = [0; 3].map(|_| 0.05 + 0.9 * rng(&mut seed));
            let mut d = [0; 3].map(|_| 2.0 * rng(&mut seed) - 1.0);
            // One or two components tiny (down to the smallest subnormal), some zero;
            // the origin on a tiny axis's exit plane (or a hair before it) half the time.
            for k in 0..3 {
                if rng(&mut seed) < 0.4 {
                    let e = -149 + (rng(&mut seed) * 100.0) as i32;
                    d[k] = (2f64.powi(e) * (1.0 + rng(&mut seed) as f64)) as f32 * d[k].signum();
                    if rng(&mut seed) < 0.5 {
                        let plane = if d[k] < 0.0 { 0.0f32 } else { 1.0 };
                        o[k] = if rng(&mut seed) < 0.5 { plane } else { plane - d[k].signum() * 1e-30 };
                    }
                } else if i % 7 == 0 && rng(&mut seed) < 0.2 {
                    d[k] = 0.0 * d[k].signum();
                }
            }
            if d.iter().all(|&c| c == 0.0) {
                continue;
            }
            let a = corner_offsets(o, d, [0.0; 3], [1.0; 3]);
            let (face, t) = exact_exit(a, d);
            let moving = (0..3).filter(|&k| d[k] != 0.0);
            let t_exact = moving.map(|k| a[k] as f64 / d[k] as f64).fold(f64::INFINITY, f64::min);
            let axis = face >> 1;
            assert_ne!(d[axis], 0.0, "o {o:?} d {d:?}");
            assert_eq!(a[axis] as f64 / d[axis] as f64, t_exact, "o {o:?} d {d:?}");
            assert_eq!(t, t_exact as f32);
            assert_eq!(face & 1, !d[axis].is_sign_negative() as usize);
            table_wrong += (!d.contains(&0.0) && EXIT_FACE[octant(d)][exit_code(a, d)] as usize != face) as usize;
        }
        assert!(table_wrong > 1000, "the table erred on {table_wrong} rays only");
    }

    #[test]
    fn zero_components_are_never_chosen_from_inside_the_cell() {
        let (lo, hi) = ([0.0f32; 3], [1.0f32; 3]);
        let mut seed = 11u64;
        for _ in 0..50_000 {
            let o = [0; 3].map(|_| 0.01 + 0.98 * rng(&mut seed));
            for zeros in 1..7u32 {
                let mut d = [0; 3].map(|_| 2.0 * rng(&mut seed) - 1.0);
                for a in 0..3 {
                    if zeros >> a & 1 == 1 {
                        d[a] = if rng(&mut seed) < 0.5 { 0.0 } else { -0.0 };
                    }
                }
                if d.iter().all(|&c| c == 0.0) {
                    continue;
                }
                let a = corner_offsets(o, d, lo, hi);
                let face = EXIT_FACE[octant(d)][exit_code(a, d)] as usize;
                assert_ne!(d[face >> 1], 0.0, "o {o:?} d {d:?} chose a zero axis");
                assert_eq!(face, slab_exit(o, d, lo, hi));
            }
        }
    }
}
