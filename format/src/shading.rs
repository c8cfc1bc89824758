//! What a renderer needs beyond geometry: materials, lights, cameras, and the set of
//! effects the scene calls for, decided at bake.
//!
//! The per-triangle parts (material ids, shading normals, texture coordinates) are
//! arrays of [`crate::BakedScene`], in the triangle array's order; the rest is here,
//! small, in the archive's root section.

use rkyv::{Archive, Deserialize, Serialize};

use crate::texture::{Texture, MAX_TEXTURE_SIDE, TEXEL_WORDS};

/// How a material's alpha is used (glTF `alphaMode`).
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[rkyv(derive(Debug))]
#[repr(u8)]
pub enum AlphaMode {
    /// Alpha is ignored: the surface is opaque.
    #[default]
    Opaque,
    /// The surface exists where alpha is at least the cutoff, and not elsewhere.
    Mask,
    /// The surface covers a fraction alpha of what lies behind it.
    Blend,
}

/// A surface material, from glTF's metallic-roughness model or from an MTL file.
///
/// Colours are linear RGB. glTF and MTL values land in the same fields; what a field
/// means for each source is written on it.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Material {
    /// The material's name in its file (`"default"` for the one a loader supplies).
    pub name: String,
    /// Base colour and alpha: glTF `baseColorFactor`; MTL `Kd` with alpha `d` (or
    /// `1 - Tr`).
    pub base_color: [f32; 4],
    /// glTF `metallicFactor`; 0 for MTL.
    pub metallic: f32,
    /// glTF `roughnessFactor`; for MTL, from `Ns` (`sqrt(2 / (Ns + 2))`).
    pub roughness: f32,
    /// Emitted radiance: glTF `emissiveFactor` times `KHR_materials_emissive_strength`;
    /// MTL `Ke`; times [`Material::emissive_texture`] where there is one. Triangles
    /// of an emissive material are area lights (with a texture, only those whose
    /// texels are not all black: [`crate::LitTexels`]).
    pub emissive: [f32; 3],
    /// glTF `alphaMode`; MTL: `Blend` when `d < 1` without an index of refraction.
    pub alpha_mode: AlphaMode,
    /// glTF `alphaCutoff` (0.5 by default), used by [`AlphaMode::Mask`].
    pub alpha_cutoff: f32,
    /// Fraction of light transmitted by refraction: glTF
    /// `KHR_materials_transmission`; MTL `1 - d` when `Ni` is given.
    pub transmission: f32,
    /// Index of refraction: glTF `KHR_materials_ior` (1.5 by default); MTL `Ni`.
    pub ior: f32,
    /// Mirror reflectance of an MTL material with `illum` 3 to 7: its `Ks`; 0 otherwise
    /// (glTF's mirror term follows from metallic and roughness, see [`Material::mirror`]).
    pub specular: [f32; 3],
    /// The MTL `illum` model, when the material came from an MTL file that gave one.
    pub illum: Option<u32>,
    /// glTF `KHR_materials_unlit`: the surface shows its base colour as it is, lit by
    /// nothing and casting no shadow rays of its own.
    pub unlit: bool,
    /// The texture (an index into [`Shading::textures`]) whose texels multiply
    /// `base_color` (glTF `baseColorTexture`), sampled at the triangle's texture
    /// coordinates.
    pub base_color_texture: Option<u32>,
    /// The texture (an index into [`Shading::textures`]) whose colour multiplies
    /// `emissive` (glTF `emissiveTexture`, sRGB like the base colour), sampled at the
    /// same texture coordinates as the base colour texture.
    pub emissive_texture: Option<u32>,
    /// The texture whose blue channel multiplies `metallic` and green channel
    /// multiplies `roughness` (glTF `metallicRoughnessTexture`, linear), sampled at the
    /// same coordinates.
    pub metallic_roughness_texture: Option<u32>,
    /// The texture whose red channel darkens the light that reaches the surface from
    /// all around (glTF `occlusionTexture`, linear): the renderer's ambient term, times
    /// `1 + occlusion_strength * (red - 1)`.
    pub occlusion_texture: Option<u32>,
    /// glTF `occlusionTexture.strength` (1 by default), in `[0, 1]`.
    pub occlusion_strength: f32,
    /// The texture of tangent-space normals that perturb the shading normal (glTF
    /// `normalTexture`, linear): `(2 r - 1) scale, (2 g - 1) scale, 2 b - 1` in the frame
    /// of the triangle's tangent (the direction of increasing `u`, made orthogonal to
    /// the shading normal), the normal crossed with it, and the normal.
    pub normal_texture: Option<u32>,
    /// glTF `normalTexture.scale` (1 by default).
    pub normal_scale: f32,
    /// The texture-coordinate channel each texture slot reads, in the order of
    /// [`Material::TEXTURE_SLOTS`]: a channel is a glTF `TEXCOORD_n` set through one
    /// `KHR_texture_transform` (the `uvs` section holds a scene's channels one after
    /// the other); 0 for every slot that reads what the first does.
    pub uv_channels: [u8; 5],
    /// Whether the surface is seen from behind (glTF `doubleSided`; MTL and materials
    /// made in code: true). A single-sided surface's back, where a view meets the
    /// triangle against its winding (its corners clockwise as seen), is not seen by
    /// camera rays (nor the rays that continue them through cut-outs), and a surface
    /// whose back a light sees casts no shadow from it: the renderer passes through, as
    /// glTF's back-face culling asks. Reflection and refraction rays see both sides.
    pub double_sided: bool,
}

