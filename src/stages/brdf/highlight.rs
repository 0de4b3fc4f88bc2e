//! A drawn highlight as the target (docs/DESIGN.md §2.1).
//!
//! The image is the light a part reflects onto a screen, in this configuration: a collimated light along
//! the part's normal (`ωi = z`), and a flat screen parallel to the part at distance `L`, seen from above
//! (image right = the part's +x, image up = +y). A screen point `(X, Y)`, in units of `L`, receives the
//! light reflected into `ωo ∝ (X, Y, 1)`, at `tan θo = R = √(X² + Y²)`. The image's half-width along its
//! longer axis is `tan(extent)`: `highlight_extent_deg` is the angle of reflection at the ends of the image's
//! longer axis (the middles of its shorter edges; of every edge for a square image), at most 40°.
//!
//! The facet that sends `z` into `ωo` has the half vector `ωh ∝ z + ωo ∝ (X, Y, 1 + ρ)`, `ρ = √(1 + R²)`, so
//! its slope is `(p, q) = −(X, Y)/(1 + ρ)`, with `s = |(p, q)| = tan(θo/2)`; the inverse is
//! `(X, Y) = −(p, q)·2/(1 − s²)`. Light along the normal falls on each facet in proportion to its projected
//! area, which is what `P22` measures, and leaves it towards `ωo`: the power on the screen patch of a slope
//! cell is `P22 dp dq` (Fresnel and masking taken as 1; at normal incidence within 45° of reflection they
//! vary by well under 1% for the shipped metals). With the screen's irradiance `I(X, Y)` (the image),
//! `P22(p, q) dp dq = c·I(X, Y) dX dY`, and the Jacobian of the map is
//! `J = |∂(X, Y)/∂(p, q)| = 4(1 + s²)/(1 − s²)³`, so
//!
//! `P22(p, q) = c · I(X(p, q), Y(p, q)) · 4(1 + s²)/(1 − s²)³`, `c = 1/∫ I dX dY`.
//!
//! A uniform disc of reflection angle `β` is therefore the slope disc `s ≤ tan(β/2)`, denser towards its
//! rim by `J` (13% at `β` = 20°). Pixels are constant over their square (so `∫ I dX dY = Σ I·δ²` exactly);
//! their values are sRGB-encoded, decoded to linear light, reduced to luminance, and multiplied by alpha.
//!
//! Rendering runs the map the other way: a distribution `P22` lights the screen with `I ∝ P22 / J`.

use super::BrdfError;
use crate::base::geometry::{normal_to_slope, Vec3};
use crate::base::slope::{SlopeDomain, SlopeGrid, SmithTable};
use crate::base::Invalid;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The largest image side accepted, pixels (16 M pixels at most, 128 MB of luminance).
pub const MAX_SIDE_PX: u32 = crate::base::image::MAX_SIDE_PX;

/// The largest PNG file read, bytes.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// The working resolution of the comparison: images are box-averaged to at most this many pixels on their
/// longer side before they are compared with a rendered highlight.
pub const COMPARE_SIDE_PX: usize = 256;

/// The most sub-samples per cell side of [`Highlight::slope_grid`].
pub const MAX_SUBSAMPLES: usize = 48;

/// Accepted extents, degrees of reflection at the ends of the longer axis: up to 40° (corners of a square
/// image at 50°, facets at 25°), where Fresnel and masking are still within about 1% of 1.
pub const EXTENT_DEG: (f64, f64) = (1.0, 40.0);

/// A highlight image and its geometry, usable as the NDF of a microfacet model.
#[derive(Clone, Debug)]
pub struct Highlight {
    /// Where the image came from (for messages and the report).
    pub path: PathBuf,
    /// Width, pixels.
    pub w: usize,
    /// Height, pixels.
    pub h: usize,
    /// Linear luminance, row-major, top row first.
    pub pixels: Vec<f64>,
    /// Angle of reflection at the ends of the longer axis, degrees.
    pub extent_deg: f64,
    /// Side of a pixel on the screen, in units of the screen's distance (`tan θo` per pixel).
    pub pixel_tan: f64,
    /// `c = 1/Σ I δ²`.
    norm: f64,
    /// Smith Λ of the distribution, for the masking term.
    smith: SmithTable,
    /// The image box-averaged to the comparison size ([`Highlight::compare_image`]), made once.
    compare: Vec<f64>,
}

