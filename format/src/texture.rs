//! Texture images of a baked scene: how they are stored (8 bits a channel, as the
//! source image holds them) and sampled (decoded to linear 16-bit values by a table,
//! then integer arithmetic, so the CPU and the GPU kernel read the same values).

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

/// Words a texel takes in [`crate::BakedScene::texels`]: RGBA, 8 bits a channel as the
/// source image holds them, `r | g << 8 | b << 16 | a << 24`.
pub const TEXEL_WORDS: usize = 1;

/// A texture image, its texels in [`crate::BakedScene::texels`].
///
/// Texels are stored at the source's 8 bits a channel and decoded as they are read: an
/// sRGB texture's colour channels (glTF base colour and emissive textures) through
/// [`linear16`]'s table, 16 bits of linear light, a linear texture's as `c * 257`, and
/// alpha as `a * 257`. Sampling ([`Texture::sample`]) is integer arithmetic up to one
/// final multiplication, so the GPU kernel samples exactly the same values.
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
    /// Whether the colour channels are sRGB-encoded (decoded to linear light when
    /// read) rather than linear.
    pub srgb: bool,
    /// Where the texture's image is kept encoded (a PNG or a JPEG in the scene's
    /// `images`, decoded the first time texels are read), or `None` when its texels
    /// are stored in the `texels` section.
    pub encoded: Option<Encoded>,
}

/// The encodings a texture's image may be kept in.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[rkyv(derive(Debug))]
#[repr(u8)]
pub enum ImageKind {
    /// A PNG image.
    Png,
    /// A (baseline or progressive) JPEG image.
    Jpeg,
}

impl ImageKind {
    /// `PNG` or `JPEG`.
    pub fn name(self) -> &'static str {
        match self {
            ImageKind::Png => "PNG",
            ImageKind::Jpeg => "JPEG",
        }
    }
}

/// A texture kept as its source image encodes it: smaller than its texels (a JPEG of
/// 2048 x 2048 texels takes about 1 MB against 16 MB), decoded the first time the
/// scene's texels are read ([`crate::Texels`]), with the decoder the bake used; the
/// hash of the texels the bake decoded checks that they are the same.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[rkyv(derive(Debug))]
pub struct Encoded {
    /// PNG or JPEG.
    pub kind: ImageKind,
    /// Offset of its first byte in the scene's images (bytes).
    pub offset: u64,
    /// Its length in bytes.
    pub bytes: u64,
    /// xxh3-64 of the texels it decodes to, their words' little-endian bytes.
    pub texels_hash: u64,
}

impl Texture {
    /// Whether an image of `kind` and `width x height` is the one the record says.
    pub(crate) fn same_image(&self, kind: ImageKind, width: u32, height: u32) -> Result<(), String> {
        let Some(e) = &self.encoded else { return Err("not encoded".into()) };
        if (kind, width, height) == (e.kind, self.width, self.height) {
            return Ok(());
        }
        Err(format!(
            "its image is a {} of {width} x {height}, its record says a {} of {} x {}",
            kind.name(),
            e.kind.name(),
            self.width,
            self.height
        ))
    }
}

