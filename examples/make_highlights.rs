//! Draw the highlight images of the shipped highlight examples, so that they can be reproduced: a
//! five-pointed star and a ring, as seen on the screen of `brdf::highlight`'s configuration.
//!
//! `cargo run --release --example make_highlights -- DIR [SOFT_DEG]` writes `DIR/star.png` and
//! `DIR/ring.png` (256 × 256, 8-bit grey, sRGB-encoded); `SOFT_DEG` overrides [`SOFT_DEG`] (0 draws hard
//! edges). Shapes are given in degrees of reflection for an image whose
//! edges' middles are at [`EXTENT_DEG`] of reflection; each pixel is the shape's coverage of 4 × 4 sub-pixels,
//! softened by a Gaussian of [`SOFT_DEG`]: a highlight on metal has soft edges (the default job's polish
//! lobe alone, Beckmann α = 0.06, blurs reflection by about 4.8° rms), and no cut of that material could
//! show a sharper one.

use std::path::Path;

/// The extent the images are drawn for (the examples' `target.highlight_extent_deg`).
pub const EXTENT_DEG: f64 = 30.0;

/// σ of the Gaussian that softens the shapes' edges, degrees of reflection (at the image's centre).
pub const SOFT_DEG: f64 = 2.5;

/// Side of the images, pixels.
pub const SIDE_PX: usize = 256;

/// Which shape.
#[derive(Clone, Copy)]
pub enum Shape {
    /// Five points, the tips at `outer_deg` of reflection, the valleys at `inner_deg`, one tip up.
    Star { outer_deg: f64, inner_deg: f64 },
    /// Between two angles of reflection.
    Ring { inner_deg: f64, outer_deg: f64 },
}

/// The shipped shapes and their file names.
pub const SHAPES: [(&str, Shape); 2] = [
    (
        "star.png",
        Shape::Star {
            outer_deg: 26.0,
            inner_deg: 12.0,
        },
    ),
    (
        "ring.png",
        Shape::Ring {
            inner_deg: 10.0,
            outer_deg: 22.0,
        },
    ),
];

impl Shape {
    /// Whether the screen point `(x, y)` (units of the screen's distance) is inside.
    fn contains(self, x: f64, y: f64) -> bool {
        let theta = x.hypot(y).atan().to_degrees();
        match self {
            Shape::Ring { inner_deg, outer_deg } => theta >= inner_deg && theta <= outer_deg,
            Shape::Star { outer_deg, inner_deg } => {
                // a star polygon: the boundary's polar radius (in tan units) between tip and valley is the
                // straight edge joining them
                let sector = std::f64::consts::TAU / 5.0;
                let phi = (y.atan2(x) - std::f64::consts::FRAC_PI_2).rem_euclid(sector);
                let a = (phi - sector / 2.0).abs(); // 0 at a valley, sector/2 at a tip
                let (rt, rv) = (outer_deg.to_radians().tan(), inner_deg.to_radians().tan());
                // tip at angle sector/2 from the valley direction: line through (rv, 0) and (rt cos h, rt sin h)
                let h = sector / 2.0;
                let (tx, ty) = (rt * h.cos(), rt * h.sin());
                // ray at angle a from the valley direction meets that line at radius r
                let (dx, dy) = (tx - rv, ty);
                let r = (rv * dy) / (a.cos() * dy - a.sin() * dx);
                x.hypot(y) <= r
            }
        }
    }
}

/// Draw a shape with edges softened by σ = `soft_deg`: 8-bit grey values, top row first.
pub fn draw(shape: Shape, soft_deg: f64) -> Vec<u8> {
    let t = EXTENT_DEG.to_radians().tan() / (SIDE_PX as f64 / 2.0);
    let mut cover = vec![0.0; SIDE_PX * SIDE_PX];
    for row in 0..SIDE_PX {
        for col in 0..SIDE_PX {
            let mut n = 0;
            for b in 0..4 {
                for a in 0..4 {
                    let x = (col as f64 + (a as f64 + 0.5) / 4.0 - SIDE_PX as f64 / 2.0) * t;
                    let y = (SIDE_PX as f64 / 2.0 - row as f64 - (b as f64 + 0.5) / 4.0) * t;
                    n += shape.contains(x, y) as u32;
                }
            }
            cover[row * SIDE_PX + col] = n as f64 / 16.0;
        }
    }
    let soft = if soft_deg > 0.0 {
        blur(&cover, soft_deg.to_radians() / t)
    } else {
        cover
    };
    // coverage is linear light; the file is sRGB-encoded
    soft.iter()
        .map(|&c| {
            let c = c.clamp(0.0, 1.0);
            let e = if c <= 0.0031308 {
                12.92 * c
            } else {
                1.055 * c.powf(1.0 / 2.4) - 0.055
            };
            (e * 255.0).round() as u8
        })
        .collect()
}

/// A separable Gaussian blur of σ `sigma_px` pixels, zero beyond the image.
fn blur(v: &[f64], sigma_px: f64) -> Vec<f64> {
    let r = (3.0 * sigma_px).ceil() as isize;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma_px * sigma_px)).exp())
        .collect();
    let sum: f64 = k.iter().sum();
    let n = SIDE_PX as isize;
    let pass = |src: &[f64], horizontal: bool| -> Vec<f64> {
        let mut out = vec![0.0; src.len()];
        for a in 0..n {
            for b in 0..n {
                let mut acc = 0.0;
                for (o, w) in (-r..=r).zip(&k) {
                    let c = b + o;
                    if (0..n).contains(&c) {
                        let idx = if horizontal { a * n + c } else { c * n + a };
                        acc += w * src[idx as usize];
                    }
                }
                let idx = if horizontal { a * n + b } else { b * n + a };
                out[idx as usize] = acc / sum;
            }
        }
        out
    };
    pass(&pass(v, true), false)
}

/// Encode grey values as a PNG.
pub fn png(grey: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut e = png::Encoder::new(&mut bytes, SIDE_PX as u32, SIDE_PX as u32);
    e.set_color(png::ColorType::Grayscale);
    e.set_depth(png::BitDepth::Eight);
    e.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    e.write_header()
        .and_then(|mut w| w.write_image_data(grey))
        .expect("encoding to memory");
    bytes
}

#[allow(dead_code)]
fn main() -> anyhow::Result<()> {
    let usage = "usage: make_highlights DIR [SOFT_DEG]";
    let dir = std::env::args().nth(1).ok_or_else(|| anyhow::anyhow!(usage))?;
    let soft = match std::env::args().nth(2) {
        Some(s) => s
            .parse::<f64>()
            .ok()
            .filter(|v| *v >= 0.0 && *v <= 20.0)
            .ok_or_else(|| anyhow::anyhow!("SOFT_DEG `{s}` is not in [0, 20]; {usage}"))?,
        None => SOFT_DEG,
    };
    for (name, shape) in SHAPES {
        let path = Path::new(&dir).join(name);
        brdfmill::base::io::write_atomic(&path, &png(&draw(shape, soft)))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