impl Default for Material {
    /// glTF's default material: white, fully metallic, fully rough, opaque; but seen
    /// from both sides (glTF's `doubleSided` is false by default: the glTF loader says
    /// so for each material, its default one included).
    fn default() -> Self {
        Material {
            name: "default".into(),
            base_color: [1.0; 4],
            metallic: 1.0,
            roughness: 1.0,
            emissive: [0.0; 3],
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            transmission: 0.0,
            ior: 1.5,
            specular: [0.0; 3],
            illum: None,
            unlit: false,
            base_color_texture: None,
            emissive_texture: None,
            metallic_roughness_texture: None,
            occlusion_texture: None,
            occlusion_strength: 1.0,
            normal_texture: None,
            normal_scale: 1.0,
            uv_channels: [0; 5],
            double_sided: true,
        }
    }
}

/// Reflectance at normal incidence of a dielectric of index 1.5 (glTF's `F0` of 0.04;
/// [`Material::dielectric_f0`] computes it from the material's index).
pub const DIELECTRIC_F0: f32 = 0.04;

/// A weight below this adds less than half a step of 8-bit colour to any pixel: an
/// effect whose weights all lie below it is not worth a ray.
pub const VISIBLE_WEIGHT: f32 = 1.0 / 512.0;

impl Material {
    /// Mirror reflectance per channel: the weight of a reflection ray.
    ///
    /// glTF: the metallic-roughness `F0` (the dielectric's [`Material::dielectric_f0`]
    /// for the share that neither is metal nor transmits, the base colour for metals,
    /// mixed by `metallic`), scaled by `(1 - roughness)^2` so that a rough surface has
    /// no mirror image. The transmitted share's reflection is the Fresnel reflection
    /// of the refraction effect, not counted here. Unlit materials reflect nothing.
    /// MTL: `Ks` when `illum` is 3 to 7, else nothing.
    pub fn mirror(&self) -> [f32; 3] {
        if let Some(illum) = self.illum {
            return if (3..=7).contains(&illum) { self.specular.map(|k| k.clamp(0.0, 1.0)) } else { [0.0; 3] };
        }
        if self.unlit {
            return [0.0; 3];
        }
        let m = self.metallic.clamp(0.0, 1.0);
        let (dielectric, gloss) = (self.dielectric_mirror(), self.gloss());
        [0, 1, 2].map(|c| (dielectric + m * self.base_color[c].clamp(0.0, 1.0)) * gloss)
    }

