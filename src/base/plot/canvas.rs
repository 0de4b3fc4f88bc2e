//! [`Canvas`]: a figure being drawn, in two layers — raster pixels (the colour maps, colour bars, rendered
//! spheres) and vector marks (text, axes, ticks, curves) — so that one drawing gives both a PNG file and an
//! SVG whose text is text.
//!
//! The SVG ([`Canvas::to_svg`]) keeps the marks as `<text>` and `<path>` elements, set in the reader's own
//! sans-serif font at 11 px, over the raster layer embedded once as a PNG (omitted when it is blank). The
//! PNG ([`Canvas::to_png`]) draws the same marks into the pixels with `embedded-graphics`' built-in bitmap
//! fonts, which need no font files on the user's machine. Layout uses one estimate for both: 6 px a
//! character, the bitmap font's cell and about the mean advance of a sans-serif face at 11 px.

use base64::Engine;
use embedded_graphics::{
    mono_font::{iso_8859_1::FONT_6X10, iso_8859_7::FONT_6X10 as GREEK_6X10, MonoTextStyle},
    pixelcolor::Rgb888,
    prelude::*,
    primitives::{Line, PrimitiveStyle},
    text::{Alignment, Text},
};
use std::path::Path;

/// Width of one character in the layout, pixels (see the module's doc).
pub const CHAR_PX: i32 = 6;

/// Font size of the SVG's text, pixels.
const FONT_PX: u32 = 11;

/// Dashes of a dashed mark, pixels on and off.
pub const DASH_PX: (f64, f64) = (6.0, 4.0);

/// Greek letters, which the ISO 8859-7 font draws.
fn is_greek(c: char) -> bool {
    ('\u{0391}'..='\u{03C9}').contains(&c)
}

/// Text as the bitmap fonts can draw it: Latin-1 and Greek letters as they are, the mathematical signs of
/// the figures' titles spelt in ASCII (`−` → `-`, `⊛` → `*`, `≤` → `<=`, …), anything else as `?`.
#[must_use]
pub fn glyph_text(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            c if u32::from(c) <= 0xFF || is_greek(c) => out.push(c),
            '−' | '–' | '—' => out.push('-'),
            '⊛' | '∗' | '⋆' => out.push('*'),
            '≤' => out.push_str("<="),
            '≥' => out.push_str(">="),
            '≈' | '∼' => out.push('~'),
            '→' => out.push_str("->"),
            '←' => out.push_str("<-"),
            '…' => out.push_str("..."),
            '‘' | '’' | '′' => out.push('\''),
            '“' | '”' | '″' => out.push('"'),
            '∞' => out.push_str("inf"),
            '√' => out.push_str("sqrt"),
            _ => out.push('?'),
        }
    }
    out
}

/// The left edge of text `width` pixels wide anchored at `x` with `align`.
fn left_edge(x: i32, width: i32, align: Alignment) -> i32 {
    match align {
        Alignment::Left => x,
        Alignment::Center => x - width / 2,
        Alignment::Right => x - width,
    }
}

/// A vector mark on a [`Canvas`].
#[derive(Clone, Debug, PartialEq)]
pub enum Mark {
    /// Black text, its baseline at `y`; `x` is the anchor of `align`, already moved so that the estimated
    /// extent stays inside the canvas.
    Text {
        /// Anchor, pixels from the left.
        x: i32,
        /// Baseline, pixels from the top.
        y: i32,
        /// The text.
        text: String,
        /// Which end (or the middle) of the text sits at `x`.
        align: Alignment,
    },
    /// A polyline through pixel centres.
    Path {
        /// Vertices, pixels.
        points: Vec<(i32, i32)>,
        /// Colour.
        color: [u8; 3],
        /// Stroke width, pixels.
        width: u32,
        /// Dashed ([`DASH_PX`]), the pattern running on across vertices.
        dashed: bool,
    },
}

