//! Procedural meshes for tests, benchmarks and demos: spheres, boxes, tori, grids,
//! fans and random soups, all closed where the name says so.

use crate::mesh::Mesh;

mod solids;

pub use solids::{closed_solids, ClosedSolid};

fn mesh(triangles: Vec<[[f32; 3]; 3]>) -> Mesh {
    Mesh::from_triangles(triangles)
}

/// A closed UV sphere with `stacks x slices` quads (poles as fans), its triangles wound
/// counter-clockwise seen from outside (normals out).
pub fn sphere(center: [f32; 3], radius: f32, stacks: u32, slices: u32) -> Mesh {
    let (stacks, slices) = (stacks.max(2), slices.max(3));
    let point = |i: u32, j: u32| {
        // The poles are one exact point each (sin(pi) is not 0 in floating point, and a
        // pole per slice would leave slits around the axis: the mesh would not be closed).
        if i == 0 || i == stacks {
            let y = if i == 0 { radius } else { -radius };
            return [center[0], center[1] + y, center[2]];
        }
        let theta = std::f64::consts::PI * i as f64 / stacks as f64;
        let phi = std::f64::consts::TAU * (j % slices) as f64 / slices as f64;
        let r = radius as f64;
        [
            center[0] + (r * theta.sin() * phi.cos()) as f32,
            center[1] + (r * theta.cos()) as f32,
            center[2] + (r * theta.sin() * phi.sin()) as f32,
        ]
    };
    let mut tris = Vec::new();
    for i in 0..stacks {
        for j in 0..slices {
            let (a, b, c, d) = (point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1));
            // Counter-clockwise seen from outside: the normals point out.
            if i > 0 {
                tris.push([a, d, b]);
            }
            if i + 1 < stacks {
                tris.push([d, c, b]);
            }
        }
    }
    mesh(tris)
}

/// A closed, bumpy, bunny-like blob around the origin: a sphere of radius 1 displaced
/// radially by smooth waves (radius between about 0.65 and 1.35).
pub fn blob(stacks: u32, slices: u32) -> Mesh {
    let mut m = sphere([0.0; 3], 1.0, stacks, slices);
    for v in m.triangles.iter_mut().flatten() {
        let [x, y, z] = *v;
        let bump = 1.0 + 0.25 * (3.0 * x).sin() * (2.0 * y).cos() + 0.1 * (7.0 * z).sin();
        *v = [x * bump, y * bump, z * bump];
    }
    m
}

/// A closed torus around the y axis, its triangles wound counter-clockwise seen from
/// outside (normals out).
pub fn torus(center: [f32; 3], major: f32, minor: f32, rings: u32, sides: u32) -> Mesh {
    let point = |i: u32, j: u32| {
        let u = std::f64::consts::TAU * (i % rings) as f64 / rings as f64;
        let v = std::f64::consts::TAU * (j % sides) as f64 / sides as f64;
        let r = major as f64 + minor as f64 * v.cos();
        [
            center[0] + (r * u.cos()) as f32,
            center[1] + (minor as f64 * v.sin()) as f32,
            center[2] + (r * u.sin()) as f32,
        ]
    };
    let mut tris = Vec::new();
    for i in 0..rings {
        for j in 0..sides {
            let (a, b, c, d) = (point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1));
            // Counter-clockwise seen from outside: the normals point out.
            tris.push([a, c, b]);
            tris.push([a, d, c]);
        }
    }
    mesh(tris)
}