    /// `(1 - roughness)^2`: how much of a mirror image (and of a sharp highlight) the
    /// surface keeps.
    pub fn gloss(&self) -> f32 {
        (1.0 - self.roughness.clamp(0.0, 1.0)).powi(2)
    }

    /// [`Material::mirror`]'s dielectric part before gloss: the share that is neither
    /// metal nor transmitted, times [`Material::dielectric_f0`].
    pub fn dielectric_mirror(&self) -> f32 {
        let m = self.metallic.clamp(0.0, 1.0);
        (1.0 - m) * (1.0 - self.transmission.clamp(0.0, 1.0)) * self.dielectric_f0()
    }

    /// Reflectance at normal incidence of the material as a dielectric:
    /// `((ior - 1) / (ior + 1))^2`, [`DIELECTRIC_F0`] for glTF's default index of 1.5,
    /// zero for an index of 1 (no interface, no reflection).
    pub fn dielectric_f0(&self) -> f32 {
        if self.ior == 1.5 {
            return DIELECTRIC_F0; // the f32 nearest 0.04, which the formula misses by an ulp
        }
        let r = (self.ior - 1.0) / (self.ior + 1.0);
        r * r
    }

    /// The fraction of the surface that exists (alpha coverage): 1 for opaque
    /// surfaces, 0 or 1 for masks (alpha against the cutoff), alpha for blending.
    pub fn coverage(&self) -> f32 {
        self.coverage_at(self.base_color[3])
    }

    /// [`Material::coverage`] where the surface's alpha is `alpha` (the factor times
    /// what a texture or a vertex colour gives there).
    pub fn coverage_at(&self, alpha: f32) -> f32 {
        let alpha = alpha.clamp(0.0, 1.0);
        match self.alpha_mode {
            AlphaMode::Opaque => 1.0,
            AlphaMode::Mask => {
                if alpha >= self.alpha_cutoff {
                    1.0
                } else {
                    0.0
                }
            }
            AlphaMode::Blend => alpha,
        }
    }

    /// The texture slots, in the order of [`Material::uv_channels`].
    pub const TEXTURE_SLOTS: [&'static str; 5] =
        ["base colour", "emissive", "metallic-roughness", "occlusion", "normal"];

    /// The texture-coordinate channel texture slot `slot` reads
    /// ([`Material::TEXTURE_SLOTS`]'s order).
    pub fn uv_channel(&self, slot: usize) -> usize {
        self.uv_channels.get(slot).map_or(0, |&c| c as usize)
    }

    /// The texture of each slot, in the order of [`Material::TEXTURE_SLOTS`].
    pub fn slot_textures(&self) -> [Option<u32>; 5] {
        [
            self.base_color_texture,
            self.emissive_texture,
            self.metallic_roughness_texture,
            self.occlusion_texture,
            self.normal_texture,
        ]
    }

    /// The textures the material reads (base colour, emissive, metallic-roughness,
    /// occlusion, normal), those it has.
    pub fn textures(&self) -> impl Iterator<Item = u32> {
        self.slot_textures().into_iter().flatten()
    }

    /// Whether the material emits light.
    pub fn is_emissive(&self) -> bool {
        self.emissive.iter().any(|&e| e > 0.0)
    }

    /// Every number of the material is finite and in its range.
    fn check(&self) -> std::result::Result<(), String> {
        let all = self.base_color.iter().chain(&self.emissive).chain(&self.specular).chain([
            &self.occlusion_strength,
            &self.metallic,
            &self.roughness,
            &self.alpha_cutoff,
            &self.transmission,
            &self.ior,
        ]);
        if let Some(bad) = all.clone().find(|v| !v.is_finite()) {
            return Err(format!("material '{}' holds {bad}", self.name));
        }
        if !self.normal_scale.is_finite() {
            return Err(format!("material '{}' holds normal scale {}", self.name, self.normal_scale));
        }
        if all.clone().any(|&v| v < 0.0) || self.ior == 0.0 {
            return Err(format!("material '{}' holds a negative value or a zero index of refraction", self.name));
        }
        Ok(())
    }
}

/// The kind of a punctual light (glTF `KHR_lights_punctual`).
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[rkyv(derive(Debug))]
#[repr(u8)]
pub enum LightKind {
    /// Light from a point in every direction; intensity in candela.
    Point,
    /// A point light limited to a cone; intensity in candela.
    Spot,
    /// Parallel light from infinitely far away; intensity in lux.
    Directional,
}

/// A punctual light, in world space.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Light {
    /// The light's name, or `light N`.
    pub name: String,
    /// Point, spot or directional.
    pub kind: LightKind,
    /// Linear RGB colour.
    pub color: [f32; 3],
    /// Candela (point, spot) or lux (directional).
    pub intensity: f32,
    /// Position (unused by directional lights).
    pub position: [f32; 3],
    /// Unit direction the light shines towards (spot, directional).
    pub direction: [f32; 3],
    /// Distance where the light's influence ends; infinite when unlimited.
    pub range: f32,
    /// Spot: angle from the axis where the falloff starts, radians.
    pub inner_cone: f32,
    /// Spot: angle from the axis where the light ends, radians.
    pub outer_cone: f32,
}

