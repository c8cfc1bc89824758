//! The bunny's standard ray sets: the octree agrees with the f64 oracle ray for ray
//! (on a sample: the oracle tests every triangle), and the whole sets reproduce the
//! checksums every correct tracer gives (`shared/bench/PEERS.md`).

use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::{Agreement, Reference};
use octrace_runtime::{Hit, Ray};
use octrace_tests::{bunny_mesh, bunny_scene};

fn frame() -> Frame {
    Frame::from_triangles(&bunny_mesh().triangles)
}

fn oracle() -> Reference {
    Reference::in_input_order(bunny_mesh().triangles.clone())
}

/// Every `step`-th ray gives the oracle's answer: the same triangle, or the same
/// distance within 1e-5 t (two triangles tie there).
fn sample_agrees(name: &str, rays: &[Ray], step: usize) {
    let scene = bunny_scene();
    let oracle = oracle();
    let mut checked = 0;
    for r in rays.iter().step_by(step) {
        let got = scene.intersect(r);
        let verdict = oracle.compare(r, got.map(|h| (h.t, h.triangle, h.u, h.v)));
        assert_eq!(verdict, Agreement::Same, "{name}: ray {r:?}: octree {got:?}, oracle {:?}", oracle.intersect(r));
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

/// A sample of `rays` agrees with the oracle, and the whole set reproduces the
/// published hits and sum of distances.
fn set_agrees(name: &str, rays: &[Ray], step: usize, published_hits: usize, published_sum: f64) {
    sample_agrees(name, rays, step);
    let (n, sum) = checksum(&bunny_scene().intersect_batch(rays));
    assert!(within(n, published_hits), "{name} hits {n}, published {published_hits}");
    assert!((sum - published_sum).abs() < published_sum * 3e-4, "{name} sum of t {sum}, published {published_sum}");
}

#[test]
fn primary_agrees_with_the_oracle_and_the_published_checksum() {
    set_agrees("primary", &raysets::primary(&frame()), 1009, 223_442, 69_618.09);
}

#[test]
fn incoherent_agrees_with_the_oracle_and_the_published_checksum() {
    set_agrees("incoherent", &raysets::incoherent(&frame(), 1_000_000), 997, 431_741, 14_676.46);
}

#[test]
fn shadow_agrees_with_the_oracle_and_the_published_checksum() {
    let f = frame();
    let scene = bunny_scene();
    let hits = scene.intersect_batch(&raysets::primary(&f));
    let rays = raysets::shadow(&f, |i| hits[i].map(|h| (h.t, scene.view().triangle(h.prim))));
    let oracle = oracle();
    for r in rays.iter().step_by(211) {
        assert_eq!(scene.occluded(r), oracle.occluded(r), "shadow ray {r:?}");
    }
    let occluded = scene.occluded_batch(&rays).iter().filter(|&&o| o).count();
    assert!(within(occluded, 121_774), "shadow occluded {occluded}, published 121774");
}

/// The interval is closed (`Ray`'s docs): a segment that ends exactly at its nearest
/// hit still hits there, for the nearest-hit and any-hit queries, one ray or a batch,
/// and one that ends an ulp before it does not.
#[test]
fn a_hit_at_exactly_tmax_counts_on_every_path() {
    let scene = bunny_scene();
    let tracer = scene.tracer();
    // Rays from inside the scene's box, and from a camera outside it (whose origins
    // the walk moves onto the root cube first).
    let mut rays = raysets::incoherent(&frame(), 20_000);
    rays.extend(raysets::primary(&frame()).into_iter().step_by(53));
    // An axis-aligned ray from below the bunny, its origin off the root cube.
    rays.push(Ray::new(
        [f32::from_bits(0xbc89f517), f32::from_bits(0x3de1986c), f32::from_bits(0xc000192f)].into(),
        [0.0, 0.0, 1.0].into(),
    ));
    let mut checked = 0;
    let mut ended = Vec::new();
    for r in &rays {
        let Some(h) = scene.intersect(r) else { continue };
        let at = Ray { tmax: h.t, ..*r };
        let short = Ray { tmax: f32::from_bits(h.t.to_bits() - 1), ..*r };
        assert_eq!(scene.intersect(&at), Some(h), "ray {r:?} ending at its hit {h:?}");
        assert_eq!(tracer.intersect_scalar(&at), Some(h), "scalar: ray {r:?} ending at its hit {h:?}");
        assert!(scene.occluded(&at), "occluded: ray {r:?} ending at its hit {h:?}");
        assert!(tracer.occluded_scalar(&at), "occluded, scalar: ray {r:?} ending at its hit {h:?}");
        assert_eq!(scene.occluded_batch(&[at]), [true], "occluded_batch: ray {r:?} ending at its hit {h:?}");
        assert_eq!(scene.intersect_batch(&[at]), [Some(h)], "intersect_batch: ray {r:?} ending at its hit {h:?}");
        let before = scene.intersect(&short);
        assert!(before.is_none_or(|b| b.t < h.t), "ray {r:?} ending an ulp before its hit {h:?}: {before:?}");
        ended.push(at);
        checked += 1;
    }
    assert!(checked > 5_000, "only {checked} rays hit");
    assert!(scene.occluded_batch(&ended).iter().all(|&o| o), "occluded_batch");
    assert!(scene.intersect_batch(&ended).iter().all(Option::is_some), "intersect_batch");
}