/// The `highlight:` spec of an image with an optional extent and material (a job's `target.highlight`, or
/// `brdfmill ndf --highlight`). The error says which value a spec cannot hold: a path with a comma, or a
/// material that is not a bare name.
pub fn spec(path: &str, extent_deg: Option<f64>, material: Option<&str>) -> Result<String, Invalid> {
    if path.contains(',') {
        return Err(Invalid(format!("the image path `{path}` must not contain a comma")));
    }
    let mut spec = format!("highlight:{path}");
    if let Some(e) = extent_deg {
        spec.push_str(&format!(",extent_deg={e}"));
    }
    if let Some(m) = material {
        if m.contains(',') || m.contains('=') {
            return Err(Invalid(format!("the material `{m}` is not a material name")));
        }
        spec.push_str(&format!(",material={m}"));
    }
    Ok(spec)
}

/// The Jacobian `|∂(X, Y)/∂(p, q)|` of the slope → screen map at `s² = p² + q²` (module docs).
#[inline]
pub fn jacobian(s2: f64) -> f64 {
    let d = 1.0 - s2;
    4.0 * (1.0 + s2) / (d * d * d)
}

/// The screen point `(X, Y)` lit by the facet of slope `(p, q)`; `None` from `s ≥ 1` (θo ≥ 90°).
#[inline]
pub fn slope_to_screen(p: f64, q: f64) -> Option<(f64, f64)> {
    let s2 = p * p + q * q;
    (s2 < 1.0).then(|| {
        let k = -2.0 / (1.0 - s2);
        (k * p, k * q)
    })
}

/// The slope of the facet that lights the screen point `(X, Y)`.
#[inline]
pub fn screen_to_slope(x: f64, y: f64) -> (f64, f64) {
    let rho = (1.0 + x * x + y * y).sqrt();
    (-x / (1.0 + rho), -y / (1.0 + rho))
}

impl Highlight {
    /// Read a PNG (grey or colour, 8 or 16 bits, any alpha) as a highlight spanning `extent_deg`.
    pub fn read(path: &Path, extent_deg: f64) -> Result<Self, BrdfError> {
        let fmt = |reason: Invalid| BrdfError::Format {
            path: path.to_path_buf(),
            reason: reason.0,
        };
        if let Ok(m) = std::fs::metadata(path) {
            if m.len() > MAX_FILE_BYTES {
                return Err(fmt(Invalid(format!(
                    "the file is {} bytes; a highlight PNG of at most {MAX_FILE_BYTES} bytes is accepted",
                    m.len()
                ))));
            }
        }
        let bytes = crate::base::io::read(path)?;
        let (w, h, pixels) = decode_png(&bytes).map_err(fmt)?;
        Self::from_luminance(path, w, h, pixels, extent_deg).map_err(fmt)
    }

