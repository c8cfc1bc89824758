//! The hard rays of a mesh: rays that random sets never draw, each kind priced as
//! wrong answers per million beside the random rays' error.

use glam::Vec3;
use octrace_bake::hard_rays::{grid_rays, GridPlanes, HardKind};
use octrace_bake::procedural::SplitMix;
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::reference::Reference;
use octrace_runtime::Ray;
use rayon::prelude::*;

use super::measure::{errors_of, want, Errors, Traced, Want};

/// The kinds, in the report's order. `far` is the same mix of rays as the others, shot
/// at the mesh moved [`FAR`] times its size from the origin.
pub(super) const KINDS: [&str; 8] =
    ["in-plane", "along-edge", "corners", "grazing", "vertex-aimed", "slivers", "on-surface", "far"];

/// How far the far kind's copy of the mesh lies from the origin, in root edges.
pub(super) const FAR: f64 = 1e4;

/// One kind's rays and the oracle's answers.
struct Kind {
    name: &'static str,
    rays: Vec<Ray>,
    wants: Vec<Want>,
}

/// The hard rays of a mesh, and of its far copy.
pub(super) struct HardSet {
    kinds: Vec<Kind>,
    reference: Reference,
    far: Kind,
    far_reference: Reference,
    /// The mesh moved [`FAR`] root edges from the origin: each configuration is built
    /// on it again for the far kind.
    pub far_mesh: Mesh,
}

impl HardSet {
    /// `n` rays of each kind at `mesh` (grid rays on the planes of its bake with the
    /// default parameters) and at its far copy, and the oracle's answers.
    pub(super) fn new(mesh: &Mesh, n: usize) -> anyhow::Result<HardSet> {
        let rays = kinds(mesh, n)?;
        let reference = Reference::in_input_order(mesh.triangles.clone());
        let answered = |(name, rays): (&'static str, Vec<Ray>), reference: &Reference| {
            let wants = rays.par_iter().map(|r| want(reference, r, false)).collect();
            Kind { name, rays, wants }
        };
        let kinds = rays.into_iter().map(|k| answered(k, &reference)).collect();
        // The far copy: every kind but the slivers, mixed, the same number in all.
        let root = bake(mesh, &BuildParams::auto())?.bounds.root_size as f64;
        let far_mesh = moved(mesh, FAR * root);
        let far_rays: Vec<Ray> = kinds_of_far(&far_mesh, n)?;
        let far_reference = Reference::in_input_order(far_mesh.triangles.clone());
        let far = answered(("far", far_rays), &far_reference);
        Ok(HardSet { kinds, reference, far, far_reference, far_mesh })
    }

