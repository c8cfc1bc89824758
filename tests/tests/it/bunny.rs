//! The bunny's standard ray sets: the octree agrees with the f64 oracle ray for ray
//! (on a sample: the oracle tests every triangle), and the whole sets reproduce the
//! checksums every correct tracer gives (`shared/bench/PEERS.md`).

use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::Reference;
use octrace_runtime::{Hit, Ray};
use octrace_tests::{bunny_mesh, bunny_scene};

fn frame() -> Frame {
    Frame::from_triangles(&bunny_mesh().triangles)
}

fn oracle() -> Reference {
    let m = bunny_mesh();
    Reference::new(m.triangles.clone(), (0..m.triangles.len() as u32).collect())
}

/// Same triangle, or the same distance within 1e-5 t (two triangles tie there).
fn agree(got: Option<Hit>, want: Option<(f64, u32)>) -> bool {
    match (got, want) {
        (None, None) => true,
        (Some(h), Some((t, id))) => h.triangle == id || (h.t as f64 - t).abs() <= 1e-5 * t,
        _ => false,
    }
}

fn sample_agrees(name: &str, rays: &[Ray], step: usize) {
    let scene = bunny_scene();
    let oracle = oracle();
    let mut checked = 0;
    for r in rays.iter().step_by(step) {
        let want = oracle.intersect(r).map(|h| (h.t, h.triangle));
        let got = scene.intersect(r);
        assert!(agree(got, want), "{name}: ray {r:?}: octree {got:?}, oracle {want:?}");
        checked += 1;
    }
    assert!(checked > 300, "{name}: only {checked} rays checked");
}

fn checksum(hits: &[Option<Hit>]) -> (usize, f64) {
    let n = hits.iter().flatten().count();
    (n, hits.iter().flatten().map(|h| h.t as f64).sum())
}

fn within(got: usize, want: usize) -> bool {
    got.abs_diff(want) * 10_000 <= want * 3
}

#[test]
fn primary_agrees_with_the_oracle_and_the_published_checksum() {
    let rays = raysets::primary(&frame());
    sample_agrees("primary", &rays, 1009);
    let hits = bunny_scene().intersect_all(&rays);
    let (n, sum) = checksum(&hits);
    assert!(within(n, 223_442), "primary hits {n}, published 223442");
    assert!((sum - 69_618.09).abs() < 69_618.09 * 3e-4, "primary sum of t {sum}, published 69618.09");
}

#[test]
fn incoherent_agrees_with_the_oracle_and_the_published_checksum() {
    let rays = raysets::incoherent(&frame(), 1_000_000);
    sample_agrees("incoherent", &rays, 997);
    let hits = bunny_scene().intersect_all(&rays);
    let (n, sum) = checksum(&hits);
    assert!(within(n, 431_741), "incoherent hits {n}, published 431741");
    assert!((sum - 14_676.46).abs() < 14_676.46 * 3e-4, "incoherent sum of t {sum}, published 14676.46");
}

#[test]
fn shadow_agrees_with_the_oracle_and_the_published_checksum() {
    let f = frame();
    let scene = bunny_scene();
    let hits = scene.intersect_all(&raysets::primary(&f));
    let rays = raysets::shadow(&f, |i| hits[i].map(|h| (h.t, scene.view().triangle(h.prim))));
    let oracle = oracle();
    for r in rays.iter().step_by(211) {
        assert_eq!(scene.occluded(r), oracle.occluded(r), "shadow ray {r:?}");
    }
    let occluded = scene.occluded_all(&rays).iter().filter(|&&o| o).count();
    assert!(within(occluded, 121_774), "shadow occluded {occluded}, published 121774");
}
