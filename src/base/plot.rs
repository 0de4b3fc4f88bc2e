//! Figures as PNG: false-colour maps with axes, ticks, a colour bar and a title.
//!
//! Pixels are drawn into a [`Canvas`]; text and lines come from `embedded-graphics` (its built-in bitmap
//! fonts need no font files on the user's machine); colour maps from `colorous`; PNG encoding from `png`.

use embedded_graphics::{
    mono_font::{iso_8859_1::FONT_6X10, iso_8859_7::FONT_6X10 as GREEK_6X10, MonoTextStyle},
    pixelcolor::Rgb888,
    prelude::*,
    primitives::{Line, PrimitiveStyle, Rectangle},
    text::{Alignment, Text},
};
use std::path::Path;

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

/// An RGB image being drawn.
#[derive(Clone, Debug)]
pub struct Canvas {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGB pixels, top row first.
    pub pixels: Vec<[u8; 3]>,
    /// Labels that could not be drawn as given: a character with no glyph (drawn as `?`) or text wider than
    /// the canvas (cut at its edges). Kept so that a report can say so and a test can fail on it.
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
            if p.x >= 0 && p.y >= 0 && (p.x as u32) < self.width && (p.y as u32) < self.height {
                self.pixels[p.y as usize * self.width as usize + p.x as usize] = [c.r(), c.g(), c.b()];
            }
        }
        Ok(())
    }
}

const BLACK: Rgb888 = Rgb888::new(0, 0, 0);

impl Canvas {
    /// A white canvas.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![[255, 255, 255]; (width * height) as usize],
            label_defects: vec![],
        }
    }

    /// Set one pixel (ignored outside the canvas).
    #[inline]
    pub fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            self.pixels[y as usize * self.width as usize + x as usize] = c;
        }
    }

    /// Draw text with its anchor at `(x, y)` (baseline), aligned left, centre or right. Latin-1 characters
    /// come from the ISO 8859-1 bitmap font, Greek letters from its ISO 8859-7 sibling (the same 6×10 cell),
    /// and the few mathematical signs neither has are spelt in ASCII ([`glyph_text`]). Text that would run
    /// past the left or right edge is moved inside; text wider than the canvas, or with a character neither
    /// font has, is drawn as well as it can be and recorded in [`Canvas::label_defects`].
    pub fn text(&mut self, x: i32, y: i32, s: &str, align: Alignment) {
        let drawn = glyph_text(s);
        let missing = drawn.matches('?').count() > s.matches('?').count();
        let n = drawn.chars().count() as i32;
        let w = FONT_6X10.character_size.width as i32;
        let width = n * w;
        let left = match align {
            Alignment::Left => x,
            Alignment::Center => x - width / 2,
            Alignment::Right => x - width,
        };
        let left = left.min(self.width as i32 - width).max(0);
        if missing {
            self.label_defects.push(format!("missing glyph in {s:?}"));
        }
        let top = y - FONT_6X10.baseline as i32;
        let h = FONT_6X10.character_size.height as i32;
        if left + width > self.width as i32 || top < 0 || top + h > self.height as i32 {
            self.label_defects.push(format!("clipped label {s:?}"));
        }
        let latin = MonoTextStyle::new(&FONT_6X10, BLACK);
        let greek = MonoTextStyle::new(&GREEK_6X10, BLACK);
        let mut buf = [0u8; 4];
        for (k, c) in drawn.chars().enumerate() {
            let x = left + k as i32 * w;
            if c == '.' {
                // the font's full stop is a diamond reaching below the baseline, which reads as a comma in
                // tick labels ("2,5"): a 2×2 dot standing on the baseline instead
                for (dx, dy) in [(2, -1), (3, -1), (2, 0), (3, 0)] {
                    self.put(i64::from(x + dx), i64::from(y + dy), [0, 0, 0]);
                }
                continue;
            }
            let style = if is_greek(c) { greek } else { latin };
            let p = Point::new(x, y);
            Text::with_alignment(c.encode_utf8(&mut buf), p, style, Alignment::Left)
                .draw(self)
                .ok();
        }
    }

    /// A one-pixel black line.
    pub fn line(&mut self, x0: i32, y0: i32, x1: i32, y1: i32) {
        Line::new(Point::new(x0, y0), Point::new(x1, y1))
            .into_styled(PrimitiveStyle::with_stroke(BLACK, 1))
            .draw(self)
            .ok();
    }

    /// A one-pixel black rectangle outline.
    pub fn frame(&mut self, x: i32, y: i32, w: u32, h: u32) {
        Rectangle::new(Point::new(x, y), Size::new(w, h))
            .into_styled(PrimitiveStyle::with_stroke(BLACK, 1))
            .draw(self)
            .ok();
    }

    /// Copy another canvas in with its top-left corner at `(x, y)`.
    pub fn blit(&mut self, other: &Canvas, x: i64, y: i64) {
        self.label_defects.extend(other.label_defects.iter().cloned());
        for j in 0..other.height as i64 {
            for i in 0..other.width as i64 {
                self.put(x + i, y + j, other.pixels[(j * other.width as i64 + i) as usize]);
            }
        }
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

    /// Encode as PNG bytes.
    pub fn to_png(&self) -> Vec<u8> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width, self.height);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().expect("PNG header to memory");
            let flat: Vec<u8> = self.pixels.iter().flatten().copied().collect();
            w.write_image_data(&flat).expect("PNG data to memory");
        }
        out
    }

    /// Write as a PNG file, atomically.
    pub fn save_png(&self, path: &Path) -> Result<(), crate::base::io::WriteError> {
        crate::base::io::write_atomic(path, &self.to_png())
    }
}

