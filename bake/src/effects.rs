//! The effects a scene calls for, decided once at bake from its materials and lights,
//! each with the reason a user can check.

use octrace_format::{AlphaMode, Effect, EffectReason, EmissiveTriangles, Material, VISIBLE_WEIGHT};

use crate::mesh::Mesh;

/// The effects `mesh` calls for, in [`Effect::ALL`] order, considering only the
/// materials of the triangles in `used` (the triangles that reach the octree).
///
/// * shadows: any punctual light or emissive triangle, when some surface is lit (not
///   `KHR_materials_unlit`);
/// * soft shadows: emissive triangles (area lights), likewise; a triangle whose
///   material's emissive texture is black over all the texels it can read is none,
///   and emission through textures lights nothing in a scene without other light
///   (punctual lights or emitters without a texture): the headlight lights it;
/// * reflection: a lit material whose mirror weight ([`Material::mirror`]) is
///   visible (with a metallic-roughness texture, at its most mirror-like texel), or a
///   transmissive one with an index of refraction above 1 (its Fresnel reflection);
/// * refraction: a lit material with transmission above zero;
/// * alpha: coverage ([`Material::coverage_at`]) below one somewhere: the alpha
///   factor times the smallest alpha of the material's texture and of the vertex
///   colours of its triangles.
///
/// # Example
/// ```
/// use octrace_bake::{effects::decide, Mesh};
/// let mesh = Mesh::from_triangles(vec![[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
/// assert!(decide(&mesh, &[0]).is_empty()); // no lights, no materials: primary rays only
/// ```
pub fn decide(mesh: &Mesh, used: &[u32]) -> Vec<EffectReason> {
    let mut counts = vec![0usize; mesh.materials.len()];
    // The smallest vertex-colour alpha on each material's triangles.
    let mut vertex_alpha = vec![1.0f32; mesh.materials.len()];
    for &t in used {
        if let Some(&m) = mesh.material_ids.get(t as usize) {
            counts[m as usize] += 1;
            if let Some(c) = mesh.colors.get(t as usize) {
                let alpha = c.iter().map(|k| k[3]).min().unwrap_or(u16::MAX);
                vertex_alpha[m as usize] = vertex_alpha[m as usize].min(alpha as f32 / 65535.0);
            }
        }
    }
    let used_materials: Vec<(&Material, usize)> =
        mesh.materials.iter().zip(counts.iter().copied()).filter(|&(_, n)| n > 0).collect();
    let emitting = emitting_triangles(mesh, used);
    // (material, its triangles, those that emit) of each material with emitting triangles.
    let emitters: Vec<(&Material, usize, usize)> = mesh
        .materials
        .iter()
        .zip(&counts)
        .zip(&emitting)
        .filter(|&(_, &lit)| lit > 0)
        .map(|((m, &n), &lit)| (m, n, lit))
        .collect();
    // Emission through a texture lights the scene only beside other light: alone, it
    // shows where it is seen and the renderer's headlight lights the scene, as a glTF
    // viewer shows it (runtime `Emitters::need_headlight`).
    let lights_scene = !mesh.lights.is_empty() || emitters.iter().any(|(m, ..)| m.emissive_texture.is_none());
    let emitters = if lights_scene { emitters } else { Vec::new() };
    let mut effects = Vec::new();
    let mut add = |effect: Effect, reasons: Vec<String>| {
        if let Some(first) = reasons.first() {
            let reason = match reasons.len() {
                1 => first.clone(),
                n => format!("{first} (and {} more)", n - 1),
            };
            effects.push(EffectReason { effect, reason });
        }
    };
    // "area light: material 'lamp' emits (1.00, 1.00, 1.00) on 2 triangles", and with an
    // emissive texture "... times texture 'image 2' on 120 of 15452 triangles (the rest
    // under black texels)".
    let area = |&(m, n, lit): &(&Material, usize, usize)| {
        let e = m.emissive;
        let s = if n == 1 { "" } else { "s" };
        let emits = format!("area light: material '{}' emits ({:.2}, {:.2}, {:.2})", m.name, e[0], e[1], e[2]);
        match m.emissive_texture.and_then(|t| mesh.textures.get(t as usize)) {
            Some(t) if lit < n => {
                format!("{emits} times texture {} on {lit} of {n} triangles (the rest under black texels)", t.name)
            }
            Some(t) => format!("{emits} times texture {} on {n} triangle{s}", t.name),
            None => format!("{emits} on {n} triangle{s}"),
        }
    };
    // A mesh without materials is lit (the renderer's plain material).
    let lit = used_materials.is_empty() || used_materials.iter().any(|(m, _)| !m.unlit);
    let mut lights: Vec<String> =
        mesh.lights.iter().map(|l| format!("light '{}' ({:?})", l.name, l.kind).to_lowercase()).collect();
    lights.extend(emitters.iter().map(area));
    if lit {
        add(Effect::Shadows, lights);
        add(Effect::SoftShadows, emitters.iter().map(area).collect());
    }
    let mirrors = used_materials.iter().filter(|(m, _)| !m.unlit).filter_map(|(m, _)| {
        if m.transmission > 0.0 && m.ior > 1.0 {
            return Some(format!("material '{}', transmission {:.2} (Fresnel reflection)", m.name, m.transmission));
        }
        // With a metallic-roughness texture, the most mirror-like texel decides: the
        // least roughness, and the mirror weight (linear in metallic) at either end of
        // the texture's metallic range.
        let (metallic, roughness, texture) = match metallic_roughness_range(mesh, m) {
            Some((t, [lo, hi], rough)) => {
                let mirror = |metallic: f32| Material { metallic, roughness: rough, ..(*m).clone() }.mirror();
                let best = if max3(mirror(hi)) >= max3(mirror(lo)) { hi } else { lo };
                (best, rough, Some(t))
            }
            None => (m.metallic, m.roughness, None),
        };
        let w = Material { metallic, roughness, ..(*m).clone() }.mirror();
        (max3(w) >= VISIBLE_WEIGHT).then(|| match (m.illum, texture) {
            (Some(illum), _) => {
                let k = m.specular;
                format!("material '{}', illum {illum}, Ks ({:.2}, {:.2}, {:.2})", m.name, k[0], k[1], k[2])
            }
            (None, Some(t)) => format!(
                "material '{}', metallic {metallic:.2}, roughness down to {roughness:.2} (texture {})",
                m.name, t.name
            ),
            (None, None) => format!("material '{}', metallic {:.2}, roughness {:.2}", m.name, m.metallic, m.roughness),
        })
    });
    add(Effect::Reflection, mirrors.collect());
    let glass = used_materials.iter().filter(|(m, _)| m.transmission > 0.0 && !m.unlit).map(|(m, _)| match m.illum {
        Some(_) => format!("material '{}', d {:.2}, Ni {:.2}", m.name, 1.0 - m.transmission, m.ior),
        None => format!("material '{}', transmission {:.2}, ior {:.2}", m.name, m.transmission, m.ior),
    });
    add(Effect::Refraction, glass.collect());
    let texture = |m: &Material| m.base_color_texture.and_then(|t| mesh.textures.get(t as usize));
    // Each used material with its smallest alpha: factor, texture and vertex colours.
    let alphas = mesh.materials.iter().zip(&counts).zip(&vertex_alpha).filter(|((_, &n), _)| n > 0);
    let alphas = alphas.map(|((m, _), v)| (m, m.base_color[3] * texture(m).map_or(1.0, |t| t.min_alpha) * v));
    let cut = alphas.filter(|&(m, alpha)| m.coverage_at(alpha) < 1.0).map(|(m, alpha)| {
        // "alpha 0.30", or "alpha down to 0.00 (texture 'leaves.png')".
        let value = match texture(m) {
            Some(t) => format!("down to {alpha:.2} (texture {})", t.name),
            None => format!("{alpha:.2}"),
        };
        match (m.alpha_mode, m.illum) {
            (AlphaMode::Mask, _) => {
                format!("material '{}', alphaMode MASK, alpha {value} < cutoff {:.2}", m.name, m.alpha_cutoff)
            }
            (_, Some(_)) => format!("material '{}', d {alpha:.2}", m.name),
            _ => format!("material '{}', alphaMode BLEND, alpha {value}", m.name),
        }
    });
    add(Effect::Alpha, cut.collect());
    effects
}

