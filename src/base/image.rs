//! PNG images read as input (a drawn highlight, an svBRDF label map): one decoder with the checks every
//! reader of a user's image needs — the signature, a size cap, a single frame — before any pixel is used.

use crate::base::Invalid;
/// The longest side accepted, pixels (a bound on the work before it starts).
pub const MAX_SIDE_PX: u32 = 4096;

/// A decoded image: 8-bit samples, `channels` per pixel (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA), rows top
/// first, no padding.
pub struct Image8 {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Samples per pixel.
    pub channels: usize,
    /// `width · height · channels` samples.
    pub data: Vec<u8>,
}

impl Image8 {
    /// The samples of pixel `(col, row)` (row 0 at the top).
    pub fn pixel(&self, col: usize, row: usize) -> &[u8] {
        let k = (row * self.width + col) * self.channels;
        &self.data[k..k + self.channels]
    }

    /// Pixel `(col, row)` as `[r, g, b]` (grey repeated; alpha ignored).
    pub fn rgb(&self, col: usize, row: usize) -> [u8; 3] {
        let px = self.pixel(col, row);
        match self.channels {
            1 | 2 => [px[0]; 3],
            _ => [px[0], px[1], px[2]],
        }
    }
}

/// Decode a PNG (8-bit or 16-bit, any colour type; palettes expanded, 16 bits stripped to 8). Refuses what
/// is not a PNG, a truncated or corrupt one, one larger than [`MAX_SIDE_PX`] per side, and an animated one.
pub fn decode_png(bytes: &[u8]) -> Result<Image8, Invalid> {
    if !bytes.starts_with(&[0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a]) {
        return Err(Invalid(
            "not a PNG image (it does not start with the PNG signature)".into(),
        ));
    }
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(|e| format!("not a readable PNG: {e}"))?;
    let (w, h) = (reader.info().width, reader.info().height);
    if w > MAX_SIDE_PX || h > MAX_SIDE_PX {
        return Err(Invalid(format!(
            "the image is {w} × {h} pixels; at most {MAX_SIDE_PX} per side is accepted"
        )));
    }
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("the PNG's image data cannot be decoded: {e}"))?;
    if (frame.width, frame.height) != (w, h) {
        return Err(Invalid(format!(
            "an animated PNG (its first frame is {} × {} of {w} × {h}): give a single image",
            frame.width, frame.height
        )));
    }
    let channels = frame.color_type.samples();
    if !(1..=4).contains(&channels) {
        return Err(Invalid(format!("unexpected {channels} samples per pixel")));
    }
    let (w, h) = (w as usize, h as usize);
    let line = frame.line_size;
    let mut data = Vec::with_capacity(w * h * channels);
    for r in 0..h {
        data.extend_from_slice(&buf[r * line..r * line + w * channels]);
    }
    Ok(Image8 {
        width: w,
        height: h,
        channels,
        data,
    })
}
