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