/// A 2 x 2 PNG, grey levels 255, 96 / 160, 255 (78 bytes).
const GREY_PNG: [u8; 78] = [
    0x89, 0x50, 0x4e, 0x47, 0xd, 0xa, 0x1a, 0xa, 0x0, 0x0, 0x0, 0xd, 0x49, 0x48, 0x44, 0x52, 0x0, 0x0, 0x0, 0x2, 0x0,
    0x0, 0x0, 0x2, 0x8, 0x2, 0x0, 0x0, 0x0, 0xfd, 0xd4, 0x9a, 0x73, 0x0, 0x0, 0x0, 0x15, 0x49, 0x44, 0x41, 0x54, 0x78,
    0xda, 0x63, 0xf8, 0xff, 0xff, 0x7f, 0x42, 0x42, 0x2, 0xc3, 0x82, 0x5, 0xb, 0x80, 0x2c, 0x0, 0x3d, 0x64, 0x8, 0xfb,
    0x25, 0x41, 0x3b, 0xf9, 0x0, 0x0, 0x0, 0x0, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82,
];

/// A unit torus (minor radius 0.3) with every kind of shading data: one material, its
/// base colour from a 2 x 2 texture with a transparent texel (alpha mask), its
/// occlusion and normals from a 2 x 2 PNG kept encoded, face normals, tangents, texture
/// coordinates and vertex colours. Baked, every section of the file holds bytes: for the format's
/// tests and the trusted-path fuzz target.
pub fn shaded_torus(rings: u32, sides: u32) -> Mesh {
    use octrace_format::{AlphaMode, Encoded, ImageKind, Material, Texture};
    let material = Material {
        base_color_texture: Some(0),
        occlusion_texture: Some(1),
        normal_texture: Some(1),
        alpha_mode: AlphaMode::Mask,
        ..Default::default()
    };
    let texture = Texture {
        name: "2 x 2".into(),
        width: 2,
        height: 2,
        first: 0,
        wrap: Default::default(),
        filter: Default::default(),
        min_alpha: 0.0,
        srgb: false,
        encoded: None,
    };
    // Linear RGBA, 8 bits a channel (`r | g << 8 | b << 16 | a << 24`): the first
    // texel's alpha is 0.
    let mut texels = vec![0x0080_ff00, 0xff00_00ff, 0xff80_8080, 0x8001_0001];
    let grey = octrace_format::image::decode(&GREY_PNG, 4).expect("a sound PNG");
    let grey: Vec<u32> = grey.pixels.into_iter().map(u32::from_le_bytes).collect();
    let occlusion = Texture {
        name: "2 x 2 PNG".into(),
        first: texels.len() as u32,
        min_alpha: 1.0,
        encoded: Some(Encoded {
            kind: ImageKind::Png,
            offset: 0,
            bytes: GREY_PNG.len() as u64,
            texels_hash: octrace_format::texels_hash(&grey),
        }),
        ..texture.clone()
    };
    texels.extend_from_slice(&grey);
    let mut out = Mesh {
        materials: vec![material],
        textures: vec![texture, occlusion],
        texels,
        images: GREY_PNG.to_vec(),
        ..Mesh::default()
    };
    for t in torus([0.0; 3], 1.0, 0.3, rings, sides).triangles {
        let normals = Some([crate::mesh::face_normal(&t); 3]);
        let colors = Some([[65535, 0, 0, 65535], [0, 65535, 0, 30000], [0, 0, 65535, 65535]]);
        out.push_colored(t, normals, Some([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), colors);
        out.material_ids.push(0);
        // Along the first edge (where u grows), every other triangle's sign reversed.
        let e = glam::Vec3::from(t[1]) - glam::Vec3::from(t[0]);
        let w = if out.triangles.len().is_multiple_of(2) { -1.0 } else { 1.0 };
        out.push_tangents(vec![[[e.x, e.y, e.z, w]; 3]], 1);
    }
    out
}

/// A closed axis-aligned box, each face split into `n x n` quads, every triangle
/// wound counter-clockwise seen from outside (its normal points out).
pub fn cube(lo: [f32; 3], hi: [f32; 3], n: u32) -> Mesh {
    let n = n.max(1);
    let mut tris = Vec::new();
    for axis in 0..3 {
        let (u, v) = octrace_format::layout::other_axes(axis);
        // `u x v` is +x, -y, +z: turned over where that is not the face's outside.
        let turn = |side: f32| (side == lo[axis]) != (axis == 1);
        for side in [lo[axis], hi[axis]] {
            for i in 0..n {
                for j in 0..n {
                    let at = |di: u32, dj: u32| {
                        let mut p = [0.0f32; 3];
                        p[axis] = side;
                        p[u] = lo[u] + (hi[u] - lo[u]) * (i + di) as f32 / n as f32;
                        p[v] = lo[v] + (hi[v] - lo[v]) * (j + dj) as f32 / n as f32;
                        p
                    };
                    let (a, b, c, d) = (at(0, 0), at(1, 0), at(1, 1), at(0, 1));
                    if turn(side) {
                        tris.push([a, c, b]);
                        tris.push([a, d, c]);
                    } else {
                        tris.push([a, b, c]);
                        tris.push([a, c, d]);
                    }
                }
            }
        }
    }
    mesh(tris)
}

/// A flat `n x n` grid of quads in the plane `z = 0`, over `[0, size]^2`.
pub fn grid(n: u32, size: f32) -> Mesh {
    let n = n.max(1);
    let p = |i: u32, j: u32| [size * i as f32 / n as f32, size * j as f32 / n as f32, 0.0];
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    mesh(tris)
}

/// A fan of `n` thin triangles around the origin in the plane `y = 0`.
pub fn fan(n: u32, radius: f32) -> Mesh {
    cone(n, [0.0; 3], radius, 0.0)
}

/// An open cone of `n` thin triangles sharing its apex, `height` above `centre` (a
/// flat fan when 0): the rim of radius `radius` around `centre` in the plane
/// `y = centre.y`, each triangle `apex, rim(k), rim(k + 1)`.
pub fn cone(n: u32, centre: [f32; 3], radius: f32, height: f32) -> Mesh {
    let n = n.max(1);
    let rim = |k: u32| {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        let (x, z) = ((radius as f64 * a.cos()) as f32, (radius as f64 * a.sin()) as f32);
        [centre[0] + x, centre[1], centre[2] + z]
    };
    let apex = [centre[0], centre[1] + height, centre[2]];
    mesh((0..n).map(|k| [apex, rim(k), rim(k + 1)]).collect())
}

/// `n` random triangles in `[0, scale]^3`, each with edges up to `size`, from `seed`.
pub fn soup(seed: u64, n: usize, scale: f32, size: f32) -> Mesh {
    let mut rng = SplitMix(seed);
    let tris = (0..n)
        .map(|_| {
            let a = [0; 3].map(|_| rng.unit() * scale);
            let mut t = [a; 3];
            for v in &mut t[1..] {
                for (c, base) in v.iter_mut().zip(a) {
                    *c = base + (rng.unit() - 0.5) * size;
                }
            }
            t
        })
        .collect();
    mesh(tris)
}

/// A tiny deterministic generator (SplitMix64) for procedural meshes.
#[derive(Clone, Debug)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The scene of `octrace demo --scene effects`: every effect the renderer knows, each
/// on its own object, lit by a point light (hard shadows) and an area light (soft
/// shadows), seen through a camera the scene carries.
///
/// A diffuse floor; a mirror standing behind the objects; a glass sphere
/// (transmission 1, index 1.5); a clay torus; a green blended pane (alpha 0.35); a
/// lamp: an emissive square under the ceiling. The spheres carry smooth shading
/// normals.
///
/// # Example
/// ```
/// let scene = octrace_bake::procedural::effects_scene();
/// let baked = octrace_bake::bake(&scene, &Default::default())?;
/// assert_eq!(baked.shading.effects.len(), 5); // every effect
/// # Ok::<(), octrace_bake::Error>(())
/// ```
pub fn effects_scene() -> Mesh {
    use octrace_format::{AlphaMode, Camera, Light, LightKind, Material};
    let diffuse = |name: &str, rgb: [f32; 3], roughness: f32| Material {
        name: name.into(),
        base_color: [rgb[0], rgb[1], rgb[2], 1.0],
        metallic: 0.0,
        roughness,
        ..Material::default()
    };
    let mut out = Mesh {
        materials: vec![
            diffuse("floor", [0.75, 0.72, 0.66], 1.0),
            Material { roughness: 0.0, base_color: [0.92, 0.93, 0.95, 1.0], ..diffuse("mirror", [0.0; 3], 0.0) },
            Material { transmission: 1.0, ior: 1.5, ..diffuse("glass", [0.97, 0.99, 1.0], 0.0) },
            diffuse("clay", [0.8, 0.25, 0.15], 0.45),
            Material { alpha_mode: AlphaMode::Blend, ..diffuse("tinted pane", [0.2, 0.8, 0.3], 1.0) },
            Material { emissive: [14.0, 13.0, 11.5], ..diffuse("lamp", [0.0; 3], 1.0) },
        ],
        lights: vec![Light {
            name: "key".into(),
            kind: LightKind::Point,
            color: [1.0, 0.95, 0.85],
            intensity: 24.0,
            position: [3.0, 4.5, 3.5],
            direction: [0.0, -1.0, 0.0],
            range: f32::INFINITY,
            inner_cone: 0.0,
            outer_cone: 0.0,
        }],
        cameras: vec![Camera {
            name: "front".into(),
            position: [0.2, 2.1, 6.4],
            forward: normalized([-0.2, -1.5, -6.4]),
            up: [0.0, 1.0, 0.0],
            yfov: 0.7,
            aspect: Some(4.0 / 3.0),
            orthographic: None,
            gltf_camera: None,
        }],
        ..Mesh::default()
    };
    out.materials[1].metallic = 1.0;
    out.materials[4].base_color[3] = 0.35;
    // The cameras' up must be orthogonal to its forward.
    let f = out.cameras[0].forward;
    let up = [-f[0] * f[1], 1.0 - f[1] * f[1], -f[2] * f[1]];
    out.cameras[0].up = normalized(up);
    let quad = |a: [f32; 3], b: [f32; 3], c: [f32; 3], d: [f32; 3]| vec![[a, b, c], [a, c, d]];
    // Counter-clockwise seen from the side their normal points to.
    add(&mut out, quad([-5.0, 0.0, -3.0], [-5.0, 0.0, 5.0], [5.0, 0.0, 5.0], [5.0, 0.0, -3.0]), 0, None);
    add(&mut out, quad([-2.6, 0.0, -1.8], [1.4, 0.0, -2.4], [1.4, 2.6, -2.4], [-2.6, 2.6, -1.8]), 1, None);
    let glass = sphere([-0.9, 0.7, 0.4], 0.7, 24, 48);
    add(&mut out, glass.triangles, 2, Some(([-0.9, 0.7, 0.4], 0.7)));
    let clay = torus([1.0, 0.3, -0.3], 0.55, 0.25, 48, 24);
    add(&mut out, clay.triangles, 3, None);
    add(&mut out, quad([1.2, 0.0, 1.6], [2.4, 0.0, 0.9], [2.4, 1.5, 0.9], [1.2, 1.5, 1.6]), 4, None);
    add(&mut out, quad([-0.5, 3.6, -0.5], [0.5, 3.6, -0.5], [0.5, 3.6, 0.5], [-0.5, 3.6, 0.5]), 5, None);
    out
}

/// Appends `triangles` with material `material`, and radial shading normals when
/// they are the surface of sphere `(centre, radius)`.
fn add(mesh: &mut Mesh, triangles: Vec<[[f32; 3]; 3]>, material: u32, sphere: Option<([f32; 3], f32)>) {
    for t in triangles {
        let normals = sphere.map(|(c, r)| t.map(|v| [0, 1, 2].map(|a| (v[a] - c[a]) / r)));
        mesh.push(t, normals, None);
        mesh.material_ids.push(material);
    }
}

fn normalized(v: [f32; 3]) -> [f32; 3] {
    let len = v.iter().map(|c| c * c).sum::<f32>().sqrt();
    v.map(|c| c / len)
}