/// The largest channel of a colour.
fn max3(c: [f32; 3]) -> f32 {
    c[0].max(c[1]).max(c[2])
}

/// A material's metallic-roughness texture with the range of metallic it gives (the
/// factor times the blue channel's smallest and largest texel) and its least roughness
/// (the factor times the green channel's smallest).
fn metallic_roughness_range<'m>(mesh: &'m Mesh, m: &Material) -> Option<(&'m octrace_format::Texture, [f32; 2], f32)> {
    let t = mesh.textures.get(m.metallic_roughness_texture? as usize)?;
    let texels = mesh.texels.get(t.first as usize..)?.iter().take(t.width as usize * t.height as usize);
    let (mut blue, mut green) = ([u8::MAX, 0], u8::MAX);
    for texel in texels {
        let [_, g, b, _] = texel.to_le_bytes();
        blue = [blue[0].min(b), blue[1].max(b)];
        green = green.min(g);
    }
    // Decoded as sampling decodes a linear texture (c * 257, then scaled to [0, 1]).
    let unit = |c: u8| f32::from(c) / 255.0;
    Some((t, [m.metallic * unit(blue[0]), m.metallic * unit(blue[1])], m.roughness * unit(green)))
}

/// How many of the triangles in `used` emit light, per material: all of an emissive
/// material's, or, with an emissive texture, those whose texels are not all black
/// ([`EmissiveTriangles`], as the renderer decides its area lights).
fn emitting_triangles(mesh: &Mesh, used: &[u32]) -> Vec<usize> {
    let mut emitting = vec![0usize; mesh.materials.len()];
    let mut emissive = EmissiveTriangles::new(&mesh.textures, &mesh.texels);
    for &t in used {
        let Some(&id) = mesh.material_ids.get(t as usize) else { continue };
        let Some(m) = mesh.materials.get(id as usize) else { continue };
        // The coordinates its emissive texture reads.
        let corners = mesh.corner_uvs(t as usize, m.uv_channel(1)).unwrap_or_default();
        emitting[id as usize] += usize::from(emissive.emits(m, corners));
    }
    emitting
}
