//! glTF materials and their textures (base colour, emissive, metallic-roughness,
//! occlusion): images decoded, texels stored at 8 bits a channel, samplers and
//! `KHR_texture_transform` resolved at bake.

use std::collections::HashMap;
use std::path::Path;

use octrace_format::{AlphaMode, Encoded, Filter, Material, Texture, Wrap};

use super::super::refs::{self, LoadOptions};
use super::super::Mesh;
use crate::error::{Error, Result};
use octrace_format::image::{self, MAX_SCENE_TEXELS};

/// How a material's texture coordinates are found: the `TEXCOORD_n` set its base
/// colour texture reads, and the affine map `KHR_texture_transform` applies to it
/// (`[[a, b, c], [d, e, f]]`: `u' = a u + b v + c`, `v' = d u + e v + f`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct UvMap {
    pub set: u32,
    pub transform: Option<[[f64; 3]; 2]>,
}

impl UvMap {
    /// `uv` through the transform.
    pub fn apply(&self, uv: [f32; 2]) -> [f32; 2] {
        let Some([r0, r1]) = self.transform else { return uv };
        let (u, v) = (uv[0] as f64, uv[1] as f64);
        let out = [(r0[0] * u + r0[1] * v + r0[2]) as f32, (r1[0] * u + r1[1] * v + r1[2]) as f32];
        if out.iter().all(|c| c.is_finite()) {
            out
        } else {
            [0.0; 2]
        }
    }
}

/// The texture coordinates a texture slot reads: its `TEXCOORD_n` set and its
/// `KHR_texture_transform`.
fn uv_map(info: &gltf::texture::Info<'_>) -> UvMap {
    let mut uv = UvMap { set: info.tex_coord(), transform: None };
    if let Some(t) = info.texture_transform() {
        uv.set = t.tex_coord().unwrap_or(uv.set);
        let (offset, r, scale) = (t.offset().map(f64::from), t.rotation() as f64, t.scale().map(f64::from));
        uv.transform = Some(transform_matrix(offset, r, scale));
    }
    uv
}

/// The coordinates of a slot the gltf crate gives no transform for (occlusion,
/// normal): its `texCoord`, and its `KHR_texture_transform` as JSON (`offset`,
/// `rotation`, `scale`, `texCoord`; a value of another type is left at its default).
fn raw_uv_map(tex_coord: u32, transform: Option<&gltf::json::Value>) -> UvMap {
    let Some(t) = transform else { return UvMap { set: tex_coord, transform: None } };
    let pair = |key: &str, default: f64| {
        let v = t.get(key).and_then(|v| v.as_array());
        let c = |i: usize| v.and_then(|v| v.get(i)).and_then(|c| c.as_f64()).unwrap_or(default);
        [c(0), c(1)]
    };
    let set = t.get("texCoord").and_then(|c| c.as_u64()).and_then(|c| u32::try_from(c).ok()).unwrap_or(tex_coord);
    let rotation = t.get("rotation").and_then(|r| r.as_f64()).unwrap_or(0.0);
    UvMap { set, transform: Some(transform_matrix(pair("offset", 0.0), rotation, pair("scale", 1.0))) }
}

/// KHR_texture_transform's matrix: translation * rotation * scale, the rotation as the
/// spec writes it, rows (cos r, sin r), (-sin r, cos r).
fn transform_matrix([ox, oy]: [f64; 2], r: f64, [sx, sy]: [f64; 2]) -> [[f64; 3]; 2] {
    let (c, s) = (r.cos(), r.sin());
    [[c * sx, s * sy, ox], [-s * sx, c * sy, oy]]
}