    /// A highlight from linear luminance (row-major, top row first). The error says what is wrong.
    pub fn from_luminance(path: &Path, w: usize, h: usize, pixels: Vec<f64>, extent_deg: f64) -> Result<Self, Invalid> {
        if !(extent_deg >= EXTENT_DEG.0 && extent_deg <= EXTENT_DEG.1) {
            return Err(Invalid(format!(
                "the highlight's extent must be in [{}, {}] degrees of reflection, got {extent_deg}",
                EXTENT_DEG.0, EXTENT_DEG.1
            )));
        }
        if pixels.len() != w * h {
            return Err(Invalid(format!("{} pixel values for a {w} × {h} image", pixels.len())));
        }
        let f = w.max(h).div_ceil(COMPARE_SIDE_PX).max(1);
        if w / f < 2 || h / f < 2 {
            return Err(Invalid(format!(
                "the image is {w} × {h} pixels: too thin to compare with (each side must keep at least 2 pixels when the longer one is reduced to {COMPARE_SIDE_PX})"
            )));
        }
        if let Some(i) = pixels.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(Invalid(format!(
                "pixel {} of row {} is not a finite value ≥ 0",
                i % w,
                i / w
            )));
        }
        let sum: f64 = pixels.iter().sum();
        let max = pixels.iter().fold(0.0f64, |a, b| a.max(*b));
        if sum <= 0.0 || max < 1e-6 {
            return Err(Invalid(
                "the image has no highlight: every pixel is black (or fully transparent)".into(),
            ));
        }
        let pixel_tan = extent_deg.to_radians().tan() / (w.max(h) as f64 / 2.0);
        let mut out = Self {
            path: path.to_path_buf(),
            w,
            h,
            pixels,
            extent_deg,
            pixel_tan,
            norm: 1.0 / (sum * pixel_tan * pixel_tan),
            smith: SmithTable::new(&SlopeGrid::from_fn(SlopeDomain::square(8, 0.1), |_, _| 1.0), 8, 4),
            compare: Vec::new(),
        };
        out.compare = out.box_averaged();
        let support = out.support_slope();
        let grid = out.slope_grid(SlopeDomain::square(256, support * 1.02));
        out.smith = SmithTable::new(&grid, 64, 32);
        Ok(out)
    }

    /// The largest slope the image reaches (its corners).
    pub fn support_slope(&self) -> f64 {
        let (x, y) = (
            self.w as f64 / 2.0 * self.pixel_tan,
            self.h as f64 / 2.0 * self.pixel_tan,
        );
        let (p, q) = screen_to_slope(x, y);
        (p * p + q * q).sqrt()
    }

    /// The image's value at screen point `(X, Y)` (constant over each pixel; 0 outside the image).
    #[inline]
    pub fn irradiance(&self, x: f64, y: f64) -> f64 {
        let c = (x / self.pixel_tan + self.w as f64 / 2.0).floor();
        let r = (self.h as f64 / 2.0 - y / self.pixel_tan).floor();
        if !(c >= 0.0 && r >= 0.0 && c < self.w as f64 && r < self.h as f64) {
            return 0.0; // outside the image, or not a number
        }
        self.pixels[r as usize * self.w + c as usize]
    }

    /// `P22(p, q) = c·I(X, Y)·J` (module docs).
    pub fn p22(&self, p: f64, q: f64) -> f64 {
        match slope_to_screen(p, q) {
            Some((x, y)) => self.norm * self.irradiance(x, y) * jacobian(p * p + q * q),
            None => 0.0,
        }
    }

    /// `D(ωm) = P22 / cos⁴θm`.
    pub fn d(&self, wm: &Vec3) -> f64 {
        match normal_to_slope(wm) {
            Some((p, q)) if wm.z > 0.0 => self.p22(p, q) / wm.z.powi(4),
            _ => 0.0,
        }
    }

    /// Separable Smith masking from the distribution's own Λ.
    pub fn g(&self, wi: &Vec3, wo: &Vec3, wm: &Vec3) -> f64 {
        self.smith.g2(wi, wo, wm)
    }

    /// `P22` averaged over each cell of `domain`, normalised to unit mass on the grid. Each cell is
    /// sub-sampled finely enough that every pixel it covers is seen, up to [`MAX_SUBSAMPLES`]² samples per
    /// cell; an image finer than that (thousands of pixels over a narrow extent on a coarse grid) is
    /// sampled, not averaged.
    pub fn slope_grid(&self, domain: SlopeDomain) -> SlopeGrid {
        // a slope step ds moves the screen point by up to J^(1/2)·ds·(1 + s²)/(…) ≤ 2(1 + s²)/(1 − s²)² ds
        let s = self.support_slope().min(0.99);
        let stretch = 2.0 * (1.0 + s * s) / (1.0 - s * s).powi(2);
        let cell = domain.dp().max(domain.dq());
        let k = ((2.0 * stretch * cell / self.pixel_tan).ceil() as usize).clamp(1, MAX_SUBSAMPLES);
        let (dp, dq) = (domain.dp() / k as f64, domain.dq() / k as f64);
        let mut density = vec![0.0; domain.len()];
        density.par_chunks_mut(domain.nx).enumerate().for_each(|(j, row)| {
            let q0 = domain.q_min + j as f64 * domain.dq();
            for (i, v) in row.iter_mut().enumerate() {
                let p0 = domain.p_min + i as f64 * domain.dp();
                let mut acc = 0.0;
                for b in 0..k {
                    let q = q0 + (b as f64 + 0.5) * dq;
                    for a in 0..k {
                        acc += self.p22(p0 + (a as f64 + 0.5) * dp, q);
                    }
                }
                *v = acc / (k * k) as f64;
            }
        });
        let mut g = SlopeGrid { domain, density };
        g.normalise();
        g
    }

    /// Size of the comparison image: the image box-averaged by an integer factor to at most
    /// [`COMPARE_SIDE_PX`] on its longer side. Returns `(factor, width, height)`.
    fn compare_size(&self) -> (usize, usize, usize) {
        let f = self.w.max(self.h).div_ceil(COMPARE_SIDE_PX).max(1);
        (f, self.w / f, self.h / f)
    }

    /// The image at the comparison size (row-major, top row first), and its width and height.
    pub fn compare_image(&self) -> (&[f64], usize, usize) {
        let (_, w, h) = self.compare_size();
        (&self.compare, w, h)
    }

    /// The image box-averaged by the comparison factor.
    fn box_averaged(&self) -> Vec<f64> {
        let (f, w, h) = self.compare_size();
        let mut out = vec![0.0; w * h];
        for (r, row) in out.chunks_mut(w).enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for rr in 0..f {
                    let base = (r * f + rr) * self.w + c * f;
                    acc += self.pixels[base..base + f].iter().sum::<f64>();
                }
                *v = acc / (f * f) as f64;
            }
        }
        out
    }

    /// The highlight a slope distribution casts in this image's configuration, at the comparison size:
    /// `I ∝ P22(p(X, Y) − p̄, q(X, Y) − q̄) / J` at each pixel's centre, scaled to the image's total.
    /// `tilt = (p̄, q̄)` is the mean slope the NDF stage removed (a tileable surface has none): the part tilted
    /// by it shows the highlight where it was drawn, so it is put back before the comparison.
    pub fn render(&self, grid: &SlopeGrid, tilt: (f64, f64)) -> (Vec<f64>, usize, usize) {
        let (f, w, h) = self.compare_size();
        let px = self.pixel_tan * f as f64;
        // the comparison image is the top-left w·f × h·f pixels, so its centre is offset from the image's
        let (x0, y0) = (
            -(self.w as f64) / 2.0 * self.pixel_tan,
            self.h as f64 / 2.0 * self.pixel_tan,
        );
        let mut out = vec![0.0; w * h];
        out.par_chunks_mut(w).enumerate().for_each(|(r, row)| {
            let y = y0 - (r as f64 + 0.5) * px;
            for (c, v) in row.iter_mut().enumerate() {
                let x = x0 + (c as f64 + 0.5) * px;
                let (p, q) = screen_to_slope(x, y);
                *v = grid.sample(p - tilt.0, q - tilt.1) / jacobian(p * p + q * q);
            }
        });
        let (target, _, _) = self.compare_image();
        let (ts, rs): (f64, f64) = (target.iter().sum(), out.iter().sum());
        if rs > 0.0 {
            out.iter_mut().for_each(|v| *v *= ts / rs);
        }
        (out, w, h)
    }

    /// Pearson correlation between the image and the highlight `grid` casts ([`Highlight::render`]), at the
    /// comparison size.
    pub fn correlation(&self, grid: &SlopeGrid, tilt: (f64, f64)) -> f64 {
        let (a, _, _) = self.compare_image();
        let (b, _, _) = self.render(grid, tilt);
        pearson(a, &b)
    }

    /// The report's figure: the image and a rendered highlight side by side on one linear colour scale
    /// topped at the image's brightest pixel, axes in screen units `X/L = tan θo cos φo`.
    pub fn figure(&self, rendered: &[f64], title: &str) -> crate::base::plot::Canvas {
        let (f, w, h) = self.compare_size();
        let (img, _, _) = self.compare_image();
        let max = img.iter().fold(0.0f64, |a, b| a.max(*b));
        // the compared image is the top-left (w·f) × (h·f) pixels of the image
        let (x0, y1) = (
            -(self.w as f64) / 2.0 * self.pixel_tan,
            self.h as f64 / 2.0 * self.pixel_tan,
        );
        let (x1, y0) = (
            x0 + (w * f) as f64 * self.pixel_tan,
            y1 - (h * f) as f64 * self.pixel_tan,
        );
        let panel = |values: &[f64], t: &str| {
            // the heatmap's row 0 is drawn at the bottom; the image's row 0 is its top
            let flipped: Vec<f64> = values.chunks(w).rev().flatten().map(|v| v.min(max)).collect();
            crate::base::plot::Heatmap {
                values: &flipped,
                nx: w,
                ny: h,
                x_range: (x0, x1),
                y_range: (y0, y1),
                title: t.to_string(),
                x_label: "X/L = tan θo cos φo".into(),
                y_label: "Y/L".into(),
                value_label: "irradiance".into(),
                scale: crate::base::plot::Scale::Linear,
                value_max: Some(max),
                value_min: None,
                plot_px: 320,
                rgb: None,
            }
            .render()
        };
        crate::base::plot::Canvas::hstack(&[panel(img, "highlight asked for"), panel(rendered, title)])
    }
}

