//! glTF documents made by tests: a buffer of accessors, embedded as a `data:` URI.

/// The bytes, buffer views and accessors of a test's glTF document, one buffer.
///
/// ```
/// let mut b = octrace_tests::gltf::GltfBuffer::default();
/// let p = b.positions(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
/// let json = format!(
///     r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
///     "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}],{}}}"#,
///     b.members()
/// );
/// assert!(json.contains("\"accessors\""));
/// ```
#[derive(Clone, Debug, Default)]
pub struct GltfBuffer {
    bytes: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl GltfBuffer {
    /// A buffer view of `bytes` (padded to 4 bytes), its index.
    fn view(&mut self, bytes: &[u8]) -> usize {
        self.views.push(format!(r#"{{"buffer":0,"byteOffset":{},"byteLength":{}}}"#, self.bytes.len(), bytes.len()));
        self.bytes.extend_from_slice(bytes);
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        self.views.len() - 1
    }

    /// An accessor of `count` elements of `kind` (`"VEC3"`, ...) over `floats`, with
    /// `extra` JSON members (`"min"`/`"max"`), its index.
    fn floats(&mut self, floats: &[f32], kind: &str, count: usize, extra: &str) -> usize {
        let bytes: Vec<u8> = floats.iter().flat_map(|c| c.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors
            .push(format!(r#"{{"bufferView":{view},"componentType":5126,"count":{count},"type":"{kind}"{extra}}}"#));
        self.accessors.len() - 1
    }

    /// A `POSITION` accessor (with the `min` and `max` the spec asks for).
    pub fn positions(&mut self, p: &[[f32; 3]]) -> usize {
        let lo = (0..3).map(|a| p.iter().map(|v| v[a]).fold(f32::INFINITY, f32::min).to_string());
        let hi = (0..3).map(|a| p.iter().map(|v| v[a]).fold(f32::NEG_INFINITY, f32::max).to_string());
        let extra =
            format!(r#","min":[{}],"max":[{}]"#, lo.collect::<Vec<_>>().join(","), hi.collect::<Vec<_>>().join(","));
        self.floats(p.as_flattened(), "VEC3", p.len(), &extra)
    }

    /// A `VEC3` float accessor (normals).
    pub fn vec3(&mut self, v: &[[f32; 3]]) -> usize {
        self.floats(v.as_flattened(), "VEC3", v.len(), "")
    }

    /// A `VEC2` float accessor (texture coordinates).
    pub fn vec2(&mut self, v: &[[f32; 2]]) -> usize {
        self.floats(v.as_flattened(), "VEC2", v.len(), "")
    }

    /// A `VEC4` float accessor (colours, tangents).
    pub fn vec4(&mut self, v: &[[f32; 4]]) -> usize {
        self.floats(v.as_flattened(), "VEC4", v.len(), "")
    }

    /// An unsigned-short index accessor.
    pub fn indices(&mut self, indices: &[u16]) -> usize {
        let bytes: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors
            .push(format!(r#"{{"bufferView":{view},"componentType":5123,"count":{},"type":"SCALAR"}}"#, indices.len()));
        self.accessors.len() - 1
    }

    /// The document's `"buffers"`, `"bufferViews"` and `"accessors"` members, the
    /// buffer embedded as base64.
    pub fn members(&self) -> String {
        format!(
            r#""buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}],"bufferViews":[{}],"accessors":[{}]"#,
            self.bytes.len(),
            crate::base64(&self.bytes),
            self.views.join(","),
            self.accessors.join(",")
        )
    }
}

/// A PNG of `width x height` RGBA texels, as a `data:` URI for a glTF image.
pub fn png_data_uri(width: u32, height: u32, rgba: &[u8]) -> String {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgba);
        let mut writer = encoder.write_header().expect("PNG header");
        writer.write_image_data(rgba).expect("PNG data");
    }
    format!("data:image/png;base64,{}", crate::base64(&out))
}

impl GltfBuffer {
    /// The document `json` as a GLB file, the buffer its binary chunk: `json` names
    /// buffer 0 without a `uri` (`members_glb`'s members).
    pub fn glb(&self, json: &str) -> Vec<u8> {
        let mut text = json.as_bytes().to_vec();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let total = 12 + 8 + text.len() + 8 + self.bytes.len();
        let mut out = Vec::with_capacity(total);
        for word in [0x4654_6C67u32, 2, total as u32, text.len() as u32, 0x4E4F_534A] {
            out.extend_from_slice(&word.to_le_bytes());
        }
        out.extend_from_slice(&text);
        for word in [self.bytes.len() as u32, 0x004E_4942] {
            out.extend_from_slice(&word.to_le_bytes());
        }
        out.extend_from_slice(&self.bytes);
        out
    }

    /// The document's `"buffers"`, `"bufferViews"` and `"accessors"` members for a
    /// GLB ([`GltfBuffer::glb`]): the buffer is the binary chunk.
    pub fn members_glb(&self) -> String {
        format!(
            r#""buffers":[{{"byteLength":{}}}],"bufferViews":[{}],"accessors":[{}]"#,
            self.bytes.len(),
            self.views.join(","),
            self.accessors.join(",")
        )
    }
}

/// A GLB like Khronos' MetalRoughSpheresNoTextures: one sphere (radius 1, 100
/// segments by 54 rings: 10,600 triangles, with normals) stored once and shared by
/// `count` meshes, each with its own material (metallic and roughness factors in a
/// grid), placed by `count` nodes on a grid 2.5 apart in `x` and `y`: node 1 mirrored
/// (scale -1 in `x`), node 2 turned a quarter about `y` and scaled by 1.5. With
/// `floor`, a square of 2 triangles below them (its own material) placed once, a
/// point light above, and a camera (aspect 2) looking at them from `z = 30`.
pub fn placed_spheres(count: usize, floor: bool) -> Vec<u8> {
    let (segments, rings) = (100usize, 54usize);
    let mut positions = Vec::new();
    for r in 0..=rings {
        let theta = std::f64::consts::PI * r as f64 / rings as f64;
        for s in 0..=segments {
            let phi = std::f64::consts::TAU * s as f64 / segments as f64;
            let p = [theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin()];
            positions.push(p.map(|c| c as f32));
        }
    }
    let mut indices = Vec::new();
    for r in 0..rings {
        for s in 0..segments {
            let a = (r * (segments + 1) + s) as u16;
            let b = a + segments as u16 + 1;
            if r > 0 {
                indices.extend([a, a + 1, b]);
            }
            if r < rings - 1 {
                indices.extend([a + 1, b + 1, b]);
            }
        }
    }
    let mut b = GltfBuffer::default();
    let p = b.positions(&positions);
    let n = b.vec3(&positions);
    let i = b.indices(&indices);
    let columns = 14;
    let mut nodes: Vec<String> = (0..count)
        .map(|k| {
            let at = format!(r#""translation":[{},{},0]"#, 2.5 * (k % columns) as f64, 2.5 * (k / columns) as f64);
            match k {
                1 => format!(r#"{{"mesh":{k},{at},"scale":[-1,1,1]}}"#),
                2 => format!(r#"{{"mesh":{k},{at},"rotation":[0,0.7071068,0,0.7071068],"scale":[1.5,1.5,1.5]}}"#),
                _ => format!(r#"{{"mesh":{k},{at}}}"#),
            }
        })
        .collect();
    let mut meshes: Vec<String> = (0..count)
        .map(|k| {
            format!(
                r#"{{"primitives":[{{"attributes":{{"POSITION":{p},"NORMAL":{n}}},"indices":{i},"material":{k}}}]}}"#
            )
        })
        .collect();
    let rows = count.div_ceil(columns).max(2) - 1;
    let mut materials: Vec<String> = (0..count)
        .map(|k| {
            let (m, r) = ((k % columns) as f64 / (columns - 1) as f64, (k / columns) as f64 / rows as f64);
            format!(r#"{{"name":"sphere {k}","pbrMetallicRoughness":{{"metallicFactor":{m},"roughnessFactor":{r}}}}}"#)
        })
        .collect();
    let mut extensions = String::new();
    if floor {
        let w = 2.5 * columns as f32;
        let corners = [[-2.0, -2.0, -1.5], [w, -2.0, -1.5], [w, w, -1.5], [-2.0, w, -1.5]];
        let fp = b.positions(&corners);
        let fi = b.indices(&[0, 1, 2, 0, 2, 3]);
        meshes.push(format!(
            r#"{{"primitives":[{{"attributes":{{"POSITION":{fp}}},"indices":{fi},"material":{count}}}]}}"#
        ));
        materials.push(r#"{"name":"floor","pbrMetallicRoughness":{"baseColorFactor":[0.5,0.5,0.5,1]}}"#.into());
        nodes.push(format!(r#"{{"mesh":{count}}}"#));
        nodes.push(r#"{"translation":[15,10,20],"extensions":{"KHR_lights_punctual":{"light":0}}}"#.into());
        nodes.push(r#"{"camera":0,"translation":[16,3,30]}"#.into());
        extensions = r#""extensionsUsed":["KHR_lights_punctual"],
            "extensions":{"KHR_lights_punctual":{"lights":[{"type":"point","intensity":500}]}},
            "cameras":[{"type":"perspective","perspective":{"yfov":0.8,"aspectRatio":2.0,"znear":0.1}}],"#
            .into();
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},{extensions}"scenes":[{{"nodes":[{}]}}],"nodes":[{}],"meshes":[{}],
        "materials":[{}],{}}}"#,
        (0..nodes.len()).map(|k| k.to_string()).collect::<Vec<_>>().join(","),
        nodes.join(","),
        meshes.join(","),
        materials.join(","),
        b.members_glb()
    );
    b.glb(&json)
}
