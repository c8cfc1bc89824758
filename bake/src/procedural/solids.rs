//! Closed solids for leak tests: meshes with no hole, samplers of points well inside
//! them, and the same solids moved far from the origin.

use super::{blob, cube, sphere, torus, SplitMix};
use crate::hard_rays::{grid_rays, GridPlanes, HardRay};
use crate::mesh::Mesh;

/// A closed mesh, a sampler of points well inside it and a test for such points, for
/// leak tests: every ray from such a point must hit the mesh.
///
/// A solid may be moved away from the origin ([`ClosedSolid::moved`]): its vertices,
/// its samples and its test follow, rounded to `f32` where the mesh is.
///
/// # Example
/// ```
/// use octrace_bake::procedural::closed_solids;
/// let sphere = closed_solids().into_iter().find(|s| s.name == "sphere").unwrap();
/// let far = sphere.moved(1e7, 1e3);
/// let p = far.inside(&mut octrace_bake::procedural::SplitMix(1));
/// assert!(far.contains(p) && p[0] > 9.99e6);
/// ```
pub struct ClosedSolid {
    /// A short name.
    pub name: &'static str,
    /// The closed mesh.
    pub mesh: Mesh,
    /// A random point well inside, before the solid was moved.
    sample: fn(&mut SplitMix) -> [f32; 3],
    /// Whether a point (before the solid was moved) lies well inside: at least a
    /// small clearance from the surface, so that snapping a sample onto a nearby
    /// plane is checked, not assumed.
    holds: fn([f64; 3]) -> bool,
    /// Added to every coordinate after scaling.
    offset: f64,
    /// Scale about the origin.
    scale: f64,
}

/// The closed solids of the leak tests and `octrace soak`: a sphere, a torus, a box, a
/// bumpy blob and a room (a box with 32 x 32 quads a face, as a room around a camera),
/// each with a few thousand triangles.
pub fn closed_solids() -> Vec<ClosedSolid> {
    let solid = |name, mesh, sample, holds| ClosedSolid { name, mesh, sample, holds, offset: 0.0, scale: 1.0 };
    vec![
        solid(
            "sphere",
            sphere([0.1, -0.2, 0.3], 1.0, 48, 64),
            |r| [0.1 + (r.unit() - 0.5), -0.2 + (r.unit() - 0.5), 0.3 + (r.unit() - 0.5)],
            // The tessellation's inscribed radius is above 0.997.
            |p| length([p[0] - 0.1, p[1] + 0.2, p[2] - 0.3]) < 0.95,
        ),
        solid(
            "torus",
            torus([0.0; 3], 1.0, 0.3, 64, 32),
            |r| {
                let a = std::f32::consts::TAU * r.unit();
                let k = 1.0 + 0.2 * (r.unit() - 0.5);
                [a.cos() * k, 0.2 * (r.unit() - 0.5), a.sin() * k]
            },
            // The tube's tessellation stays within 0.004 of radius 0.3.
            |p| {
                let ring = (p[0] * p[0] + p[2] * p[2]).sqrt() - 1.0;
                ring * ring + p[1] * p[1] < 0.27 * 0.27
            },
        ),
        solid(
            "box",
            cube([-1.0, -0.5, -2.0], [1.0, 0.5, 2.0], 8),
            |r| [r.unit() * 1.9 - 0.95, r.unit() * 0.9 - 0.45, r.unit() * 3.9 - 1.95],
            |p| p[0].abs() < 0.99 && p[1].abs() < 0.49 && p[2].abs() < 1.99,
        ),
        solid(
            "blob",
            blob(64, 96),
            |r| [(r.unit() - 0.5) * 0.8, (r.unit() - 0.5) * 0.8, (r.unit() - 0.5) * 0.8],
            // The blob's radius in direction u is bump(u) (see `blob`).
            |p| {
                let r = length(p);
                let u = p.map(|c| c / r.max(1e-30));
                let bump = 1.0 + 0.25 * (3.0 * u[0]).sin() * (2.0 * u[1]).cos() + 0.1 * (7.0 * u[2]).sin();
                r < bump - 0.05
            },
        ),
        solid(
            "room",
            cube([-2.0, -1.0, -3.0], [2.0, 1.5, 3.0], 32),
            |r| [r.unit() * 3.9 - 1.95, r.unit() * 2.4 - 0.95, r.unit() * 5.9 - 2.95],
            |p| p[0].abs() < 1.99 && p[1] > -0.99 && p[1] < 1.49 && p[2].abs() < 2.99,
        ),
    ]
}