/// Pearson correlation of two equal-length series (0 when either is constant).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

/// sRGB-encoded value in [0, 1] → linear light.
#[inline]
fn srgb_decode(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Decode a PNG to linear luminance × alpha: `(width, height, pixels)`, top row first
/// ([`crate::base::image::decode_png`] does the checks).
fn decode_png(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), Invalid> {
    let img = crate::base::image::decode_png(bytes)?;
    let lin = |v: u8| srgb_decode(v as f64 / 255.0);
    let pixels = img
        .data
        .chunks_exact(img.channels)
        .map(|px| {
            let (lum, alpha) = match img.channels {
                1 => (lin(px[0]), 1.0),
                2 => (lin(px[0]), px[1] as f64 / 255.0),
                c => (
                    super::luminance(&[lin(px[0]), lin(px[1]), lin(px[2])]),
                    if c == 4 { px[3] as f64 / 255.0 } else { 1.0 },
                ),
            };
            lum * alpha
        })
        .collect();
    Ok((img.width, img.height, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc of reflection angle `beta_deg` on a `n × n` image spanning `extent_deg`.
    fn disc(n: usize, extent_deg: f64, beta_deg: f64) -> Highlight {
        let t = extent_deg.to_radians().tan() / (n as f64 / 2.0);
        let r = beta_deg.to_radians().tan();
        let mut px = vec![0.0; n * n];
        for row in 0..n {
            for col in 0..n {
                let x = (col as f64 + 0.5 - n as f64 / 2.0) * t;
                let y = (n as f64 / 2.0 - row as f64 - 0.5) * t;
                if x * x + y * y <= r * r {
                    px[row * n + col] = 1.0;
                }
            }
        }
        Highlight::from_luminance(Path::new("disc"), n, n, px, extent_deg).unwrap()
    }

    /// The slope map and its inverse agree, and the Jacobian is the map's: the area of a small slope square
    /// mapped to the screen, by finite differences.
    #[test]
    fn map_inverse_and_jacobian() {
        for (p, q) in [(0.0, 0.0), (0.1, -0.05), (-0.3, 0.2), (0.5, 0.4)] {
            let (x, y) = slope_to_screen(p, q).unwrap();
            let (p2, q2) = screen_to_slope(x, y);
            assert!((p - p2).abs() < 1e-12 && (q - q2).abs() < 1e-12);
            // the reflected direction is z mirrored about the facet normal
            let n = crate::base::geometry::slope_to_normal(p, q);
            let o = crate::base::geometry::reflect(&Vec3::new(0.0, 0.0, 1.0), &n);
            assert!(
                (o.x / o.z - x).abs() < 1e-9 && (o.y / o.z - y).abs() < 1e-9,
                "{o:?} vs {x},{y}"
            );
            let e = 1e-6;
            let (xa, ya) = slope_to_screen(p + e, q).unwrap();
            let (xb, yb) = slope_to_screen(p, q + e).unwrap();
            let area = ((xa - x) * (yb - y) - (xb - x) * (ya - y)).abs() / (e * e);
            let j = jacobian(p * p + q * q);
            assert!((area - j).abs() < 1e-4 * j, "{area} vs {j}");
        }
    }

    /// A uniform disc of reflection angle β is the slope disc of radius tan(β/2), with the radial profile
    /// ∝ J: its second moment is the closed form ∫₀ˢ s³J ds / ∫₀ˢ sJ ds, and nothing lies outside it.
    #[test]
    fn uniform_disc_is_slope_disc_of_predicted_radius() {
        let beta = 36.0f64;
        let h = disc(512, 40.0, beta);
        let s_max = (beta.to_radians() / 2.0).tan();
        let g = h.slope_grid(SlopeDomain::square(256, 0.4));
        let d = g.domain;
        let (mut outside, mut m2) = (0.0, 0.0);
        for j in 0..d.ny {
            for i in 0..d.nx {
                let (p, q) = (d.p_at(i), d.q_at(j));
                let m = g.at(i, j) * d.cell_area();
                let s = (p * p + q * q).sqrt();
                if s > s_max + d.dp() {
                    outside += m;
                }
                m2 += m * s * s;
            }
        }
        assert!(outside < 1e-9, "mass beyond tan(β/2): {outside}");
        // closed form by fine quadrature of the radial integrals
        let (mut a, mut b) = (0.0, 0.0);
        let n = 100_000;
        for k in 0..n {
            let s = (k as f64 + 0.5) / n as f64 * s_max;
            a += s * s * s * jacobian(s * s);
            b += s * jacobian(s * s);
        }
        let want = a / b;
        assert!((m2 - want).abs() < 0.01 * want, "E[s²] {m2} vs closed form {want}");
        // uniform (J-free) would be s_max²/2, 6.7% away: the Jacobian is plainly visible at this size
        assert!(((s_max * s_max / 2.0) - want).abs() > 0.05 * want);
    }

    /// Casting a distribution back onto the screen gives the image again (the two maps are inverse).
    #[test]
    fn render_inverts_the_map() {
        let h = disc(256, 30.0, 18.0);
        let g = h.slope_grid(SlopeDomain::square(512, h.support_slope()));
        let c = h.correlation(&g, (0.0, 0.0));
        assert!(c > 0.97, "{c}");
        // and a different distribution does not correlate
        let other = SlopeGrid::from_fn(g.domain, |p, q| (-(p * p + q * q) / 0.0004).exp());
        assert!(h.correlation(&other, (0.0, 0.0)) < 0.8);
    }

    /// A smooth image off-centre, asymmetric, of varying brightness: cast back from its slope grid it is the
    /// same image pixel by pixel (so the Jacobian is divided out again and nothing is flipped or shifted),
    /// and its light sits at the slopes the orientation convention says (top right of the image: facets
    /// tilted towards +x and +y, p < 0 and q < 0).
    #[test]
    fn an_asymmetric_image_comes_back_pixel_for_pixel() {
        let n = 200;
        let t = 30f64.to_radians().tan() / (n as f64 / 2.0);
        let mut px = vec![0.0; n * n];
        for row in 0..n {
            for col in 0..n {
                let x = (col as f64 + 0.5 - n as f64 / 2.0) * t;
                let y = (n as f64 / 2.0 - row as f64 - 0.5) * t;
                px[row * n + col] = (-((x - 0.25).powi(2) + (y - 0.15).powi(2)) / 0.006).exp() * (1.0 + x)
                    + 0.5 * (-((x + 0.2).powi(2) + (y + 0.25).powi(2)) / 0.003).exp();
            }
        }
        let h = Highlight::from_luminance(Path::new("blobs"), n, n, px.clone(), 30.0).unwrap();
        let g = h.slope_grid(SlopeDomain::square(600, h.support_slope()));
        // the brighter blob is at the top right (x > 0, y > 0): its slopes are p < 0, q < 0
        let d = g.domain;
        let mut quadrant = 0.0;
        for j in 0..d.ny {
            for i in 0..d.nx {
                if d.p_at(i) < 0.0 && d.q_at(j) < 0.0 {
                    quadrant += g.at(i, j) * d.cell_area();
                }
            }
        }
        assert!(quadrant > 0.6, "mass at p < 0, q < 0: {quadrant}");
        let (back, w, hh) = h.render(&g, (0.0, 0.0));
        assert_eq!((w, hh), (n, n));
        let max = px.iter().fold(0.0f64, |a, b| a.max(*b));
        let mut worst = 0.0f64;
        for (a, b) in px.iter().zip(&back) {
            if *a > 0.1 * max {
                worst = worst.max((b - a).abs() / a);
            }
        }
        assert!(worst < 0.02, "largest relative error where the image is lit: {worst}");
        // centroids agree to a tenth of a pixel
        let centroid = |v: &[f64]| {
            let (mut m, mut cx, mut cy) = (0.0, 0.0, 0.0);
            for (k, a) in v.iter().enumerate() {
                m += a;
                cx += a * (k % n) as f64;
                cy += a * (k / n) as f64;
            }
            (cx / m, cy / m)
        };
        let (a, b) = (centroid(&px), centroid(&back));
        assert!((a.0 - b.0).abs() < 0.1 && (a.1 - b.1).abs() < 0.1, "{a:?} vs {b:?}");
        // a tilt put back moves the rendering: the same grid shifted by the tilt the NDF stage would remove
        let tilted = g.shifted(0.05, 0.0);
        let (moved, _, _) = h.render(&tilted, (0.05, 0.0));
        assert!(pearson(&moved, &px) > 0.999);
        assert!(pearson(&h.render(&tilted, (0.0, 0.0)).0, &px) < 0.99);
    }

    /// `D` is normalised: `∫ D cosθ dω = ∫ P22 dp dq = 1`.
    #[test]
    fn ndf_is_normalised() {
        let h = disc(128, 30.0, 25.0);
        let g = SlopeGrid::from_fn(SlopeDomain::square(800, 0.35), |p, q| h.p22(p, q));
        assert!((g.mass() - 1.0).abs() < 0.01, "{}", g.mass());
    }

    /// The spec a job or the command line builds: extent and material appended, and the values a spec
    /// cannot hold refused.
    #[test]
    fn spec_of_a_highlight() {
        assert_eq!(
            spec("s.png", Some(25.0), Some("gold")).unwrap(),
            "highlight:s.png,extent_deg=25,material=gold"
        );
        assert_eq!(spec("s.png", None, None).unwrap(), "highlight:s.png");
        assert!(spec("a,b.png", None, None).unwrap_err().contains("comma"));
        assert!(spec("s.png", None, Some("gold,eta=2"))
            .unwrap_err()
            .contains("not a material name"));
    }

    /// Bad images get errors that say what is wrong.
    #[test]
    fn refuses_bad_images() {
        let black = Highlight::from_luminance(Path::new("b"), 4, 4, vec![0.0; 16], 30.0).unwrap_err();
        assert!(black.contains("no highlight"), "{black}");
        assert!(decode_png(b"GIF89a....").unwrap_err().contains("not a PNG"));
        let mut png = Vec::new();
        {
            let mut e = png::Encoder::new(&mut png, 2, 2);
            e.set_color(png::ColorType::Grayscale);
            e.write_header().unwrap().write_image_data(&[0, 255, 0, 0]).unwrap();
        }
        let (w, h, px) = decode_png(&png).unwrap();
        assert_eq!((w, h), (2, 2));
        assert!((px[1] - 1.0).abs() < 1e-12 && px[0] == 0.0);
        assert!(decode_png(&png[..png.len() - 20]).is_err());
        let e = Highlight::from_luminance(Path::new("b"), 2, 2, px, 45.0).unwrap_err();
        assert!(e.contains("extent"), "{e}");
        let e = Highlight::from_luminance(Path::new("thin"), 1000, 3, vec![1.0; 3000], 30.0).unwrap_err();
        assert!(e.contains("too thin"), "{e}");
    }
}
