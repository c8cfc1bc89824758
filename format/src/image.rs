//! PNG and JPEG images for textures: decoded to 8-bit RGBA, within a size limit
//! checked before the pixels are allocated.
//!
//! The bake decodes a glTF's images with these functions, and a baked scene that keeps
//! an image encoded (see [`crate::Encoded`]) is decoded with the same ones when its
//! texels are first read, so both see the same pixels (and a hash of them, taken at
//! bake, checks it).

use crate::texture::{ImageKind, Texture, MAX_TEXTURE_SIDE};

/// Texels a scene may hold in all (1 GiB of texel data): a bound on what a small file
/// of many images can make the bake, or the decoding of a baked scene's images,
/// allocate.
pub const MAX_SCENE_TEXELS: usize = 1 << 28;

/// A decoded image: `width * height` RGBA pixels, rows top to bottom.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rgba8 {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `r, g, b, a`, 8 bits each, row after row.
    pub pixels: Vec<[u8; 4]>,
}

/// What an encoded image is: [`ImageKind::Png`] or [`ImageKind::Jpeg`] by its
/// signature, whatever a file's MIME type says; `None` for anything else.
pub fn kind(bytes: &[u8]) -> Option<ImageKind> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some(ImageKind::Png)
    } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        Some(ImageKind::Jpeg)
    } else {
        None
    }
}

/// An encoded image's kind and size in pixels, read from its header alone (no pixel
/// is decoded).
///
/// # Errors
/// A message for an image that is neither a PNG nor a JPEG, or whose header cannot be
/// read.
pub fn dimensions(bytes: &[u8]) -> Result<(ImageKind, u32, u32), String> {
    match kind(bytes) {
        Some(ImageKind::Png) => {
            let reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().map_err(|e| format!("PNG: {e}"))?;
            Ok((ImageKind::Png, reader.info().width, reader.info().height))
        }
        Some(ImageKind::Jpeg) => {
            let mut decoder = zune_jpeg::JpegDecoder::new(zune_core::bytestream::ZCursor::new(bytes));
            decoder.decode_headers().map_err(|e| format!("JPEG: {e}"))?;
            let info = decoder.info().ok_or("JPEG: no image header")?;
            Ok((ImageKind::Jpeg, u32::from(info.width), u32::from(info.height)))
        }
        None => Err("neither a PNG nor a JPEG image".into()),
    }
}

/// Pixels an image may decode to per byte of its encoding, beyond
/// [`PIXELS_SLACK`]: real textures compress 3 to 20 times; a flat image declaring
/// thousands of pixels per byte is a bomb.
pub const PIXELS_PER_ENCODED_BYTE: usize = 256;
/// Pixels any image may have whatever its encoded size (a 2048 x 2048 texture).
pub const PIXELS_SLACK: usize = 1 << 22;

/// Decodes a PNG or JPEG (told apart by their signatures, whatever the file's MIME
/// type says), if its declared size is at most `max_pixels` and
/// [`PIXELS_PER_ENCODED_BYTE`] times its encoding (plus [`PIXELS_SLACK`]): checked
/// from the header, before the pixels are allocated.
///
/// # Errors
/// A message for an image of another format, a malformed one, or one larger than
/// [`MAX_TEXTURE_SIDE`] on a side or than the limits.
///
/// A decoder that panics on a malformed image (the `png` crate did on an animated PNG
/// whose first frame is smaller than the image) is a malformed image too: its panic
/// becomes this error, and the caller goes on.
pub fn decode(bytes: &[u8], max_pixels: usize) -> Result<Rgba8, String> {
    let limit = max_pixels.min(bytes.len().saturating_mul(PIXELS_PER_ENCODED_BYTE).saturating_add(PIXELS_SLACK));
    let kind = kind(bytes);
    std::panic::catch_unwind(|| match kind {
        Some(ImageKind::Png) => png(bytes, limit),
        Some(ImageKind::Jpeg) => jpeg(bytes, limit),
        None => Err("neither a PNG nor a JPEG image".into()),
    })
    .unwrap_or_else(|_| Err(format!("malformed {} (its decoder gave up)", kind.map_or("image", |k| k.name()))))
}

fn check_size(width: usize, height: usize, limit: usize) -> Result<(), String> {
    let side = MAX_TEXTURE_SIDE as usize;
    if width == 0 || height == 0 || width > side || height > side {
        return Err(format!("{width} x {height} pixels; textures may have 1 to {side} a side"));
    }
    if width * height > limit {
        return Err(format!(
            "{width} x {height} pixels, more than the {limit} allowed (the scene's texel budget, or \
             {PIXELS_PER_ENCODED_BYTE} a byte of the encoded image)"
        ));
    }
    Ok(())
}