/// The hash [`Encoded::texels_hash`] keeps of a decoded image's texels.
pub fn texels_hash(texels: &[u32]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytemuck::cast_slice(texels))
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
        let table = linear16();
        let texel = |x: i64, y: i64| -> [u32; 4] {
            let i = (self.first as usize).saturating_add((y * w + x) as usize);
            match texels.get(i) {
                Some(&word) => self.decode(word, table),
                None => [0xffff; 4],
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

impl Texture {
    /// A stored texel's four channels at 16 bits: colour through `table` (sRGB) or
    /// times 257 (linear), alpha times 257.
    fn decode(&self, word: u32, table: &[u16; 256]) -> [u32; 4] {
        let [r, g, b, a] = word.to_le_bytes().map(u32::from);
        let colour = |c: u32| if self.srgb { u32::from(table[c as usize]) } else { c * 257 };
        [colour(r), colour(g), colour(b), a * 257]
    }
}

/// The 16-bit linear value of each 8-bit sRGB-encoded value ([`srgb_to_linear16`]),
/// computed once: what sampling an sRGB texture reads (the GPU kernel gets the same
/// table).
pub fn linear16() -> &'static [u16; 256] {
    static TABLE: std::sync::OnceLock<[u16; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|c| srgb_to_linear16(c as u8)))
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
/// sampling decodes texels.
pub fn srgb_to_linear16(c: u8) -> u16 {
    let x = c as f64 / 255.0;
    let l = if x <= 0.04045 { x / 12.92 } else { ((x + 0.055) / 1.055).powf(2.4) };
    (l * 65535.0).round() as u16
}

/// Which texels of a texture have colour (any of red, green, blue above zero), as a
/// summed-area table: whether the texels a triangle's samples can read are all black,
/// asked in constant time. The renderer and the bake use it to decide which triangles
/// of a material with an emissive texture are area lights.
///
/// # Example
/// ```
/// use octrace_format::{LitTexels, Texture};
/// use octrace_format::{Filter, Wrap};
/// // 4 x 1 texels, clamped: three black, then white (RGBA, 8 bits a channel).
/// let texels = [0xff00_0000, 0xff00_0000, 0xff00_0000, 0xffff_ffff];
/// let texture = Texture { name: "t".into(), width: 4, height: 1, first: 0, wrap: [Wrap::ClampToEdge; 2],
///     filter: Filter::Nearest, min_alpha: 1.0, srgb: true, encoded: None };
/// let lit = LitTexels::new(&texture, &texels);
/// assert!(!lit.any_lit([[0.1, 0.5], [0.2, 0.5], [0.1, 0.6]])); // over the black texels
/// assert!(lit.any_lit([[0.1, 0.5], [0.9, 0.5], [0.1, 0.6]])); // reaching the white one
/// ```
#[derive(Clone, Debug)]
pub struct LitTexels {
    width: i64,
    height: i64,
    wrap: [Wrap; 2],
    /// `(width + 1) * (height + 1)` running counts of lit texels above and left of each
    /// corner.
    sums: Vec<u32>,
}

impl LitTexels {
    /// The table of `texture`, its texels in `texels` (a texel outside `texels` reads
    /// white, as [`Texture::sample`] reads it).
    pub fn new(texture: &Texture, texels: &[u32]) -> LitTexels {
        let (w, h) = (texture.width as usize, texture.height as usize);
        let mut sums = vec![0u32; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0u32;
            for x in 0..w {
                // A colour channel is zero decoded exactly when it is zero stored.
                let lit = texels
                    .get((texture.first as usize).saturating_add(y * w + x))
                    .is_none_or(|&c| c & 0x00ff_ffff != 0);
                row += u32::from(lit);
                sums[(y + 1) * (w + 1) + x + 1] = sums[y * (w + 1) + x + 1] + row;
            }
        }
        LitTexels { width: w as i64, height: h as i64, wrap: texture.wrap, sums }
    }

    /// Whether a sample anywhere in the triangle whose corners have texture coordinates
    /// `corners` may read a texel with colour: the texels under the coordinates'
    /// bounding box, one more on each side (what bilinear filtering and the rounding of
    /// the texel index can reach), wrapped as the texture wraps. Conservative: a
    /// triangle only near a lit texel may answer yes; one whose samples can reach one
    /// never answers no.
    pub fn any_lit(&self, corners: [[f32; 2]; 3]) -> bool {
        if self.width == 0 || self.height == 0 {
            return true; // reads as white
        }
        let xs = axis_spans(self.wrap[0], corners.map(|c| c[0]), self.width);
        let ys = axis_spans(self.wrap[1], corners.map(|c| c[1]), self.height);
        xs.iter().flatten().any(|&(x0, x1)| ys.iter().flatten().any(|&(y0, y1)| self.count(x0, x1, y0, y1) > 0))
    }

    /// Lit texels in columns `x0..=x1`, rows `y0..=y1`.
    fn count(&self, x0: i64, x1: i64, y0: i64, y1: i64) -> u32 {
        let row = self.width + 1;
        let at = |x: i64, y: i64| self.sums[(y * row + x) as usize];
        at(x1 + 1, y1 + 1) + at(x0, y0) - at(x0, y1 + 1) - at(x1 + 1, y0)
    }
}

/// Whether triangles emit light, as the bake and the renderer decide it: a triangle of
/// an emissive material emits, unless the material's emissive texture is black over all
/// the texels the triangle can read ([`LitTexels::any_lit`], each texture's table built
/// the first time it is asked). An emissive texture past `textures` counts as none.
#[derive(Debug)]
pub struct EmissiveTriangles<'a> {
    textures: &'a [Texture],
    texels: &'a [u32],
    tables: Vec<Option<LitTexels>>,
}

impl<'a> EmissiveTriangles<'a> {
    /// For a scene's `textures` and their `texels`.
    pub fn new(textures: &'a [Texture], texels: &'a [u32]) -> Self {
        EmissiveTriangles { textures, texels, tables: vec![None; textures.len()] }
    }

    /// Whether a triangle of `material` whose corners have texture coordinates
    /// `corners` emits light.
    pub fn emits(&mut self, material: &crate::Material, corners: [[f32; 2]; 3]) -> bool {
        if !material.is_emissive() {
            return false;
        }
        match material.emissive_texture.map(|t| t as usize).filter(|&t| t < self.textures.len()) {
            Some(t) => {
                let (texture, texels) = (&self.textures[t], self.texels);
                self.tables[t].get_or_insert_with(|| LitTexels::new(texture, texels)).any_lit(corners)
            }
            None => true,
        }
    }
}

/// The texel indices (inclusive ranges in `0..n`, at most three) that samples at
/// coordinates between the smallest and largest of `c` can read along one axis.
fn axis_spans(wrap: Wrap, c: [f32; 3], n: i64) -> [Option<(i64, i64)>; 3] {
    let whole = [Some((0, n - 1)), None, None];
    let (lo, hi) = (
        c.iter().fold(f64::INFINITY, |a, &b| a.min(b as f64)),
        c.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b as f64)),
    );
    // Not finite, or so large that f32's spacing exceeds a texel: every texel.
    if !(lo.is_finite() && hi.is_finite()) || lo.abs().max(hi.abs()) >= (1u64 << 22) as f64 {
        return whole;
    }
    let (first, last) = ((lo * n as f64).floor() as i64 - 1, (hi * n as f64).floor() as i64 + 1);
    if wrap == Wrap::ClampToEdge {
        return [Some((first.clamp(0, n - 1), last.clamp(0, n - 1))), None, None];
    }
    let period = if wrap == Wrap::Repeat { n } else { 2 * n };
    if last - first + 1 >= period {
        return whole;
    }
    // Split where a period of `n` texels ends: within one, `wrap_index` is monotone.
    let mut out = [None; 3];
    let mut start = first;
    for slot in &mut out {
        if start > last {
            break;
        }
        let end = last.min(start.div_euclid(n) * n + n - 1);
        let (a, b) = (wrap_index(wrap, start, n), wrap_index(wrap, end, n));
        *slot = Some((a.min(b), a.max(b)));
        start = end + 1;
    }
    out
}