/// A figure being drawn: raster pixels and vector marks (see the module's doc).
#[derive(Clone, Debug)]
pub struct Canvas {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The raster layer: row-major RGB pixels, top row first (marks are not in it; see
    /// [`Canvas::rasterized`]).
    pub pixels: Vec<[u8; 3]>,
    /// The vector layer, drawn over the pixels in order.
    pub marks: Vec<Mark>,
    /// Labels that could not be drawn as given: a character with no glyph in the PNG's bitmap font (drawn
    /// as `?` there) or text wider than the canvas (cut at its edges). Kept so that a report can say so
    /// and a test can fail on it.
    pub label_defects: Vec<String>,
}

impl OriginDimensions for Canvas {
    fn size(&self) -> Size {
        Size::new(self.width, self.height)
    }
}

impl DrawTarget for Canvas {
    type Color = Rgb888;
    type Error = std::convert::Infallible;

    fn draw_iter<I>(&mut self, pixels: I) -> Result<(), Self::Error>
    where
        I: IntoIterator<Item = Pixel<Self::Color>>,
    {
        for Pixel(p, c) in pixels {
            self.put(i64::from(p.x), i64::from(p.y), [c.r(), c.g(), c.b()]);
        }
        Ok(())
    }
}

const BLACK: [u8; 3] = [0, 0, 0];
const WHITE: [u8; 3] = [255, 255, 255];

impl Canvas {
    /// A white canvas.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![WHITE; (width * height) as usize],
            marks: vec![],
            label_defects: vec![],
        }
    }

    /// Set one raster pixel (ignored outside the canvas).
    #[inline]
    pub fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            self.pixels[y as usize * self.width as usize + x as usize] = c;
        }
    }

    /// Text with its anchor at `(x, y)` (baseline), aligned left, centre or right. Text whose estimated
    /// extent ([`CHAR_PX`] a character) would run past the left or right edge is moved inside; text wider
    /// than the canvas or reaching past its top or bottom, and characters the PNG's bitmap fonts lack
    /// ([`glyph_text`]), are recorded in [`Canvas::label_defects`].
    pub fn text(&mut self, x: i32, y: i32, s: &str, align: Alignment) {
        let drawn = glyph_text(s);
        if drawn.matches('?').count() > s.matches('?').count() {
            self.label_defects.push(format!("missing glyph in {s:?}"));
        }
        let width = drawn.chars().count() as i32 * CHAR_PX;
        let left = left_edge(x, width, align);
        let moved = left.min(self.width as i32 - width).max(0);
        let top = y - FONT_6X10.baseline as i32;
        let h = FONT_6X10.character_size.height as i32;
        if moved + width > self.width as i32 || top < 0 || top + h > self.height as i32 {
            self.label_defects.push(format!("clipped label {s:?}"));
        }
        self.marks.push(Mark::Text {
            x: x + moved - left,
            y,
            text: s.to_string(),
            align,
        });
    }

    /// A one-pixel black line.
    pub fn line(&mut self, x0: i32, y0: i32, x1: i32, y1: i32) {
        self.path(vec![(x0, y0), (x1, y1)], BLACK, 1, false);
    }

    /// A polyline of `width` pixels, solid or dashed.
    pub fn path(&mut self, points: Vec<(i32, i32)>, color: [u8; 3], width: u32, dashed: bool) {
        if points.len() >= 2 {
            self.marks.push(Mark::Path {
                points,
                color,
                width,
                dashed,
            });
        }
    }

    /// A one-pixel black rectangle outline whose outer edge is the box `(x, y, w, h)`.
    pub fn frame(&mut self, x: i32, y: i32, w: u32, h: u32) {
        let (x1, y1) = (x + w as i32 - 1, y + h as i32 - 1);
        self.path(vec![(x, y), (x1, y), (x1, y1), (x, y1), (x, y)], BLACK, 1, false);
    }

    /// Copy another canvas in with its top-left corner at `(x, y)`: its pixels, its marks moved by as much,
    /// its label defects.
    pub fn blit(&mut self, other: &Canvas, x: i64, y: i64) {
        self.label_defects.extend(other.label_defects.iter().cloned());
        for j in 0..other.height as i64 {
            for i in 0..other.width as i64 {
                self.put(x + i, y + j, other.pixels[(j * other.width as i64 + i) as usize]);
            }
        }
        let (dx, dy) = (x as i32, y as i32);
        self.marks.extend(other.marks.iter().map(|m| match m {
            Mark::Text { x, y, text, align } => Mark::Text {
                x: x + dx,
                y: y + dy,
                text: text.clone(),
                align: *align,
            },
            Mark::Path {
                points,
                color,
                width,
                dashed,
            } => Mark::Path {
                points: points.iter().map(|p| (p.0 + dx, p.1 + dy)).collect(),
                color: *color,
                width: *width,
                dashed: *dashed,
            },
        }));
    }

    /// Panels side by side, top-aligned, on a white canvas as tall as the tallest.
    pub fn hstack(panels: &[Canvas]) -> Canvas {
        let w = panels.iter().map(|p| p.width).sum();
        let h = panels.iter().map(|p| p.height).max().unwrap_or(0);
        let mut cv = Canvas::new(w, h);
        let mut x = 0i64;
        for p in panels {
            cv.blit(p, x, 0);
            x += p.width as i64;
        }
        cv
    }

    /// The canvas with its marks drawn into the pixels (bitmap font, one- or two-pixel lines) and no marks.
    pub fn rasterized(&self) -> Canvas {
        let mut cv = Canvas {
            width: self.width,
            height: self.height,
            pixels: self.pixels.clone(),
            marks: vec![],
            label_defects: self.label_defects.clone(),
        };
        for m in &self.marks {
            match m {
                Mark::Text { x, y, text, align } => cv.raster_text(*x, *y, text, *align),
                Mark::Path {
                    points,
                    color,
                    width,
                    dashed,
                } => {
                    let mut phase = 0.0;
                    for w in points.windows(2) {
                        phase = cv.raster_segment(w[0], w[1], *color, *width, *dashed, phase);
                    }
                }
            }
        }
        cv
    }

    /// Bitmap text: Latin-1 from the ISO 8859-1 6×10 font, Greek from its ISO 8859-7 sibling, other signs
    /// spelt in ASCII ([`glyph_text`]).
    fn raster_text(&mut self, x: i32, y: i32, s: &str, align: Alignment) {
        let drawn = glyph_text(s);
        let left = left_edge(x, drawn.chars().count() as i32 * CHAR_PX, align);
        let latin = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let greek = MonoTextStyle::new(&GREEK_6X10, Rgb888::BLACK);
        let mut buf = [0u8; 4];
        for (k, c) in drawn.chars().enumerate() {
            let x = left + k as i32 * CHAR_PX;
            if c == '.' {
                // the font's full stop is a diamond reaching below the baseline, which reads as a comma in
                // tick labels ("2,5"): a 2×2 dot standing on the baseline instead
                for (dx, dy) in [(2, -1), (3, -1), (2, 0), (3, 0)] {
                    self.put(i64::from(x + dx), i64::from(y + dy), BLACK);
                }
                continue;
            }
            let style = if is_greek(c) { greek } else { latin };
            Text::with_alignment(c.encode_utf8(&mut buf), Point::new(x, y), style, Alignment::Left)
                .draw(self)
                .ok();
        }
    }

    /// One segment, solid or dashed; dashes continue across segments from `phase` (pixels into the dash
    /// pattern), and the phase at the segment's end is returned.
    fn raster_segment(
        &mut self,
        a: (i32, i32),
        b: (i32, i32),
        c: [u8; 3],
        width: u32,
        dashed: bool,
        phase: f64,
    ) -> f64 {
        let style = PrimitiveStyle::with_stroke(Rgb888::new(c[0], c[1], c[2]), width);
        let mut draw = |p: (i32, i32), q: (i32, i32)| {
            Line::new(Point::new(p.0, p.1), Point::new(q.0, q.1))
                .into_styled(style)
                .draw(self)
                .ok();
        };
        if !dashed {
            draw(a, b);
            return 0.0;
        }
        let (dx, dy) = (f64::from(b.0 - a.0), f64::from(b.1 - a.1));
        let len = dx.hypot(dy);
        let period = DASH_PX.0 + DASH_PX.1;
        let at = |t: f64| {
            let f = if len > 0.0 { t / len } else { 0.0 };
            (
                (f64::from(a.0) + f * dx).round() as i32,
                (f64::from(a.1) + f * dy).round() as i32,
            )
        };
        // walk the pattern: dash starts at multiples of the period, shifted by the phase
        let mut t = -(phase % period);
        while t < len {
            // a line's end pixels are both inked: a dash of n pixels runs from its first to its n-th
            let (on0, on1) = (t.max(0.0), (t + DASH_PX.0 - 1.0).min(len));
            if on1 >= on0 {
                draw(at(on0), at(on1));
            }
            t += period;
        }
        (phase + len) % period
    }

    /// Encode as PNG bytes, the marks drawn in.
    pub fn to_png(&self) -> Vec<u8> {
        encode_png(&self.rasterized())
    }

    /// Write as a PNG file, atomically.
    pub fn save_png(&self, path: &Path) -> Result<(), crate::base::io::WriteError> {
        crate::base::io::write_atomic(path, &self.to_png())
    }

    /// The figure as an SVG element to place inline in an HTML page (which needs no namespace declaration,
    /// and so the page names no URL): the raster layer as one embedded PNG (left out when it is all white),
    /// then the marks as `<path>` and `<text>`.
    pub fn to_svg(&self) -> String {
        let (w, h) = (self.width, self.height);
        let mut s = format!(
            "<svg width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" \
             font-family=\"'DejaVu Sans', 'Helvetica Neue', Arial, sans-serif\" font-size=\"{FONT_PX}\" role=\"img\">\
             <rect width=\"{w}\" height=\"{h}\" fill=\"#fff\"/>"
        );
        if self.pixels.iter().any(|p| *p != WHITE) {
            s.push_str(&format!(
                "<image width=\"{w}\" height=\"{h}\" style=\"image-rendering:pixelated\" href=\"data:image/png;base64,{}\"/>",
                base64::engine::general_purpose::STANDARD.encode(encode_png(self))
            ));
        }
        for m in &self.marks {
            match m {
                Mark::Path {
                    points,
                    color,
                    width,
                    dashed,
                } => {
                    // one-pixel strokes through pixel centres, as the raster draws them
                    let d: Vec<String> = points
                        .iter()
                        .enumerate()
                        .map(|(k, p)| format!("{}{}.5 {}.5", if k == 0 { "M" } else { "L" }, p.0, p.1))
                        .collect();
                    s.push_str(&format!(
                        "<path d=\"{}\" fill=\"none\" stroke=\"rgb({},{},{})\" stroke-width=\"{width}\"{}/>",
                        d.join(" "),
                        color[0],
                        color[1],
                        color[2],
                        if *dashed {
                            format!(" stroke-dasharray=\"{} {}\"", DASH_PX.0, DASH_PX.1)
                        } else {
                            String::new()
                        }
                    ));
                }
                Mark::Text { x, y, text, align } => {
                    let anchor = match align {
                        Alignment::Left => "start",
                        Alignment::Center => "middle",
                        Alignment::Right => "end",
                    };
                    s.push_str(&format!(
                        "<text x=\"{x}\" y=\"{y}\" text-anchor=\"{anchor}\">{}</text>",
                        escape_markup(text)
                    ));
                }
            }
        }
        s.push_str("</svg>");
        s
    }
}

/// Text as XML or HTML character data or attribute value: `&`, `<`, `>` and `"` escaped (the SVG's labels,
/// and the report pages that hold them).
pub fn escape_markup(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The raster layer as PNG bytes (marks not drawn).
fn encode_png(cv: &Canvas) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, cv.width, cv.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().expect("PNG header to memory");
        let flat: Vec<u8> = cv.pixels.iter().flatten().copied().collect();
        w.write_image_data(&flat).expect("PNG data to memory");
    }
    out
}