/// A perspective camera from the scene file, in world space.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Camera {
    /// The camera's name, or `camera N`.
    pub name: String,
    /// Eye position.
    pub position: [f32; 3],
    /// Unit viewing direction.
    pub forward: [f32; 3],
    /// Unit up vector, not parallel to `forward` (a glTF camera's is orthogonal to
    /// it; the renderer takes the part orthogonal to `forward`).
    pub up: [f32; 3],
    /// Vertical field of view, radians.
    pub yfov: f32,
    /// Width over height, when the file fixes it.
    pub aspect: Option<f32>,
    /// An orthographic camera's half height of view (glTF `ymag`): its rays are
    /// parallel, along `forward`, from a `2 ymag` high rectangle (`yfov` is then
    /// unused); `None` for a perspective camera.
    pub orthographic: Option<f32>,
    /// The glTF camera this places (its index in the file's `cameras`), what `render
    /// --camera` takes; `None` for a camera made in code.
    pub gltf_camera: Option<u32>,
}

impl Camera {
    /// The number users call the camera by (`render --camera N`, `inspect`): its glTF
    /// camera index, or else its `position` in [`Shading::cameras`].
    ///
    /// # Example
    /// ```
    /// let camera = octrace_format::Camera {
    ///     name: "top".into(),
    ///     position: [0.0, 5.0, 0.0],
    ///     forward: [0.0, -1.0, 0.0],
    ///     up: [0.0, 0.0, -1.0],
    ///     yfov: 0.8,
    ///     aspect: None,
    ///     orthographic: None,
    ///     gltf_camera: Some(13),
    /// };
    /// assert_eq!(camera.number(0), 13);
    /// assert_eq!(octrace_format::Camera { gltf_camera: None, ..camera }.number(0), 0);
    /// ```
    pub fn number(&self, position: usize) -> u32 {
        self.gltf_camera.unwrap_or(position as u32)
    }
}

/// A part of the input mesh: a glTF primitive of a node, or an OBJ object or group.
/// Its triangles are consecutive in the input (`first .. first + count`), so a hit's
/// input triangle names its part and its index within it
/// ([`Shading::part_of`]).
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Eq)]
#[rkyv(derive(Debug))]
pub struct MeshPart {
    /// What the file calls it: `node 3 'wheel', mesh 1 'tyre', primitive 0` (glTF), or
    /// `object 'lid'` (OBJ; the object or group name).
    pub name: String,
    /// Index of its first triangle in the input.
    pub first: u32,
    /// Its triangles.
    pub count: u32,
    /// Where it comes from in the file, as numbers (the name says it in words).
    pub source: PartSource,
    /// Whether it is closed and consistently oriented, counted over its triangles that
    /// are not degenerate (the bake fills it in).
    pub edges: crate::topology::EdgeCensus,
}