fn length(p: [f64; 3]) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

impl ClosedSolid {
    /// The same solid scaled by `scale` about the origin, then moved by `offset` along
    /// every axis (vertices computed in `f64`, rounded to `f32` once: shared vertices
    /// stay shared, so the mesh stays closed). Far from the origin the `f32` grid is
    /// coarse (1.0 at 1e7): scale the solid so that it keeps its shape there.
    pub fn moved(mut self, offset: f64, scale: f64) -> ClosedSolid {
        let (offset, scale) = (self.offset * scale + offset, self.scale * scale);
        for v in self.mesh.triangles.iter_mut().flatten() {
            *v = v.map(|c| ((c as f64 - self.offset) / self.scale * scale + offset) as f32);
        }
        self.offset = offset;
        self.scale = scale;
        self
    }

    /// The name and, for a moved solid, where it was moved: `sphere`, `sphere@1e7`.
    pub fn label(&self) -> String {
        match self.offset {
            0.0 => self.name.to_string(),
            o => format!("{}@{o:e}", self.name),
        }
    }

    /// A random point well inside.
    pub fn inside(&self, rng: &mut SplitMix) -> [f32; 3] {
        (self.sample)(rng).map(|c| (c as f64 * self.scale + self.offset) as f32)
    }

    /// Whether `p` lies well inside (a small clearance from the surface).
    pub fn contains(&self, p: [f32; 3]) -> bool {
        (self.holds)(p.map(|c| (c as f64 - self.offset) / self.scale))
    }

    /// Rays that must all hit the solid, as `(origin, direction)`: `random` rays from
    /// inside points in uniform directions, then, for every triangle, rays from an
    /// inside point aimed exactly at its three vertices and three edge midpoints.
    pub fn leak_rays(&self, random: usize, seed: u64) -> Vec<([f32; 3], [f32; 3])> {
        let mut rng = SplitMix(seed);
        let mut rays = Vec::with_capacity(random + 6 * self.mesh.triangles.len());
        for _ in 0..random {
            let z = 1.0 - 2.0 * rng.unit();
            let phi = std::f32::consts::TAU * rng.unit();
            let r = (1.0 - z * z).max(0.0).sqrt();
            rays.push((self.inside(&mut rng), [r * phi.cos(), r * phi.sin(), z]));
        }
        for [a, b, c] in &self.mesh.triangles {
            let o = self.inside(&mut rng);
            let mid = |p: &[f32; 3], q: &[f32; 3]| [(p[0] + q[0]) * 0.5, (p[1] + q[1]) * 0.5, (p[2] + q[2]) * 0.5];
            for target in [*a, *b, *c, mid(a, b), mid(b, c), mid(c, a)] {
                rays.push((o, [target[0] - o[0], target[1] - o[1], target[2] - o[2]]));
            }
        }
        rays
    }

    /// `n` rays on the planes of the octree `grid` (the solid's own bake), from points
    /// well inside: in cell planes with `+0.0` and `-0.0` components, along cell
    /// edges, from and through cell corners, on every axis, level and sign quadrant
    /// ([`grid_rays`]). Every one must hit.
    pub fn grid_rays(&self, grid: &GridPlanes, n: usize, seed: u64) -> Vec<HardRay> {
        grid_rays(grid, n, seed, |rng| self.inside(rng), None::<fn(&mut SplitMix) -> [f32; 3]>, |p| self.contains(p))
    }
}