fn png(bytes: &[u8], limit: usize) -> Result<Rgba8, String> {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().map_err(|e| format!("PNG: {e}"))?;
    let (width, height) = (reader.info().width as usize, reader.info().height as usize);
    check_size(width, height, limit)?;
    let mut buffer = vec![0; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut buffer).map_err(|e| format!("PNG: {e}"))?;
    // An animated PNG's first frame, when it is the image, is the image's size (APNG:
    // the default image's fcTL must match IHDR).
    if (frame.width as usize, frame.height as usize) != (width, height) {
        return Err(format!(
            "PNG: an animated PNG whose first frame ({} x {}) is not the whole image ({width} x {height})",
            frame.width, frame.height
        ));
    }
    let data = &buffer[..frame.buffer_size()];
    let channels = match frame.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => return Err("PNG: palette left unexpanded".into()),
    };
    let row = frame.line_size;
    let mut pixels = Vec::with_capacity(width * height);
    for y in 0..height {
        for p in data[y * row..][..width * channels].chunks_exact(channels) {
            pixels.push(match *p {
                [g] => [g, g, g, 255],
                [g, a] => [g, g, g, a],
                [r, g, b] => [r, g, b, 255],
                [r, g, b, a] => [r, g, b, a],
                _ => unreachable!("chunks of 1 to 4 bytes"),
            });
        }
    }
    Ok(Rgba8 { width: width as u32, height: height as u32, pixels })
}

fn jpeg(bytes: &[u8], limit: usize) -> Result<Rgba8, String> {
    use zune_core::{bytestream::ZCursor, colorspace::ColorSpace, options::DecoderOptions};
    let side = MAX_TEXTURE_SIDE as usize;
    let options =
        DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGBA).set_max_width(side).set_max_height(side);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    decoder.decode_headers().map_err(|e| format!("JPEG: {e}"))?;
    let info = decoder.info().ok_or("JPEG: no image header")?;
    let (width, height) = (info.width as usize, info.height as usize);
    check_size(width, height, limit)?;
    // A file cut short: the decoder would fill what is missing with grey. A JPEG ends
    // with its end-of-image marker after its (last) scan; anything may follow it.
    let scan = bytes.windows(2).rposition(|w| w == [0xFF, 0xDA]);
    if scan.is_none_or(|at| !bytes[at..].windows(2).any(|w| w == [0xFF, 0xD9])) {
        return Err(format!("JPEG: cut short ({} bytes, no end-of-image marker after its scan)", bytes.len()));
    }
    // Every 8 x 8 block of luma costs a bit at least (its DC code, in any JPEG mode): a
    // header that claims more blocks than the file has bits is a lie the decoder would
    // fill with grey.
    let blocks = width.div_ceil(8) * height.div_ceil(8);
    if blocks > 8 * bytes.len() {
        return Err(format!(
            "JPEG: the header says {width} x {height} pixels ({blocks} blocks), more than its {} bytes can hold \
             (a bit a block at least)",
            bytes.len()
        ));
    }
    let data = decoder.decode().map_err(|e| format!("JPEG: {e}"))?;
    if data.len() != width * height * 4 {
        return Err(format!("JPEG: {} bytes decoded for {width} x {height} pixels", data.len()));
    }
    let pixels = data.chunks_exact(4).map(|p| [p[0], p[1], p[2], p[3]]).collect();
    Ok(Rgba8 { width: width as u32, height: height as u32, pixels })
}

/// Reading a texture's encoded image lives here, beside the header readers it calls,
/// so that `texture` (the records) does not depend on `image` (the codecs' headers).
impl Texture {
    /// The bytes of the texture's encoded image in the scene's `images`, once its
    /// header (read, not decoded) says the kind and size the record says.
    ///
    /// # Errors
    /// A message (without the texture's name) for a texture that is not encoded, an
    /// image past `images`, a header that cannot be read, or another kind or size.
    pub fn encoded_image<'a>(&self, images: &'a [u8]) -> Result<&'a [u8], String> {
        let e = self.encoded.as_ref().ok_or("not encoded")?;
        let bytes = usize::try_from(e.offset)
            .ok()
            .zip(usize::try_from(e.bytes).ok())
            .and_then(|(at, n)| images.get(at..at.checked_add(n)?))
            .ok_or_else(|| {
                format!(
                    "its image ({} bytes from {}) runs past the {} bytes of images",
                    e.bytes,
                    e.offset,
                    images.len()
                )
            })?;
        let (kind, width, height) = dimensions(bytes)?;
        self.same_image(kind, width, height)?;
        Ok(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 130 bytes: IHDR 64 x 64, acTL, an fcTL of 8 x 8 for the default image, IDAT of
    /// 8 x 8 pixels (the audit's APNG, rebuilt). Decoding it panicked.
    const APNG: &str = "89504e470d0a1a0a0000000d4948445200000040000000400802000000250be689000000086163544c\
        0000000100000000b42de9a00000001a6663544c0000000000000008000000080000000000000000000100010000fe1b5583\
        0000000f49444154789c6368c001188696040082f360019cee0f240000000049454e44ae426082";

    fn bytes(hex: &str) -> Vec<u8> {
        let hex: Vec<u8> = hex.bytes().filter(u8::is_ascii_hexdigit).collect();
        hex.chunks(2).map(|c| u8::from_str_radix(std::str::from_utf8(c).unwrap(), 16).unwrap()).collect()
    }

    #[test]
    fn an_animated_png_whose_first_frame_is_smaller_is_an_error() {
        let apng = bytes(APNG);
        assert_eq!(apng.len(), 130);
        let why = decode(&apng, 1 << 20).unwrap_err();
        assert!(why.contains("first frame (8 x 8) is not the whole image (64 x 64)"), "{why}");
    }
}