/// How values map to colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// Linear between the minimum and maximum.
    Linear,
    /// log10, spanning the given number of decades below the maximum.
    Log {
        /// Decades shown below the maximum.
        decades: f64,
    },
}

/// A false-colour map of a regular grid with axes.
#[derive(Clone, Debug)]
pub struct Heatmap<'a> {
    /// Values, row-major, row 0 at `y_range.0` (drawn at the bottom).
    pub values: &'a [f64],
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Extent along x (left edge, right edge).
    pub x_range: (f64, f64),
    /// Extent along y (bottom edge, top edge).
    pub y_range: (f64, f64),
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Label of the colour bar.
    pub value_label: String,
    /// Colour scale.
    pub scale: Scale,
    /// Top of the colour scale (default: the largest finite value). Panels compared side by side pass the
    /// same value so that one colour means one value in all of them.
    pub value_max: Option<f64>,
    /// Side of the square plot area in pixels (the longer side when the extents are not square).
    pub plot_px: u32,
    /// Pixel colours to show instead of the colour-mapped values (e.g. a shaded relief tinted by height);
    /// the colour bar still maps `values`.
    pub rgb: Option<&'a [[u8; 3]]>,
}

/// "Nice" tick positions covering `[lo, hi]` with about `n` ticks.
pub fn nice_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if !lo.is_finite() || !hi.is_finite() || hi <= lo {
        return vec![];
    }
    let raw = (hi - lo) / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = vec![];
    while t <= hi + 1e-9 * step {
        out.push(if t.abs() < 1e-12 * step { 0.0 } else { t });
        t += step;
    }
    out
}

fn fmt_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (0.01..1e4).contains(&a) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

/// Map a value in `[0, 1]` to the viridis colour map.
pub fn viridis(t: f64) -> [u8; 3] {
    let c = colorous::VIRIDIS.eval_continuous(t.clamp(0.0, 1.0));
    [c.r, c.g, c.b]
}

