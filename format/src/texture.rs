//! Texture images of a baked scene: how they are stored (decoded, linear, 16 bits a
//! channel) and sampled (integer arithmetic, so the CPU and the GPU kernel read the
//! same values).

use rkyv::{Archive, Deserialize, Serialize};

/// How texture coordinates outside `[0, 1]` land on a texture (glTF sampler `wrapS`,
/// `wrapT`).
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[rkyv(derive(Debug))]
#[repr(u8)]
pub enum Wrap {
    /// The texture tiles the plane (glTF's default).
    #[default]
    Repeat,
    /// Tiles, every other one mirrored.
    MirroredRepeat,
    /// Coordinates are clamped to the texture's edge.
    ClampToEdge,
}

impl Wrap {
    /// The mode's name in glTF's words, lower case: `repeat`, `mirrored repeat`,
    /// `clamp to edge`.
    pub fn name(self) -> &'static str {
        match self {
            Wrap::Repeat => "repeat",
            Wrap::MirroredRepeat => "mirrored repeat",
            Wrap::ClampToEdge => "clamp to edge",
        }
    }
}

/// How a texture is read between texel centres (glTF sampler `magFilter`; there are
/// no mipmaps, so minification uses the same filter).
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq, Default)]
#[rkyv(derive(Debug))]
#[repr(u8)]
pub enum Filter {
    /// The nearest texel.
    Nearest,
    /// Bilinear between the four nearest texels (glTF leaves the default to the
    /// viewer; this is octrace's).
    #[default]
    Linear,
}

impl Filter {
    /// `nearest` or `linear`.
    pub fn name(self) -> &'static str {
        match self {
            Filter::Nearest => "nearest",
            Filter::Linear => "linear",
        }
    }
}

/// Texels along a texture's side at most: [`Texture::sample`]'s fixed point needs
/// `side * 512 < 2^23`.
pub const MAX_TEXTURE_SIDE: u32 = 1 << 13;

/// Words a texel takes in [`crate::BakedScene::texels`]: linear RGBA, 16 bits a
/// channel, `r | g << 16` then `b | a << 16`.
pub const TEXEL_WORDS: usize = 2;

/// A texture image, its texels in [`crate::BakedScene::texels`].
///
/// Texels are stored decoded and linear: colour channels converted from sRGB (glTF
/// base colour textures are sRGB-encoded) and rounded to 16 bits, alpha as it is
/// (`a * 257`). Sampling ([`Texture::sample`]) is integer arithmetic up to one final
/// multiplication, so the GPU kernel samples exactly the same values.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Texture {
    /// The image's name, URI or `texture N`.
    pub name: String,
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Index of its first texel in the texel array (rows top to bottom, texels left to
    /// right; `v = 0` is the top row, as in glTF).
    pub first: u32,
    /// How `u` and `v` wrap.
    pub wrap: [Wrap; 2],
    /// Nearest or bilinear.
    pub filter: Filter,
    /// The smallest alpha of any texel, in `[0, 1]`: whether the texture cuts or
    /// blends anything out.
    pub min_alpha: f32,
}

/// `1 / (65535 * 256)`: the scale from a sample's 24-bit fixed point to `[0, 1]`.
pub const TEXEL_SCALE: f32 = 1.0 / 16_776_960.0;

impl Texture {
    /// The texture's value at `uv` (linear RGBA in `[0, 1]`), from `texels` (the
    /// scene's texel array): the wrap modes, then the nearest texel or the bilinear
    /// blend of four with 8-bit weights, all in integers; only the final scale is a
    /// floating-point operation. A texture that is empty, or whose texels lie outside
    /// `texels`, reads as white (the validator refuses such files; the trusted path
    /// may see them).
    pub fn sample(&self, texels: &[u32], uv: [f32; 2]) -> [f32; 4] {
        let (w, h) = (self.width as i64, self.height as i64);
        if w == 0 || h == 0 {
            return [1.0; 4];
        }
        let texel = |x: i64, y: i64| -> [u32; 4] {
            let i = (self.first as usize).saturating_add((y * w + x) as usize).saturating_mul(TEXEL_WORDS);
            match texels.get(i..i.saturating_add(TEXEL_WORDS)) {
                Some(&[a, b]) => [a & 0xffff, a >> 16, b & 0xffff, b >> 16],
                _ => [0xffff; 4],
            }
        };
        let mut sum = [0u32; 4];
        match self.filter {
            Filter::Nearest => {
                let x = wrap_index(self.wrap[0], (reduce(self.wrap[0], uv[0]) * w as f32).floor() as i64, w);
                let y = wrap_index(self.wrap[1], (reduce(self.wrap[1], uv[1]) * h as f32).floor() as i64, h);
                sum = texel(x, y).map(|c| c << 16);
            }
            Filter::Linear => {
                // Texel centres lie at half-integers: 1/256ths of a texel from the
                // centre of texel 0 (the product is exact up to its rounding, and
                // `* 256` and `- 128` are exact).
                let fixed = |c: f32, n: i64| (c * (n * 256) as f32).floor() as i64 - 128;
                let (fx, fy) = (fixed(reduce(self.wrap[0], uv[0]), w), fixed(reduce(self.wrap[1], uv[1]), h));
                let (x0, y0) = (fx >> 8, fy >> 8);
                let (ax, ay) = ((fx & 255) as u32, (fy & 255) as u32);
                for (dy, wy) in [(0, 256 - ay), (1, ay)] {
                    for (dx, wx) in [(0, 256 - ax), (1, ax)] {
                        let t = texel(wrap_index(self.wrap[0], x0 + dx, w), wrap_index(self.wrap[1], y0 + dy, h));
                        for c in 0..4 {
                            sum[c] += t[c] * (wx * wy);
                        }
                    }
                }
            }
        }
        sum.map(|s| (s >> 8) as f32 * TEXEL_SCALE)
    }
}

/// A texture coordinate brought into one period of its wrap mode: `[0, 1)` for
/// repeat, `[0, 2)` for mirrored repeat, `[0, 1]` for clamp (exact operations: a
/// float minus its floor, halving and doubling). Not finite: 0.
fn reduce(wrap: Wrap, c: f32) -> f32 {
    if !c.is_finite() {
        return 0.0;
    }
    match wrap {
        Wrap::Repeat => c - c.floor(),
        Wrap::MirroredRepeat => c - 2.0 * (c * 0.5).floor(),
        Wrap::ClampToEdge => c.clamp(0.0, 1.0),
    }
}

/// Texel index `i` (possibly one outside `0..n`) wrapped into `0..n`.
fn wrap_index(wrap: Wrap, i: i64, n: i64) -> i64 {
    match wrap {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::MirroredRepeat => {
            let k = i.rem_euclid(2 * n);
            if k >= n {
                2 * n - 1 - k
            } else {
                k
            }
        }
        Wrap::ClampToEdge => i.clamp(0, n - 1),
    }
}

/// sRGB-encoded 8-bit colour to linear, 16 bits (the sRGB transfer function), as
/// the bake stores texels.
pub fn srgb_to_linear16(c: u8) -> u16 {
    let x = c as f64 / 255.0;
    let l = if x <= 0.04045 { x / 12.92 } else { ((x + 0.055) / 1.055).powf(2.4) };
    (l * 65535.0).round() as u16
}