    /// Errors of `traced` (and of `far`, the same structure on the far copy) kind by
    /// kind, nearest hits.
    pub(super) fn errors(&self, traced: &dyn Traced, far: Option<&dyn Traced>) -> Vec<(&'static str, Errors)> {
        let mut out: Vec<(&'static str, Errors)> = self
            .kinds
            .iter()
            .map(|k| (k.name, errors_of(&self.reference, &k.rays, &k.wants, &traced.answers(&k.rays, false))))
            .collect();
        if let Some(far) = far {
            let k = &self.far;
            out.push((k.name, errors_of(&self.far_reference, &k.rays, &k.wants, &far.answers(&k.rays, false))));
        }
        out
    }

    /// Rays of each kind (the far kind's included).
    pub(super) fn rays_per_kind(&self) -> usize {
        self.far.rays.len()
    }
}

/// `mesh` with `offset` added to every coordinate (in `f64`, rounded once).
fn moved(mesh: &Mesh, offset: f64) -> Mesh {
    let tris = mesh.triangles.iter().map(|t| t.map(|v| v.map(|c| (c as f64 + offset) as f32))).collect();
    Mesh::from_triangles(tris)
}

/// The far copy's rays: `n` in all, every kind but the slivers in turn.
fn kinds_of_far(far: &Mesh, n: usize) -> anyhow::Result<Vec<Ray>> {
    let all = kinds(far, n.div_ceil(6))?;
    let mixed: Vec<Ray> = all.into_iter().filter(|(name, _)| *name != "slivers").flat_map(|(_, r)| r).collect();
    Ok(mixed.into_iter().take(n).collect())
}

/// The seven near kinds' rays at `mesh`.
fn kinds(mesh: &Mesh, n: usize) -> anyhow::Result<Vec<(&'static str, Vec<Ray>)>> {
    let scene = bake(mesh, &BuildParams::auto())?;
    let view = scene.view();
    let grid = GridPlanes::of(&view);
    let (lo, hi) = (Vec3::from(view.bounds.mesh_lo), Vec3::from(view.bounds.mesh_hi));
    let (c, e) = ((lo + hi) * 0.5, (hi - lo).max(Vec3::splat((hi - lo).max_element() * 1e-3)));
    let tris = &mesh.triangles;
    let vertex = |r: &mut SplitMix| tris[(r.next_u64() % tris.len() as u64) as usize][(r.next_u64() % 3) as usize];
    let around = |r: &mut SplitMix| (c + (Vec3::new(r.unit(), r.unit(), r.unit()) - 0.5) * e * 1.5).to_array();
    let ray = |o: Vec3, d: Vec3| Ray::new(o, d);
    let of = |hard: Vec<octrace_bake::hard_rays::HardRay>, keep: &dyn Fn(HardKind) -> bool| -> Vec<Ray> {
        hard.iter().filter(|h| keep(h.kind)).map(|h| ray(Vec3::from(h.origin), Vec3::from(h.dir))).collect()
    };
    // The grid kinds: cycled by the generator, 4 kinds in turn; enough for n of each.
    let hard = grid_rays(&grid, 4 * n, 1, around, Some(vertex), |_| true);
    let in_plane = of(hard.clone(), &|k| k == HardKind::InPlane);
    let along_edge = of(hard.clone(), &|k| k == HardKind::AlongEdge);
    let corners = of(hard, &|k| matches!(k, HardKind::FromCorner | HardKind::ThroughCorner));
    let mut rng = SplitMix(2);
    let point_on = |t: &[[f32; 3]; 3], r: &mut SplitMix| {
        let (mut u, mut v) = (r.unit(), r.unit());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        Vec3::from(t[0]) * (1.0 - u - v) + Vec3::from(t[1]) * u + Vec3::from(t[2]) * v
    };
    let triangle = |r: &mut SplitMix| &tris[(r.next_u64() % tris.len() as u64) as usize];
    // Grazing: across a triangle at angles from 1e-2 to 1e-6 radians to its plane.
    let grazing = (0..n)
        .map(|i| {
            let t = triangle(&mut rng);
            let (a, b, cc) = (Vec3::from(t[0]), Vec3::from(t[1]), Vec3::from(t[2]));
            let normal = (b - a).cross(cc - a).normalize_or_zero();
            let along = (b - a).normalize_or(Vec3::X);
            let p = point_on(t, &mut rng);
            let tilt = 10f32.powf(-2.0 - 4.0 * (i as f32 / n.max(1) as f32));
            let d = along + normal * tilt * if i % 2 == 0 { 1.0 } else { -1.0 };
            ray(p - d * e.max_element(), d)
        })
        .collect();
    let vertex_aimed = (0..n)
        .map(|_| {
            let o = Vec3::from(around(&mut rng));
            ray(o, Vec3::from(vertex(&mut rng)) - o)
        })
        .collect();
    // Slivers: the thinnest 1 % of the triangles (longest edge squared over area).
    let mut thin: Vec<(f32, usize)> = tris
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let (a, b, cc) = (Vec3::from(t[0]), Vec3::from(t[1]), Vec3::from(t[2]));
            let longest = (b - a).length_squared().max((cc - b).length_squared()).max((a - cc).length_squared());
            (longest / (b - a).cross(cc - a).length().max(f32::MIN_POSITIVE), i)
        })
        .collect();
    thin.sort_by(|x, y| y.0.total_cmp(&x.0));
    thin.truncate((tris.len() / 100).max(1));
    let slivers = (0..n)
        .map(|_| {
            let t = &tris[thin[(rng.next_u64() % thin.len() as u64) as usize].1];
            let o = Vec3::from(around(&mut rng));
            ray(o, point_on(t, &mut rng) - o)
        })
        .collect();
    let on_surface = (0..n)
        .map(|_| {
            let p = point_on(triangle(&mut rng), &mut rng);
            ray(p, Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5))
        })
        .collect();
    let take = |mut v: Vec<Ray>| {
        v.truncate(n);
        v
    };
    Ok(vec![
        ("in-plane", take(in_plane)),
        ("along-edge", take(along_edge)),
        ("corners", take(corners)),
        ("grazing", grazing),
        ("vertex-aimed", vertex_aimed),
        ("slivers", slivers),
        ("on-surface", on_surface),
    ])
}