/// A material's texture slot: its name, its texture and coordinates if it has one,
/// and whether its colour is sRGB-encoded.
type Slot<'a> = (&'static str, Option<(gltf::Texture<'a>, UvMap)>, bool);

/// What loading a document's materials needs.
pub(super) struct Materials<'a> {
    pub path: &'a Path,
    pub base: Option<&'a Path>,
    pub options: &'a LoadOptions,
    pub buffers: &'a [super::Buffer<'a>],
    /// Textures already loaded: (image, sampler, sRGB) to the index in
    /// `mesh.textures`, or `None` when the image could not be used.
    pub loaded: HashMap<(usize, Option<usize>, bool), Option<u32>>,
    /// Images kept encoded: image index to (offset, length) in `mesh.images` (two
    /// textures of one image, as sRGB colour and as linear data, share its bytes).
    pub kept: HashMap<usize, (u64, u64)>,
}

impl Materials<'_> {
    /// A glTF material in octrace's terms, with the texture coordinates its texture
    /// reads. Factors are clamped to their ranges (the spec's ranges: 0-1 for colours
    /// and factors, an index of refraction of at least 1).
    ///
    /// # Errors
    /// [`Error::Parse`] for a value that is not finite (a JSON number beyond `f32`).
    pub fn material(&mut self, m: &gltf::Material<'_>, mesh: &mut Mesh) -> Result<(Material, Vec<UvMap>)> {
        let name = m.name().map_or_else(|| format!("material {}", m.index().unwrap_or(0)), str::to_string);
        let pbr = m.pbr_metallic_roughness();
        let strength = m.emissive_strength().unwrap_or(1.0);
        let unit = |v: f32| v.clamp(0.0, 1.0);
        // Each texture slot with its texture and the coordinates it reads: a channel for
        // each distinct set and transform, the first slot's first (one channel for
        // most materials).
        let occlusion = m.occlusion_texture();
        let normal = m.normal_texture();
        let [base_name, emissive_name, mr_name, occlusion_name, normal_name] = Material::TEXTURE_SLOTS;
        let slots: [Slot<'_>; 5] = [
            (base_name, pbr.base_color_texture().map(|i| (i.texture(), uv_map(&i))), true),
            (emissive_name, m.emissive_texture().map(|i| (i.texture(), uv_map(&i))), true),
            (mr_name, pbr.metallic_roughness_texture().map(|i| (i.texture(), uv_map(&i))), false),
            // The gltf crate gives an occlusion or normal texture's KHR_texture_transform
            // only as JSON.
            (
                occlusion_name,
                occlusion
                    .as_ref()
                    .map(|o| (o.texture(), raw_uv_map(o.tex_coord(), o.extension_value("KHR_texture_transform")))),
                false,
            ),
            (
                normal_name,
                normal
                    .as_ref()
                    .map(|n| (n.texture(), raw_uv_map(n.tex_coord(), n.extension_value("KHR_texture_transform")))),
                false,
            ),
        ];
        let mut maps: Vec<UvMap> = Vec::new();
        let mut uv_channels = [0u8; 5];
        let mut textures = [None; 5];
        for (k, (slot, texture, srgb)) in slots.iter().enumerate() {
            let Some((texture, map)) = texture else { continue };
            textures[k] = self.texture(texture, &name, slot, *srgb, mesh);
            if textures[k].is_some() {
                let channel = maps.iter().position(|m| m == map).unwrap_or_else(|| {
                    maps.push(*map);
                    maps.len() - 1
                });
                uv_channels[k] = channel as u8;
            }
        }
        if maps.is_empty() {
            maps.push(UvMap { set: 0, transform: None });
        }
        let [texture, emissive_texture, metallic_roughness_texture, occlusion_texture, normal_texture] = textures;
        let out = Material {
            base_color: pbr.base_color_factor().map(unit),
            metallic: unit(pbr.metallic_factor()),
            roughness: unit(pbr.roughness_factor()),
            emissive: m.emissive_factor().map(|e| unit(e) * strength.max(0.0)),
            alpha_mode: match m.alpha_mode() {
                gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                gltf::material::AlphaMode::Mask => AlphaMode::Mask,
                gltf::material::AlphaMode::Blend => AlphaMode::Blend,
            },
            alpha_cutoff: m.alpha_cutoff().unwrap_or(0.5).max(0.0),
            transmission: unit(m.transmission().map_or(0.0, |t| t.transmission_factor())),
            ior: m.ior().unwrap_or(1.5).max(1.0),
            specular: [0.0; 3],
            illum: None,
            unlit: m.unlit(),
            base_color_texture: texture,
            emissive_texture,
            metallic_roughness_texture,
            occlusion_texture,
            occlusion_strength: occlusion.as_ref().map_or(1.0, |o| unit(o.strength())),
            normal_texture,
            normal_scale: normal.as_ref().map_or(1.0, |n| n.scale()),
            uv_channels,
            double_sided: m.double_sided(),
            name,
        };
        let numbers = out.base_color.iter().chain(&out.emissive).chain([
            &out.alpha_cutoff,
            &out.ior,
            &strength,
            &out.normal_scale,
        ]);
        if let Some(bad) = numbers.into_iter().find(|v| !v.is_finite()) {
            return Err(Error::Parse {
                path: self.path.into(),
                element: format!("material '{}'", out.name),
                message: format!("value {bad} is not a finite number"),
            });
        }
        self.transmission_left_out(m, &out, mesh);
        Ok((out, maps))
    }

    /// Warns, naming the material, of what its `KHR_materials_transmission` asks that
    /// the renderer does not simulate: a `transmissionTexture` (the factor is taken
    /// everywhere) and rough transmission (rendered as smooth glass, one refracted
    /// ray).
    fn transmission_left_out(&self, m: &gltf::Material<'_>, out: &Material, mesh: &mut Mesh) {
        let Some(transmission) = m.transmission() else { return };
        let material = format!("{}: material '{}'", self.path.display(), out.name);
        if transmission.transmission_texture().is_some() {
            mesh.warnings.push(format!(
                "{material}: KHR_materials_transmission's transmissionTexture is ignored: its transmission factor \
                 {} is taken everywhere",
                out.transmission
            ));
        }
        let rough = out.roughness > 0.0 || pbr_has_texture(m);
        if out.transmission > 0.0 && rough {
            mesh.warnings.push(format!(
                "{material}: rough transmission (roughness {}{}) is rendered as smooth glass: one refracted ray, \
                 no blur",
                out.roughness,
                if pbr_has_texture(m) { " times its metallic-roughness texture" } else { "" }
            ));
        }
    }

    /// The index in `mesh.textures` of `texture`'s image with its sampler, loading it
    /// the first time; `None`, with a warning naming the image, when it cannot be read
    /// or decoded.
    fn texture(
        &mut self,
        texture: &gltf::Texture<'_>,
        material: &str,
        slot: &str,
        srgb: bool,
        mesh: &mut Mesh,
    ) -> Option<u32> {
        let image = texture.source();
        let sampler = texture.sampler();
        let key = (image.index(), sampler.index(), srgb);
        if let Some(&done) = self.loaded.get(&key) {
            return done;
        }
        let label = match (image.name(), image.source()) {
            (Some(name), _) => format!("image {} '{name}'", image.index()),
            (None, gltf::image::Source::Uri { uri, .. }) if !uri.starts_with("data:") => {
                format!("image {} '{}'", image.index(), uri.chars().take(200).collect::<String>())
            }
            _ => format!("image {}", image.index()),
        };
        let budget = MAX_SCENE_TEXELS.saturating_sub(mesh.texels.len() / octrace_format::TEXEL_WORDS);
        let decoded = self.image_bytes(&image, mesh).and_then(|bytes| Ok((image::decode(&bytes, budget)?, bytes)));
        let index = match decoded {
            Ok((rgba, bytes)) => {
                use gltf::texture::{MagFilter, WrappingMode};
                let wrap = |w: WrappingMode| match w {
                    WrappingMode::Repeat => Wrap::Repeat,
                    WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
                    WrappingMode::ClampToEdge => Wrap::ClampToEdge,
                };
                let first = mesh.texels.len() / octrace_format::TEXEL_WORDS;
                let Ok(first) = u32::try_from(first) else {
                    mesh.warnings.push(format!("{}: {label}: left out: more than 2^32 texels", self.path.display()));
                    return None;
                };
                let mut min_alpha = 255u8;
                // As the image holds them, 8 bits a channel; sampling decodes sRGB.
                for &pixel in &rgba.pixels {
                    mesh.texels.push(u32::from_le_bytes(pixel));
                    min_alpha = min_alpha.min(pixel[3]);
                }
                // An image smaller encoded than as texels (a JPEG, most PNGs) is kept
                // as it is and decoded when first read, with the same decoder: the hash
                // of what it decodes to here checks that.
                let raw = rgba.pixels.len() as u64 * 4;
                let encoded = image::kind(&bytes).filter(|_| (bytes.len() as u64) < raw).map(|kind| {
                    let (offset, len) = *self.kept.entry(image.index()).or_insert_with(|| {
                        let at = mesh.images.len() as u64;
                        mesh.images.extend_from_slice(&bytes);
                        (at, bytes.len() as u64)
                    });
                    let words = &mesh.texels[first as usize..];
                    Encoded { kind, offset, bytes: len, texels_hash: octrace_format::texels_hash(words) }
                });
                mesh.textures.push(Texture {
                    name: label,
                    width: rgba.width,
                    height: rgba.height,
                    first,
                    wrap: [wrap(sampler.wrap_s()), wrap(sampler.wrap_t())],
                    filter: match sampler.mag_filter() {
                        Some(MagFilter::Nearest) => Filter::Nearest,
                        _ => Filter::Linear,
                    },
                    min_alpha: f32::from(min_alpha) / 255.0,
                    // Base colour and emissive textures are sRGB-encoded (glTF), the
                    // others linear.
                    srgb,
                    encoded,
                });
                Some(mesh.textures.len() as u32 - 1)
            }
            Err(why) => {
                mesh.warnings.push(format!(
                    "{}: {label} ({slot} texture of material '{material}') left out: {why}",
                    self.path.display()
                ));
                None
            }
        };
        self.loaded.insert(key, index);
        index
    }

    /// An image's encoded bytes: from a buffer view, a `data:` URI, or a file the URI
    /// names (read only where the load options allow, as buffers are).
    fn image_bytes(&self, image: &gltf::Image<'_>, mesh: &mut Mesh) -> std::result::Result<Vec<u8>, String> {
        match image.source() {
            gltf::image::Source::View { view, .. } => {
                let buffer = self.buffers.get(view.buffer().index()).map_or(&[][..], |d| &d[..]);
                let range = view.offset()..view.offset().saturating_add(view.length());
                buffer
                    .get(range)
                    .map(<[u8]>::to_vec)
                    .ok_or_else(|| format!("buffer view {} runs past buffer {}", view.index(), view.buffer().index()))
            }
            gltf::image::Source::Uri { uri, .. } if uri.starts_with("data:") => super::buffers::data_uri(uri),
            gltf::image::Source::Uri { uri, .. } => {
                let target = super::buffers::uri_path(uri)?;
                let file = refs::resolve(self.base, Path::new(&target), self.options.references)?;
                let bytes =
                    octrace_format::read_regular_file(&file, self.options.max_file_bytes).map_err(|e| e.to_string())?;
                mesh.sources.push(file);
                Ok(bytes)
            }
        }
    }
}

/// Whether a material has a metallic-roughness texture (its roughness varies).
fn pbr_has_texture(m: &gltf::Material<'_>) -> bool {
    m.pbr_metallic_roughness().metallic_roughness_texture().is_some()
}
