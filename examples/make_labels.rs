//! Draw the label image of the shipped svBRDF example, so that it can be reproduced: a disc (the logo) on
//! a field, black on white, one pixel per 0.1 mm of the example's 19.2 × 14.4 mm work area.
//!
//! `cargo run --release --example make_labels -- DIR` writes `DIR/logo.png` (192 × 144, 8-bit RGB). A label
//! image has no anti-aliasing: every pixel is exactly one region's colour, the one at its centre.

use std::path::Path;

/// Width and height, pixels.
pub const SIZE_PX: (usize, usize) = (192, 144);

/// The work area the image spans, mm.
pub const AREA_MM: (f64, f64) = (19.2, 14.4);

/// The disc: centre and radius, mm.
pub const DISC_MM: (f64, f64, f64) = (9.6, 7.2, 4.6);

/// RGB pixels, top row first: black inside the disc, white outside.
pub fn draw() -> Vec<u8> {
    let (w, h) = SIZE_PX;
    let mm = AREA_MM.0 / w as f64;
    let (cx, cy, r) = DISC_MM;
    let mut px = Vec::with_capacity(w * h * 3);
    for row in 0..h {
        for col in 0..w {
            let (x, y) = ((col as f64 + 0.5) * mm, AREA_MM.1 - (row as f64 + 0.5) * mm);
            let v = if (x - cx).hypot(y - cy) <= r { 0 } else { 255 };
            px.extend_from_slice(&[v, v, v]);
        }
    }
    px
}

/// `draw()` as PNG bytes.
pub fn png_bytes() -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut e = png::Encoder::new(&mut out, SIZE_PX.0 as u32, SIZE_PX.1 as u32);
        e.set_color(png::ColorType::Rgb);
        e.set_depth(png::BitDepth::Eight);
        let mut w = e.write_header().expect("PNG header");
        w.write_image_data(&draw()).expect("PNG data");
    }
    out
}

#[allow(dead_code)]
fn main() {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "examples/data".into());
    let path = Path::new(&dir).join("logo.png");
    if let Err(e) = std::fs::write(&path, png_bytes()) {
        eprintln!("make_labels: cannot write {}: {e}", path.display());
        std::process::exit(1);
    }
    println!("wrote {}", path.display());
}