/// Where a mesh part comes from in its file, as numbers: what Embree's `geomID` or
/// Open3D's `geometry_ids` give an app, for the mesh it loaded itself.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[rkyv(derive(Debug))]
pub enum PartSource {
    /// A glTF mesh primitive placed by a node: the node's, the mesh's and the
    /// primitive's indices in the file (a mesh placed by two nodes is two parts).
    Gltf {
        /// The node's index in the file's `nodes`.
        node: u32,
        /// The mesh's index in the file's `meshes`.
        mesh: u32,
        /// The primitive's index in the mesh's `primitives`.
        primitive: u32,
    },
    /// An OBJ object or group: its index among the file's objects, in file order.
    Obj {
        /// The object's index, from 0.
        object: u32,
    },
    /// A mesh made in code (or a part without a file behind it).
    #[default]
    None,
}

/// An effect a renderer may have to simulate.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[rkyv(derive(Debug))]
#[repr(u8)]
pub enum Effect {
    /// Shadow rays towards lights (any light).
    Shadows,
    /// Several shadow rays towards points of area lights (emissive triangles).
    SoftShadows,
    /// Mirror reflection rays.
    Reflection,
    /// Refraction rays through transmissive materials.
    Refraction,
    /// Surfaces cut out or blended by alpha: rays continue through them.
    Alpha,
}

impl Effect {
    /// Every effect, in a fixed order.
    pub const ALL: [Effect; 5] =
        [Effect::Shadows, Effect::SoftShadows, Effect::Reflection, Effect::Refraction, Effect::Alpha];

    /// The effect's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Effect::Shadows => "shadows",
            Effect::SoftShadows => "soft-shadows",
            Effect::Reflection => "reflection",
            Effect::Refraction => "refraction",
            Effect::Alpha => "alpha",
        }
    }

    /// The effect a name stands for.
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }
}

/// An effect the scene calls for, and why.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct EffectReason {
    /// The effect.
    pub effect: Effect,
    /// What in the scene calls for it, e.g. `material 'chrome', metallic 1.00, roughness 0.05`.
    pub reason: String,
}

/// Materials, lights, cameras and effects of a baked scene.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
#[rkyv(derive(Debug))]
pub struct Shading {
    /// Materials, indexed by the scene's `material_ids`.
    pub materials: Vec<Material>,
    /// Punctual lights.
    pub lights: Vec<Light>,
    /// Cameras.
    pub cameras: Vec<Camera>,
    /// Texture images, indexed by [`Material::base_color_texture`]; their texels are
    /// [`crate::BakedScene::texels`].
    pub textures: Vec<Texture>,
    /// The parts of the input mesh, in input order, each a run of its triangles
    /// (empty for a mesh that was not loaded from a file).
    pub parts: Vec<MeshPart>,
    /// The effects the scene calls for, one entry each, in [`Effect::ALL`] order; empty
    /// when primary rays suffice.
    pub effects: Vec<EffectReason>,
}

impl Shading {
    /// The part input triangle `triangle` belongs to (a hit's [`triangle`]), and its
    /// index within the part.
    ///
    /// [`triangle`]: https://docs.rs/octrace-runtime/latest/octrace_runtime/struct.Hit.html#structfield.triangle
    ///
    /// # Example
    /// ```
    /// use octrace_format::{MeshPart, Shading};
    /// let part = |name: &str, first, count| MeshPart { name: name.into(), first, count, source: Default::default(), edges: Default::default() };
    /// let shading = Shading { parts: vec![part("object 'lid'", 0, 10), part("object 'pot'", 10, 90)], ..Default::default() };
    /// let (pot, i) = shading.part_of(12).unwrap();
    /// assert_eq!((pot.name.as_str(), i), ("object 'pot'", 2));
    /// assert!(shading.part_of(100).is_none());
    /// ```
    pub fn part_of(&self, triangle: u32) -> Option<(&MeshPart, u32)> {
        let index = self.part_index_of(triangle)?;
        let part = &self.parts[index as usize];
        Some((part, triangle - part.first))
    }