impl Heatmap<'_> {
    /// Render to a canvas.
    pub fn render(&self) -> Canvas {
        let (wx, wy) = (self.x_range.1 - self.x_range.0, self.y_range.1 - self.y_range.0);
        let (pw, ph) = if wx >= wy {
            (
                self.plot_px as i32,
                ((self.plot_px as f64 * wy / wx).round() as i32).max(16),
            )
        } else {
            (
                ((self.plot_px as f64 * wx / wy).round() as i32).max(16),
                self.plot_px as i32,
            )
        };
        let (left, top, right, bottom) = (70, 28, 110, 44);
        let mut cv = Canvas::new((left + pw + right) as u32, (top + ph + bottom) as u32);
        let finite: Vec<f64> = self.values.iter().copied().filter(|v| v.is_finite()).collect();
        let vmax = self
            .value_max
            .unwrap_or_else(|| finite.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        let vmin = finite.iter().copied().fold(f64::INFINITY, f64::min);
        let (lo, hi, map): (f64, f64, Box<dyn Fn(f64) -> f64>) = match self.scale {
            Scale::Linear => {
                let (lo, hi) = if vmax > vmin {
                    (vmin, vmax)
                } else {
                    (vmin - 1.0, vmin + 1.0)
                };
                (lo, hi, Box::new(move |v: f64| (v.min(hi) - lo) / (hi - lo)))
            }
            Scale::Log { decades } => {
                let hi = if vmax > 0.0 { vmax.log10() } else { 0.0 };
                let lo = hi - decades;
                (
                    lo,
                    hi,
                    Box::new(move |v: f64| if v > 0.0 { (v.log10() - lo) / (hi - lo) } else { 0.0 }),
                )
            }
        };
        // the map
        for py in 0..ph {
            let fy = 1.0 - (py as f64 + 0.5) / ph as f64;
            let j = ((fy * self.ny as f64) as usize).min(self.ny - 1);
            for px in 0..pw {
                let fx = (px as f64 + 0.5) / pw as f64;
                let i = ((fx * self.nx as f64) as usize).min(self.nx - 1);
                let v = self.values[j * self.nx + i];
                let c = match self.rgb {
                    Some(rgb) => rgb[j * self.nx + i],
                    None if v.is_finite() => viridis(map(v)),
                    None => [200, 200, 200],
                };
                cv.put((left + px) as i64, (top + py) as i64, c);
            }
        }
        cv.frame(left - 1, top - 1, (pw + 2) as u32, (ph + 2) as u32);
        // axes and ticks
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_range;
        for t in nice_ticks(x0, x1, 6) {
            let px = left + ((t - x0) / (x1 - x0) * pw as f64).round() as i32;
            cv.line(px, top + ph, px, top + ph + 4);
            cv.text(px, top + ph + 14, &fmt_tick(t), Alignment::Center);
        }
        for t in nice_ticks(y0, y1, 6) {
            let py = top + ph - ((t - y0) / (y1 - y0) * ph as f64).round() as i32;
            cv.line(left - 5, py, left - 1, py);
            cv.text(left - 7, py + 3, &fmt_tick(t), Alignment::Right);
        }
        cv.text(left + pw / 2, top + ph + 30, &self.x_label, Alignment::Center);
        cv.text(4, top - 8, &self.y_label, Alignment::Left);
        cv.text(left + pw / 2, 14, &self.title, Alignment::Center);
        // colour bar
        let (bx, bw) = (left + pw + 16, 14);
        for py in 0..ph {
            let t = 1.0 - (py as f64 + 0.5) / ph as f64;
            for px in 0..bw {
                cv.put((bx + px) as i64, (top + py) as i64, viridis(t));
            }
        }
        cv.frame(bx - 1, top - 1, (bw + 2) as u32, (ph + 2) as u32);
        for t in nice_ticks(lo, hi, 5) {
            let py = top + ph - ((t - lo) / (hi - lo) * ph as f64).round() as i32;
            cv.line(bx + bw, py, bx + bw + 3, py);
            let label = match self.scale {
                Scale::Log { .. } => format!("1e{}", t.round() as i64),
                Scale::Linear => fmt_tick(t),
            };
            cv.text(bx + bw + 6, py + 3, &label, Alignment::Left);
        }
        cv.text(bx - 4, top - 8, &self.value_label, Alignment::Left);
        cv
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_title_sign_has_a_glyph() {
        assert_eq!(glyph_text("design tile ⊛ base lobe"), "design tile * base lobe");
        assert_eq!(glyph_text("sim − design (µm)"), "sim - design (µm)");
        assert_eq!(glyph_text("f·cosθo, θo (degrees)"), "f·cosθo, θo (degrees)");
        // The ISO 8859-7 font maps θ to a glyph of its own, not to the replacement glyph.
        let replacement = GREEK_6X10.glyph_mapping.index('?');
        for c in ['θ', 'φ', 'α', 'σ', 'λ', 'ψ', 'ξ'] {
            assert_ne!(GREEK_6X10.glyph_mapping.index(c), replacement, "{c}");
        }
        for c in ['µ', '²', '×', '·', '°', '±'] {
            assert_ne!(
                FONT_6X10.glyph_mapping.index(c),
                FONT_6X10.glyph_mapping.index('?'),
                "{c}"
            );
        }
    }

    /// The full stop is a dot on the baseline, never below it, so "2.5" cannot read as "2,5"; the comma
    /// still reaches below.
    #[test]
    fn a_full_stop_stands_on_the_baseline() {
        let ink_rows = |s: &str| {
            let mut c = Canvas::new(12, 16);
            c.text(0, 10, s, Alignment::Left);
            (0..16usize)
                .filter(|&y| (0..12usize).any(|x| c.pixels[y * 12 + x][0] < 128))
                .collect::<Vec<_>>()
        };
        assert_eq!(ink_rows("."), vec![9, 10]);
        assert!(ink_rows(",").iter().any(|&y| y > 10), "{:?}", ink_rows(","));
        // and digits end on the same baseline
        assert_eq!(ink_rows("5").last(), Some(&10));
    }

    /// Dark pixels on the outermost rows and columns: text or lines cut by the canvas' edge.
    fn dark_border_pixels(cv: &Canvas) -> usize {
        let (w, h) = (cv.width as usize, cv.height as usize);
        let dark = |x: usize, y: usize| cv.pixels[y * w + x].iter().map(|&c| c as u32).sum::<u32>() < 600;
        (0..w).filter(|&x| dark(x, 0) || dark(x, h - 1)).count()
            + (0..h).filter(|&y| dark(0, y) || dark(w - 1, y)).count()
    }

    #[test]
    fn labels_stay_inside_the_canvas_or_are_recorded() {
        // a colour-bar label longer than the right margin is moved inside, not cut
        let v: Vec<f64> = (0..64).map(f64::from).collect();
        let h = Heatmap {
            values: &v,
            nx: 8,
            ny: 8,
            x_range: (0.0, 1.0),
            y_range: (0.0, 1.0),
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            value_label: "simulated − design height (µm)".into(),
            scale: Scale::Linear,
            value_max: None,
            plot_px: 100,
            rgb: None,
        };
        let cv = h.render();
        assert!(cv.label_defects.is_empty(), "{:?}", cv.label_defects);
        assert_eq!(dark_border_pixels(&cv), 0);
        // text wider than the canvas, and a sign neither font has, are recorded
        let mut small = Canvas::new(40, 20);
        small.text(0, 12, "far too long for forty pixels", Alignment::Left);
        small.text(0, 12, "∂z", Alignment::Left);
        small.text(0, 2, "up", Alignment::Left);
        assert_eq!(small.label_defects.len(), 3, "{:?}", small.label_defects);
        assert!(small.label_defects[1].contains("missing glyph"));
        // and survive being placed in a larger figure
        let row = Canvas::hstack(&[small.clone(), cv]);
        assert_eq!(row.label_defects, small.label_defects);
        // a literal '?' is not a missing glyph
        let mut q = Canvas::new(100, 20);
        q.text(0, 12, "why?", Alignment::Left);
        assert!(q.label_defects.is_empty());
    }

    #[test]
    fn legends_sit_below_the_plot_and_dashes_alternate() {
        let series = |label: &str, y: f64, dashed| Series {
            label: label.into(),
            points: vec![(0.0, y), (1.0, y)],
            color: [0, 0, 0],
            dashed,
        };
        let plot = LinePlot {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![series("a long legend entry", 1.0, false), series("b", -1.0, true)],
            size_px: (200, 100),
            log_y: false,
            whole_x: false,
        };
        let cv = plot.render();
        assert!(cv.label_defects.is_empty(), "{:?}", cv.label_defects);
        // the plot area (x 70..270, y 28..128) holds only the curves: the legend is below y 128 + 44
        let ink = |y0: usize, y1: usize| {
            (y0..y1)
                .flat_map(|y| (71..269).map(move |x| (x, y)))
                .filter(|&(x, y)| cv.pixels[y * cv.width as usize + x] != [255, 255, 255])
                .count()
        };
        assert!(ink(172, cv.height as usize) > 0, "no legend below the axis");
        // y = 1 and y = -1 with a 5% margin each side: neither line lies on the frame (rows 27 and 129)
        let row = |y: usize| {
            (71..269)
                .filter(|&x| cv.pixels[y * cv.width as usize + x] == [0, 0, 0])
                .count()
        };
        assert!(row(30) + row(31) + row(32) > 150, "upper line");
        // the dashed line at the bottom: ink over 6 of every 10 pixels
        let dashed: Vec<bool> = (71..269)
            .map(|x| (123..127).any(|y| cv.pixels[y * cv.width as usize + x] == [0, 0, 0]))
            .collect();
        let on = dashed.iter().filter(|&&d| d).count() as f64 / dashed.len() as f64;
        assert!((0.5..0.7).contains(&on), "dashed line inks {on} of its length");
    }

    #[test]
    fn ticks_are_nice_and_inside() {
        let t = nice_ticks(-1.732, 1.732, 6);
        assert!(t.contains(&0.0) && t.contains(&1.0) && t.contains(&-1.0), "{t:?}");
        assert!(t.iter().all(|v| (-1.732..=1.732).contains(v)));
        assert!(nice_ticks(1.0, 1.0, 5).is_empty());
    }

    #[test]
    fn heatmap_encodes_a_png_of_the_right_size() {
        let v: Vec<f64> = (0..64).map(|k| (k as f64).exp()).collect();
        let h = Heatmap {
            values: &v,
            nx: 8,
            ny: 8,
            x_range: (-1.0, 1.0),
            y_range: (-1.0, 1.0),
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            value_label: "v".into(),
            scale: Scale::Log { decades: 4.0 },
            value_max: None,
            plot_px: 100,
            rgb: None,
        };
        let cv = h.render();
        let png = cv.to_png();
        assert_eq!(&png[1..4], b"PNG");
        let dec = png::Decoder::new(std::io::Cursor::new(png));
        let reader = dec.read_info().unwrap();
        assert_eq!(reader.info().width, cv.width);
        // the brightest cell (top right) is yellow, the dimmest (bottom left, clipped) dark purple
        let at = |x: u32, y: u32| cv.pixels[(y * cv.width + x) as usize];
        let hi = at(70 + 95, 28 + 5);
        let lo = at(70 + 5, 28 + 95);
        assert!(hi[0] > 200 && hi[1] > 200, "{hi:?}");
        assert!(lo[0] < 80 && lo[2] > 60, "{lo:?}");
    }
}

/// One curve of a [`LinePlot`].
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: [u8; 3],
    /// Dashed line.
    pub dashed: bool,
}

