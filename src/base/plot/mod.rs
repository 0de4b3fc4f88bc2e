//! Figures: false-colour maps with axes, ticks, a colour bar and a title ([`Heatmap`]), and line charts
//! ([`LinePlot`]), drawn on a [`Canvas`] that gives both an SVG (text as text, for the report) and a PNG.
//!
//! Colour maps come from `colorous`.

mod canvas;

pub use canvas::{escape_markup, glyph_text, Canvas, Mark, CHAR_PX, DASH_PX};
pub use embedded_graphics::text::Alignment;

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
    /// Bottom of the colour scale (default: the smallest finite value), for the same reason.
    pub value_min: Option<f64>,
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
        let vmin = self
            .value_min
            .unwrap_or_else(|| finite.iter().copied().fold(f64::INFINITY, f64::min));
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
    use embedded_graphics::mono_font::{iso_8859_1::FONT_6X10, iso_8859_7::FONT_6X10 as GREEK_6X10};

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
            let c = c.rasterized();
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
            value_min: None,
            plot_px: 100,
            rgb: None,
        };
        let cv = h.render();
        assert!(cv.label_defects.is_empty(), "{:?}", cv.label_defects);
        assert_eq!(dark_border_pixels(&cv.rasterized()), 0);
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
        let cv = plot.render().rasterized();
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

    /// The SVG carries every label as a text element (escaped, in the font the page chooses), every line as
    /// a path, and the raster only when there is one; the PNG draws the same marks in.
    #[test]
    fn svg_keeps_text_as_text() {
        let plot = LinePlot {
            title: "variance & <ratio>".into(),
            x_label: "round".into(),
            y_label: "σ² ratio".into(),
            series: vec![Series {
                label: "x".into(),
                points: vec![(1.0, 0.9), (2.0, 1.0), (3.0, f64::NAN), (4.0, 1.1), (5.0, 1.0)],
                color: PALETTE[0],
                dashed: true,
            }],
            size_px: (200, 100),
            log_y: false,
            whole_x: true,
        };
        let cv = plot.render();
        let svg = cv.to_svg();
        assert!(svg.starts_with("<svg ") && svg.ends_with("</svg>"));
        assert!(svg.contains(">variance &amp; &lt;ratio&gt;</text>"), "{svg}");
        assert!(svg.contains(">σ² ratio</text>"));
        // a line chart has no raster, and its NaN splits the series in two dashed paths
        assert!(!svg.contains("<image"));
        assert_eq!(
            svg.matches("stroke-dasharray").count(),
            3,
            "two runs and the legend's sample"
        );
        let texts = cv.marks.iter().filter(|m| matches!(m, Mark::Text { .. })).count();
        assert_eq!(svg.matches("<text ").count(), texts);
        // the PNG has the marks drawn in: ink where the raster layer is white
        let ink = |c: &Canvas| c.pixels.iter().filter(|p| **p != [255, 255, 255]).count();
        assert_eq!(ink(&cv), 0);
        assert!(ink(&cv.rasterized()) > 500);
        // a map keeps its pixels as one embedded PNG
        let v: Vec<f64> = (0..16).map(f64::from).collect();
        let h = Heatmap {
            values: &v,
            nx: 4,
            ny: 4,
            x_range: (0.0, 1.0),
            y_range: (0.0, 1.0),
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            value_label: "v".into(),
            scale: Scale::Linear,
            value_max: None,
            value_min: None,
            plot_px: 40,
            rgb: None,
        };
        assert_eq!(h.render().to_svg().matches("<image ").count(), 1);
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
            value_min: None,
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
            // one path per run of finite points; a gap (a value the axis cannot show) breaks the line
            let mut runs: Vec<Vec<(i32, i32)>> = vec![vec![]];
            for p in &s.points {
                let y = ty(p.1);
                if y.is_finite() {
                    runs.last_mut()
                        .expect("one run at least")
                        .push((px(p.0), py(y.clamp(y0, y1))));
                } else if !runs.last().expect("one run at least").is_empty() {
                    runs.push(vec![]);
                }
            }
            let single = runs.iter().map(Vec::len).sum::<usize>() == 1;
            for run in runs {
                // a series of one point has no segment: mark the point itself
                if let (true, [(x, y)]) = (single, &run[..]) {
                    for dy in -2..=2 {
                        for dx in -2..=2 {
                            cv.put(i64::from(x + dx), i64::from(y + dy), s.color);
                        }
                    }
                }
                cv.path(run, s.color, 2, s.dashed);
            }
        }
        for (s, row, x) in legend {
            let ly = top + ph + 48 + 14 * row;
            let x = 4 + x;
            cv.path(vec![(x, ly - 3), (x + 20, ly - 3)], s.color, 2, s.dashed);
            cv.text(x + 25, ly, &s.label, Alignment::Left);
        }
        cv
    }
}

/// Where each labelled series' legend entry goes: `(series, row, x offset in pixels)`, entries left to right
/// in rows no wider than `width` (a series without a label continues the one before it and has no entry).
fn legend_layout(series: &[Series], width: i32) -> Vec<(&Series, i32, i32)> {
    let cell = CHAR_PX;
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