    /// The index in [`Shading::parts`] of the part input triangle `triangle` belongs
    /// to (a binary search): a hit's part as a number, as Embree's `geomID`.
    ///
    /// # Example
    /// ```
    /// use octrace_format::{MeshPart, Shading};
    /// let part = |name: &str, first, count| MeshPart { name: name.into(), first, count, source: Default::default(), edges: Default::default() };
    /// let shading = Shading { parts: vec![part("object 'lid'", 0, 10), part("object 'pot'", 10, 90)], ..Default::default() };
    /// assert_eq!(shading.part_index_of(12), Some(1));
    /// assert_eq!(shading.part_index_of(100), None);
    /// ```
    pub fn part_index_of(&self, triangle: u32) -> Option<u32> {
        let index = self.parts.partition_point(|p| p.first <= triangle).checked_sub(1)?;
        let part = self.parts.get(index)?;
        (triangle - part.first < part.count).then_some(index as u32)
    }

    /// Whether the scene calls for `effect`.
    pub fn has(&self, effect: Effect) -> bool {
        self.effects.iter().any(|e| e.effect == effect)
    }

    /// Checks that every number is finite and in range, and that each effect appears
    /// at most once.
    ///
    /// # Errors
    /// [`crate::Error::Corrupt`] naming the first bad value.
    pub fn validate(&self) -> crate::Result<()> {
        let corrupt = crate::Error::corrupt;
        for m in &self.materials {
            m.check().map_err(corrupt)?;
        }
        for l in &self.lights {
            let finite = l.color.iter().chain(&l.position).chain(&l.direction).chain([&l.intensity]);
            if finite.clone().any(|v| !v.is_finite()) || l.range.is_nan() || !l.inner_cone.is_finite() {
                return Err(corrupt(format!("light '{}' holds a value that is not finite", l.name)));
            }
            if !l.outer_cone.is_finite() || l.range <= 0.0 || l.intensity < 0.0 || l.color.iter().any(|&c| c < 0.0) {
                return Err(corrupt(format!("light '{}' holds a value out of range", l.name)));
            }
            if !is_unit(l.direction) {
                return Err(corrupt(format!("light '{}' has a direction that is not a unit vector", l.name)));
            }
        }
        for c in &self.cameras {
            let v = c.position.iter().chain(&c.forward).chain(&c.up).chain([&c.yfov]).chain(c.aspect.as_ref());
            if v.clone().any(|x| !x.is_finite()) || !(c.yfov > 0.0 && c.yfov < std::f32::consts::PI) {
                return Err(corrupt(format!("camera '{}' holds a value that is not finite or out of range", c.name)));
            }
            let cos = (0..3).map(|a| c.forward[a] as f64 * c.up[a] as f64).sum::<f64>();
            if !is_unit(c.forward) || !is_unit(c.up) || cos.abs() > 1.0 - UNIT_TOLERANCE {
                return Err(corrupt(format!(
                    "camera '{}' needs unit forward and up vectors that are not parallel",
                    c.name
                )));
            }
            if c.aspect.is_some_and(|a| a <= 0.0) {
                return Err(corrupt(format!("camera '{}' has a non-positive aspect ratio", c.name)));
            }
            if c.orthographic.is_some_and(|h| !(h.is_finite() && h > 0.0)) {
                return Err(corrupt(format!("camera '{}' has an orthographic height that is not positive", c.name)));
            }
        }
        for m in &self.materials {
            if m.textures().any(|t| t as usize >= self.textures.len()) {
                return Err(corrupt(format!(
                    "material '{}' names a texture beyond the {} there are",
                    m.name,
                    self.textures.len()
                )));
            }
        }
        let mut end = 0u64;
        for p in &self.parts {
            if u64::from(p.first) < end || p.count == 0 {
                return Err(corrupt(format!("mesh part '{}' is empty or overlaps the one before", p.name)));
            }
            end = u64::from(p.first) + u64::from(p.count);
        }
        for (i, e) in self.effects.iter().enumerate() {
            if self.effects[..i].iter().any(|f| f.effect == e.effect) {
                return Err(corrupt(format!("effect {} listed twice", e.effect.name())));
            }
        }
        Ok(())
    }
}

