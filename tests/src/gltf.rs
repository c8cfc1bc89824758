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
