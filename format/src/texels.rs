//! A scene's texel array: the texels stored in the file, then the texels of the images
//! kept encoded, decoded the first time anything reads them.
//!
//! Opening a scene decodes nothing (a validated open reads the images' headers only),
//! so a scene whose textures are never sampled (tracing without alpha cut-outs) never
//! pays for them; the first render, or the first texture lookup, decodes every encoded
//! image once, on as many threads as there are images and cores.

use std::sync::OnceLock;

use crate::image::MAX_SCENE_TEXELS;
use crate::texture::{texels_hash, Texture, TEXEL_WORDS};

/// The decoded texels of a scene's encoded images, made once; owned by the
/// [`crate::SceneFile`] or [`crate::BakedScene`] the views borrow from. Cloning one
/// gives an empty cache (the texels are decoded again when needed).
#[derive(Default)]
pub struct TexelCache(OnceLock<Decoded>);

impl TexelCache {
    /// An empty cache.
    pub const fn new() -> Self {
        TexelCache(OnceLock::new())
    }
}

impl Clone for TexelCache {
    fn clone(&self) -> Self {
        TexelCache::new()
    }
}

impl PartialEq for TexelCache {
    /// Always: the cache holds what the scene's own data decode to.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for TexelCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let state = match self.0.get() {
            None => "not decoded",
            Some(d) if d.error.is_some() => "decoded, with an error",
            Some(_) => "decoded",
        };
        f.write_str(state)
    }
}

/// The stored texels followed by the decoded images', and the first image that could
/// not be decoded (its texels read as white).
struct Decoded {
    texels: Vec<u32>,
    error: Option<String>,
}

/// A scene's texel array, as [`crate::Texture::first`] indexes it: the `texels`
/// section's words, then, texture after texture, the texels of each image kept
/// encoded ([`crate::Encoded`]), decoded the first time [`Texels::get`] or
/// [`Texels::check`] asks for them.
///
/// # Example
/// ```
/// # let scene = octrace_format::testing::single_leaf_scene();
/// let view = scene.view();
/// assert!(!view.texels.has_encoded()); // every texel stored: nothing to decode
/// assert_eq!(view.texels.check()?, view.texels.stored());
/// # Ok::<(), octrace_format::Error>(())
/// ```
#[derive(Clone, Copy)]
pub struct Texels<'a> {
    stored: &'a [u32],
    images: &'a [u8],
    textures: &'a [Texture],
    cache: &'a TexelCache,
}

impl std::fmt::Debug for Texels<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Texels")
            .field("stored", &self.stored.len())
            .field("images", &self.images.len())
            .field("decoded", self.cache)
            .finish()
    }
}

impl<'a> Texels<'a> {
    /// The texel array of `textures`: `stored` words, and the encoded images in
    /// `images`, decoded into `cache`.
    pub fn new(stored: &'a [u32], images: &'a [u8], textures: &'a [Texture], cache: &'a TexelCache) -> Self {
        Texels { stored, images, textures, cache }
    }