impl Shading {
    /// Checks that every texture's size is within [`MAX_TEXTURE_SIDE`] and its texels
    /// lie within the `words` words of the texel array.
    ///
    /// # Errors
    /// [`crate::Error::Corrupt`] naming the first bad texture.
    pub fn validate_texels(&self, texels: &crate::Texels<'_>) -> crate::Result<()> {
        let words = texels.stored().len();
        // The decoded images follow the stored texels, texture after texture.
        let mut decoded_end = (words / TEXEL_WORDS) as u64;
        for t in &self.textures {
            let sides = 1..=MAX_TEXTURE_SIDE;
            if t.encoded.is_some() {
                if !sides.contains(&t.width) || !sides.contains(&t.height) || u64::from(t.first) != decoded_end {
                    return Err(crate::Error::corrupt(format!(
                        "texture '{}' ({} x {}, encoded) is empty, larger than {MAX_TEXTURE_SIDE} a side, or its \
                         texels start at {} rather than {decoded_end}, after the texels before it",
                        t.name, t.width, t.height, t.first
                    )));
                }
                decoded_end += u64::from(t.width) * u64::from(t.height);
                let decoded = decoded_end - (words / TEXEL_WORDS) as u64;
                if decoded > crate::image::MAX_SCENE_TEXELS as u64 {
                    return Err(crate::Error::corrupt(format!(
                        "the encoded images hold {decoded} texels or more, past the {} a scene may have",
                        crate::image::MAX_SCENE_TEXELS
                    )));
                }
                // The header only: the pixels are decoded when first read.
                t.encoded_image(texels.images())
                    .map_err(|why| crate::Error::corrupt(format!("texture '{}': {why}", t.name)))?;
            }
            // Saturating: a hostile size must be refused, not overflow (found by fuzzing).
            let end = (t.first as u64 + t.width as u64 * t.height as u64).saturating_mul(TEXEL_WORDS as u64);
            if t.encoded.is_none() && (!sides.contains(&t.width) || !sides.contains(&t.height) || end > words as u64) {
                return Err(crate::Error::corrupt(format!(
                    "texture '{}' ({} x {} from texel {}) is empty, larger than {MAX_TEXTURE_SIDE} a side, \
                     or runs past the {} texels there are",
                    t.name,
                    t.width,
                    t.height,
                    t.first,
                    words / TEXEL_WORDS
                )));
            }
            if !(0.0..=1.0).contains(&t.min_alpha) {
                return Err(crate::Error::corrupt(format!("texture '{}' has minimum alpha {}", t.name, t.min_alpha)));
            }
        }
        Ok(())
    }
}

/// How far from 1 a stored unit vector's length may be: `f32` rounding of a normalised
/// vector stays within 1e-6; a vector built by hand from a few decimals, within this.
const UNIT_TOLERANCE: f64 = 1e-4;

/// Whether `v`'s length is 1 within [`UNIT_TOLERANCE`].
pub(crate) fn is_unit(v: [f32; 3]) -> bool {
    let len2 = v.iter().map(|&x| x as f64 * x as f64).sum::<f64>();
    (len2.sqrt() - 1.0).abs() <= UNIT_TOLERANCE
}
