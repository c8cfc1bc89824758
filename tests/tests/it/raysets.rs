//! The standard ray sets are generated bit for bit as `bench/RAYS.md` says.
//!
//! The expected bits come from an independent generator (Python, the same IEEE `f64`
//! arithmetic and libm), run over `shared/meshes/bunny.obj`.

use octrace_runtime::raysets::{self, Frame, Pcg32};
use octrace_runtime::Ray;
use octrace_tests::bunny_mesh;

fn bits(r: &Ray) -> [u32; 6] {
    let (o, d) = (r.origin, r.dir);
    [o.x, o.y, o.z, d.x, d.y, d.z].map(f32::to_bits)
}

#[test]
fn the_bunny_frame_is_the_box_of_its_used_vertices() {
    let f = Frame::from_triangles(&bunny_mesh().triangles);
    let lo = [f.lo.x, f.lo.y, f.lo.z].map(|v| (v as f32).to_bits());
    let hi = [f.hi.x, f.hi.y, f.hi.z].map(|v| (v as f32).to_bits());
    assert_eq!(lo, [0xbdc1ecd5, 0x3d071d60, 0xbd7d6f97]);
    assert_eq!(hi, [0x3d79e493, 0x3e3fd114, 0x3d70d845]);
}

#[test]
fn primary_rays_are_bit_identical() {
    let rays = raysets::primary(&Frame::from_triangles(&bunny_mesh().triangles));
    assert_eq!(rays.len(), 1 << 20);
    let eye = [0x3dbbf709, 0x3e403ee4, 0x3e9e1be7];
    for (i, dir) in [
        (0, [0xbf24459b, 0x3e18f9a8, 0xbf409536]),
        (524800, [0xbea46848, 0xbe6b928f, 0xbf6b2e5d]),
        (1048575, [0x3db18df1, 0xbf0bba51, 0xbf555a66]),
        (717100, [0xbeeb4823, 0xbebcaf32, 0xbf4edf53]),
    ] {
        let b = bits(&rays[i]);
        assert_eq!((&b[..3], &b[3..]), (&eye[..], &dir[..]), "primary ray {i}");
        assert_eq!((rays[i].tmin, rays[i].tmax), (0.0, f32::INFINITY));
    }
}

#[test]
fn incoherent_rays_are_bit_identical() {
    let rays = raysets::incoherent(&Frame::from_triangles(&bunny_mesh().triangles), 1_000_000);
    for (i, want) in [
        (0, [0xbd9f5dc3, 0x3e311ce5, 0xbc51a9b5, 0xbe65d8bb, 0xbf1f21ff, 0xbf401f44]),
        (1, [0x3cac9fa8, 0x3d70f6d7, 0x3c570fad, 0x3f28dba8, 0xbf014acc, 0x3f0e803a]),
        (2, [0xbd0410c9, 0x3dc0ea41, 0xbca3f221, 0x3e74eb8b, 0xbf6bbc7f, 0xbe9dac8c]),
        (999999, [0xbd3949f2, 0x3d7266ca, 0xbd237eba, 0xbe929e2e, 0x3f74cf7e, 0xbd727280]),
    ] {
        assert_eq!(bits(&rays[i]), want, "incoherent ray {i}");
    }
}

#[test]
fn pcg32_matches_the_reference_sequence() {
    // pcg32-global-demo's first outputs for pcg32_srandom_r(42, 54).
    let mut g = Pcg32::new(42, 54);
    let first: Vec<u32> = (0..6).map(|_| g.next_u32()).collect();
    assert_eq!(first, [0xa15c02b7, 0x7b47f409, 0xba1d3330, 0x83d2f293, 0xbfa4784b, 0xcbed606e]);
}

#[test]
fn the_light_is_where_rays_md_puts_it() {
    let l = Frame::from_triangles(&bunny_mesh().triangles).light();
    assert_eq!([l.x, l.y, l.z], [-0.12493058549776898, 0.3263341723862335, 0.06331705194661157]);
}