    /// The words of the `texels` section alone.
    pub fn stored(&self) -> &'a [u32] {
        self.stored
    }

    /// The bytes of the encoded images.
    pub fn images(&self) -> &'a [u8] {
        self.images
    }

    /// Whether some texture's image is kept encoded (so [`Texels::get`] decodes).
    pub fn has_encoded(&self) -> bool {
        self.textures.iter().any(|t| t.encoded.is_some())
    }

    /// Whether the encoded images have been decoded (or there are none).
    pub fn is_decoded(&self) -> bool {
        !self.has_encoded() || self.cache.0.get().is_some()
    }

    /// Texels the whole array holds, decoded images included (nothing is decoded).
    pub fn len(&self) -> u64 {
        let encoded = self.textures.iter().filter(|t| t.encoded.is_some());
        self.stored.len() as u64 + encoded.map(|t| t.width as u64 * t.height as u64).sum::<u64>()
    }

    /// Whether the array is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The whole texel array, decoding the encoded images the first time. An image
    /// that cannot be decoded, or decodes to other texels than the bake's, reads as
    /// white ([`Texels::check`] says which and why).
    pub fn get(&self) -> &'a [u32] {
        if !self.has_encoded() {
            return self.stored;
        }
        &self.cache.0.get_or_init(|| decode(self.stored, self.images, self.textures)).texels
    }

    /// The whole texel array, as [`Texels::get`]; an error when an encoded image
    /// could not be decoded.
    ///
    /// # Errors
    /// [`crate::Error::Corrupt`] naming the first texture whose image is damaged, of
    /// another size than its record says, or decodes to texels whose hash differs
    /// from the bake's.
    pub fn check(&self) -> crate::Result<&'a [u32]> {
        let texels = self.get();
        match self.cache.0.get().and_then(|d| d.error.as_deref()) {
            Some(why) if self.has_encoded() => Err(crate::Error::corrupt(why.to_string())),
            _ => Ok(texels),
        }
    }
}

/// Decodes every encoded image into one array after `stored` (on up to one thread a
/// core).
fn decode(stored: &[u32], images: &[u8], textures: &[Texture]) -> Decoded {
    let encoded: Vec<&Texture> = textures.iter().filter(|t| t.encoded.is_some()).collect();
    let total = encoded.iter().map(|t| t.width as u64 * t.height as u64).sum::<u64>();
    // The validated open refuses more; the trusted path must not allocate it either.
    if total > MAX_SCENE_TEXELS as u64 {
        let why = format!("the encoded images hold {total} texels, more than the {MAX_SCENE_TEXELS} a scene may have");
        return Decoded { texels: stored.to_vec(), error: Some(why) };
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(encoded.len()).max(1);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut results: Vec<Option<Result<Vec<u32>, String>>> = vec![None; encoded.len()];
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(t) = encoded.get(i) else { break done };
                        // A panic decoding one image is that image's error; the worker
                        // keeps what it decoded and goes on.
                        let one = std::panic::catch_unwind(|| decode_one(t, images))
                            .unwrap_or_else(|_| Err("its decoder gave up (a malformed image)".into()));
                        done.push((i, one));
                    }
                })
            })
            .collect();
        for worker in workers {
            // A decoder that panicked leaves its images undecoded (white, with an error).
            for (i, result) in worker.join().unwrap_or_default() {
                results[i] = Some(result);
            }
        }
    });
    let mut texels = Vec::with_capacity(stored.len() + total as usize * TEXEL_WORDS);
    texels.extend_from_slice(stored);
    let mut error = None;
    for (t, result) in encoded.iter().zip(results) {
        match result.unwrap_or_else(|| Err("its decoder stopped".into())) {
            Ok(words) => texels.extend_from_slice(&words),
            Err(why) => {
                texels.resize(texels.len() + t.width as usize * t.height as usize, u32::MAX);
                error.get_or_insert_with(|| format!("texture '{}': {why}", t.name));
            }
        }
    }
    Decoded { texels, error }
}

/// One texture's image decoded, checked against its record.
fn decode_one(t: &Texture, images: &[u8]) -> Result<Vec<u32>, String> {
    let e = t.encoded.as_ref().ok_or("not encoded")?;
    let bytes = t.encoded_image(images)?;
    let rgba = crate::image::decode(bytes, (t.width as usize).saturating_mul(t.height as usize))?;
    t.same_image(e.kind, rgba.width, rgba.height)?;
    let words: Vec<u32> = rgba.pixels.into_iter().map(u32::from_le_bytes).collect();
    let hash = texels_hash(&words);
    if hash != e.texels_hash {
        return Err(format!(
            "its {} decodes to other texels than at bake (hash {hash:016x}, the bake's {:016x}): the image was \
             altered, or this build's decoder differs from the bake's",
            e.kind.name(),
            e.texels_hash
        ));
    }
    Ok(words)
}