/// A line chart with axes, ticks and a legend.
#[derive(Clone, Debug)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// Curves.
    pub series: Vec<Series>,
    /// Plot area size in pixels `(w, h)`.
    pub size_px: (u32, u32),
    /// log10 y axis (values ≤ 0 are dropped).
    pub log_y: bool,
    /// x ticks at whole numbers only (the x axis counts something, e.g. design rounds).
    pub whole_x: bool,
}

/// Colours for up to six series (colour-blind friendly, Okabe–Ito).
pub const PALETTE: [[u8; 3]; 6] = [
    [0, 114, 178],
    [213, 94, 0],
    [0, 158, 115],
    [204, 121, 167],
    [230, 159, 0],
    [86, 180, 233],
];

impl LinePlot {
    /// Render to a canvas.
    pub fn render(&self) -> Canvas {
        let (pw, ph) = (self.size_px.0 as i32, self.size_px.1 as i32);
        let (left, top, right) = (70, 28, 20);
        // The legend sits below the x axis label, never over the curves: entries laid out in rows.
        let legend = legend_layout(&self.series, pw + right - 4);
        let legend_rows = legend.iter().map(|e| e.1 + 1).max().unwrap_or(0);
        let bottom = 44 + 14 * legend_rows + if legend_rows > 0 { 6 } else { 0 };
        let mut cv = Canvas::new((left + pw + right) as u32, (top + ph + bottom) as u32);
        let ty = |y: f64| {
            if self.log_y {
                if y > 0.0 {
                    y.log10()
                } else {
                    f64::NAN
                }
            } else {
                y
            }
        };
        let pts = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.0.is_finite() && ty(p.1).is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for p in pts {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(ty(p.1));
            y1 = y1.max(ty(p.1));
        }
        if x0 >= x1 {
            x1 = x0 + 1.0;
        }
        if y0 >= y1 {
            y1 = y0 + 1.0;
        }
        if !self.log_y && y0 > 0.0 {
            y0 = 0.0;
        }
        let margin = 0.05 * (y1 - y0);
        y1 += margin;
        if self.log_y || y0 < 0.0 {
            // nothing drawn on the frame: curves and reference lines at the low end stay visible
            y0 -= margin;
        }
        let px = |x: f64| left + ((x - x0) / (x1 - x0) * pw as f64).round() as i32;
        let py = |y: f64| top + ph - ((y - y0) / (y1 - y0) * ph as f64).round() as i32;
        cv.frame(left - 1, top - 1, (pw + 2) as u32, (ph + 2) as u32);
        let x_ticks = if self.whole_x {
            let (lo, hi) = (x0.ceil() as i64, x1.floor() as i64);
            let step = ((hi - lo) / 8 + 1).max(1);
            (lo..=hi).step_by(step as usize).map(|t| t as f64).collect()
        } else {
            nice_ticks(x0, x1, 6)
        };
        for t in x_ticks {
            cv.line(px(t), top + ph, px(t), top + ph + 4);
            cv.text(px(t), top + ph + 14, &fmt_tick(t), Alignment::Center);
        }
        for t in nice_ticks(y0, y1, 5) {
            cv.line(left - 5, py(t), left - 1, py(t));
            let label = if self.log_y {
                format!("1e{}", t.round() as i64)
            } else {
                fmt_tick(t)
            };
            if !self.log_y || (t - t.round()).abs() < 1e-9 {
                cv.text(left - 7, py(t) + 3, &label, Alignment::Right);
            }
        }
        cv.text(left + pw / 2, top + ph + 30, &self.x_label, Alignment::Center);
        cv.text(4, top - 8, &self.y_label, Alignment::Left);
        cv.text(left + pw / 2, 14, &self.title, Alignment::Center);
        for s in &self.series {
            let mut prev: Option<(i32, i32)> = None;
            let mut phase = 0.0;
            let mut drawn = vec![];
            for p in &s.points {
                let y = ty(p.1);
                if !y.is_finite() {
                    prev = None;
                    continue;
                }
                let cur = (px(p.0), py(y.clamp(y0, y1)));
                if let Some(a) = prev {
                    phase = draw_series_line(&mut cv, a, cur, s.color, s.dashed, phase);
                }
                prev = Some(cur);
                drawn.push(cur);
            }
            // a series of one point has no segment: mark the point itself
            if let [(x, y)] = drawn[..] {
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        cv.put((x + dx) as i64, (y + dy) as i64, s.color);
                    }
                }
            }
        }
        for (s, row, x) in legend {
            let ly = top + ph + 48 + 14 * row;
            let x = 4 + x;
            draw_series_line(&mut cv, (x, ly - 3), (x + 20, ly - 3), s.color, s.dashed, 0.0);
            cv.text(x + 25, ly, &s.label, Alignment::Left);
        }
        cv
    }
}

/// Where each labelled series' legend entry goes: `(series, row, x offset in pixels)`, entries left to right
/// in rows no wider than `width` (a series without a label continues the one before it and has no entry).
fn legend_layout(series: &[Series], width: i32) -> Vec<(&Series, i32, i32)> {
    let cell = FONT_6X10.character_size.width as i32;
    let (mut row, mut x) = (0, 0);
    let mut out = vec![];
    for s in series.iter().filter(|s| !s.label.is_empty()) {
        let w = 25 + cell * glyph_text(&s.label).chars().count() as i32 + 16;
        if x > 0 && x + w > width {
            row += 1;
            x = 0;
        }
        out.push((s, row, x));
        x += w;
    }
    out
}

/// Dashes of a dashed series, pixels on and off.
const DASH_PX: (f64, f64) = (6.0, 4.0);

/// A segment of a series, solid or dashed; dashes continue across segments from `phase` (pixels into the
/// dash pattern), and the phase at the segment's end is returned.
fn draw_series_line(cv: &mut Canvas, a: (i32, i32), b: (i32, i32), c: [u8; 3], dashed: bool, phase: f64) -> f64 {
    if !dashed {
        draw_line_color(cv, a, b, c);
        return 0.0;
    }
    let (dx, dy) = ((b.0 - a.0) as f64, (b.1 - a.1) as f64);
    let len = dx.hypot(dy);
    let period = DASH_PX.0 + DASH_PX.1;
    let at = |t: f64| {
        let f = if len > 0.0 { t / len } else { 0.0 };
        (
            (a.0 as f64 + f * dx).round() as i32,
            (a.1 as f64 + f * dy).round() as i32,
        )
    };
    // walk the pattern: dash starts at multiples of the period, shifted by the phase
    let mut t = -(phase % period);
    while t < len {
        // a line's end pixels are both inked: a dash of n pixels runs from its first to its n-th
        let (on0, on1) = (t.max(0.0), (t + DASH_PX.0 - 1.0).min(len));
        if on1 >= on0 {
            draw_line_color(cv, at(on0), at(on1), c);
        }
        t += period;
    }
    (phase + len) % period
}

fn draw_line_color(cv: &mut Canvas, a: (i32, i32), b: (i32, i32), c: [u8; 3]) {
    Line::new(Point::new(a.0, a.1), Point::new(b.0, b.1))
        .into_styled(PrimitiveStyle::with_stroke(Rgb888::new(c[0], c[1], c[2]), 2))
        .draw(cv)
        .ok();
}
