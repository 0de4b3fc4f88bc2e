//! Base lobes as convolution kernels in slope space.
//!
//! A kernel sits on the slope grid's spacing, has odd sides and its centre cell at slope 0, and sums to 1.
//! Two sources:
//! - the half-angle distribution of a BRDF (the milled material's own polish, e.g. `beckmann:alpha=0.05`);
//! - the **scallop lobe** of a ball-nose raster: a flat surface milled with a ball of radius `r` at stepover
//!   `s` is a row of circular arcs. Across the passes the height is `r − sqrt(r² − v²)` for `v` uniform on
//!   `[−s/2, s/2]`, so the slope `t = v / sqrt(r² − v²)` has the density `f(t) = r / (s (1 + t²)^{3/2})` on
//!   `|t| ≤ t_max = (s/2)/sqrt(r² − s²/4)`; along the passes the slope is 0. The lobe is that segment in the
//!   direction across the raster (DESIGN.md §6: "the natural base lobe is the NDF of a flat patch milled
//!   with the same bit and stepover"). Optionally convolved with a polish lobe.

use super::{halfangle, NdfConfig, NdfError};
use crate::base::slope::{splat, SlopeDomain, SlopeGrid};
use crate::stages::brdf::Brdf;

/// A base lobe on the slope grid's spacing.
#[derive(Clone, Debug, PartialEq)]
pub struct Kernel {
    /// Values, row-major (rows along q), summing to 1.
    pub values: Vec<f64>,
    /// Width (odd).
    pub w: usize,
    /// Height (odd).
    pub h: usize,
    /// Cell size along p.
    pub dp: f64,
    /// Cell size along q.
    pub dq: f64,
    /// What it is (recorded as the `base` of ndf.json).
    pub label: String,
}

/// The odd, centred domain with the spacing of `domain` and (at most) its extent.
pub fn kernel_domain(domain: &SlopeDomain) -> SlopeDomain {
    let (dp, dq) = (domain.dp(), domain.dq());
    let (mx, my) = (domain.nx / 2, domain.ny / 2);
    SlopeDomain {
        nx: 2 * mx + 1,
        ny: 2 * my + 1,
        p_min: -(mx as f64 + 0.5) * dp,
        p_max: (mx as f64 + 0.5) * dp,
        q_min: -(my as f64 + 0.5) * dq,
        q_max: (my as f64 + 0.5) * dq,
    }
}

impl Kernel {
    /// Crop a centred odd grid to its support above `1e-7` of the peak, normalised to unit sum.
    pub fn from_centred_grid(k: &SlopeGrid, label: String) -> Option<Self> {
        let d = k.domain;
        let (mx, my) = (d.nx / 2, d.ny / 2);
        let peak = k.density.iter().copied().fold(0.0, f64::max);
        if peak.is_nan() || peak <= 0.0 {
            return None;
        }
        let thr = 1e-7 * peak;
        let (mut rx, mut ry) = (0usize, 0usize);
        for j in 0..d.ny {
            for i in 0..d.nx {
                if k.at(i, j) > thr {
                    rx = rx.max(i.abs_diff(mx));
                    ry = ry.max(j.abs_diff(my));
                }
            }
        }
        let (w, h) = (2 * rx + 1, 2 * ry + 1);
        let mut values = Vec::with_capacity(w * h);
        for j in (my - ry)..=(my + ry) {
            for i in (mx - rx)..=(mx + rx) {
                values.push(k.at(i, j));
            }
        }
        let s: f64 = values.iter().sum();
        values.iter_mut().for_each(|v| *v /= s);
        Some(Self {
            values,
            w,
            h,
            dp: d.dp(),
            dq: d.dq(),
            label,
        })
    }

    /// The half-angle distribution of a BRDF as a kernel.
    pub fn from_brdf(base: &Brdf, domain: &SlopeDomain, cfg: &NdfConfig) -> Result<Self, NdfError> {
        let (k, _) = halfangle::half_angle_density(base, kernel_domain(domain), &cfg.half_angle);
        Self::from_centred_grid(&k, base.spec.clone()).ok_or_else(|| NdfError::Empty {
            what: format!("base lobe `{}`", base.spec),
            max_slope: domain.p_max,
        })
    }

    /// The scallop lobe of `tool` at stepover `s_mm`, passes at `angle_deg` from x, optionally convolved with
    /// the half-angle distribution of `polish`.
    ///
    /// Across the passes the surface is a row of the tool's cross-sections `s_mm` apart: for a ball of radius
    /// `r` a circular arc of half-width `s/2`, whose slopes `t = v / sqrt(r² − v²)` are uniform in `v`,
    /// so their density is `(r / s) / (1 + t²)^{3/2}` on `|t| ≤ t_max`. A bull-nose (a ball with runout is
    /// one: [`crate::cut::accuracy`]) has a flat of width `w` at its bottom: a fraction `min(w/s, 1)` of the
    /// surface is level, and the arcs of its corner radius cover the remaining `s − w`.
    pub fn scallop(
        domain: &SlopeDomain,
        tool: &crate::cut::tool::Shape,
        s_mm: f64,
        angle_deg: f64,
        polish: Option<&Brdf>,
        cfg: &NdfConfig,
    ) -> Result<Self, NdfError> {
        let kd = kernel_domain(domain);
        let (sin, cos) = angle_deg.to_radians().sin_cos();
        let n = (-sin, cos); // across the passes
        let r_mm = tool.corner_radius_mm();
        let flat_mm = (tool.diameter_mm() - 2.0 * r_mm).clamp(0.0, s_mm);
        let h = (s_mm - flat_mm) / 2.0;
        let t_max = h / (r_mm * r_mm - h * h).max(1e-300).sqrt();
        // the line, as weighted points (each arc sample's weight is its share of the stepover)
        let samples = if h > 0.0 && r_mm > 0.0 { 4001 } else { 0 };
        // an arc sample of slope t covers dx = r dt / (1 + t²)^{3/2} of the stepover: its share is dx / s
        let dt = if samples > 0 { 2.0 * t_max / samples as f64 } else { 0.0 };
        let mut pts: Vec<(f64, f64, f64)> = (0..samples)
            .map(|k| {
                let t = -t_max + 2.0 * t_max * (k as f64 + 0.5) / samples as f64;
                let w = r_mm * dt / (s_mm * (1.0 + t * t).powf(1.5));
                (t * n.0, t * n.1, w)
            })
            .collect();
        if flat_mm > 0.0 {
            pts.push((0.0, 0.0, flat_mm / s_mm));
        }
        // bilinear splat of the line onto the grid, then (optionally) the polish lobe by FFT convolution
        let mut g = SlopeGrid::from_fn(kd, |_, _| 0.0);
        for (p, q, w) in &pts {
            splat(&mut g, *p, *q, *w);
        }
        if let Some(b) = polish {
            g = Self::from_brdf(b, domain, cfg)?.convolve(&g);
        }
        let label = match polish {
            None => format!(
                "scallop({}, stepover={:.1} µm, angle={angle_deg}°)",
                scallop_tool(tool),
                s_mm * 1e3
            ),
            Some(b) => format!(
                "scallop({}, stepover={:.1} µm, angle={angle_deg}°) * {}",
                scallop_tool(tool),
                s_mm * 1e3,
                b.spec
            ),
        };
        Self::from_centred_grid(&g, label.clone()).ok_or(NdfError::Empty {
            what: label,
            max_slope: domain.p_max,
        })
    }

    /// Convolve a density on a grid of the same spacing with this kernel ("same" size, linear).
    pub fn convolve(&self, g: &SlopeGrid) -> SlopeGrid {
        let d = g.domain;
        let mut conv = super::deconvolve::Convolver::new(d.nx, d.ny, &self.values, self.w, self.h);
        let mut out = SlopeGrid {
            domain: d,
            density: vec![0.0; d.len()],
        };
        conv.convolve(&g.density, &mut out.density, false);
        out.density.iter_mut().for_each(|v| *v = v.max(0.0));
        out
    }

    /// Slope variance of the kernel along p and q.
    pub fn variance(&self) -> (f64, f64) {
        let (mx, my) = ((self.w / 2) as f64, (self.h / 2) as f64);
        let (mut vp, mut vq) = (0.0, 0.0);
        for j in 0..self.h {
            for i in 0..self.w {
                let v = self.values[j * self.w + i];
                vp += v * ((i as f64 - mx) * self.dp).powi(2);
                vq += v * ((j as f64 - my) * self.dq).powi(2);
            }
        }
        (vp, vq)
    }
}

/// How a scallop lobe's label names its tool: the arcs' radius, and the flat when there is one.
fn scallop_tool(tool: &crate::cut::tool::Shape) -> String {
    let r = tool.corner_radius_mm();
    let flat = tool.diameter_mm() - 2.0 * r;
    if flat > 0.0 {
        // sizes in mm, the runout's flat (µm-scale) in µm, as the rest of the page gives it
        format!("r={r} mm, flat={:.1} µm", flat * 1e3)
    } else {
        format!("r={r} mm")
    }
}

#[cfg(test)]
mod tests {
    use crate::cut::tool::Shape;

    fn ball(r_mm: f64) -> Shape {
        Shape::Ball {
            diameter_mm: 2.0 * r_mm,
        }
    }

    #[test]
    fn a_flat_bottom_levels_its_share_of_the_stepover() {
        // a bull-nose of corner radius r and flat w at stepover s: the arcs cover s − w with the slopes of
        // a ball at stepover s − w, so the variance is that ball's times (s − w)/s
        let (r, s, w) = (0.25, 0.06, 0.015);
        let domain = SlopeDomain::square(512, 0.5);
        let cfg = NdfConfig::default();
        let bull = Shape::Bull {
            diameter_mm: 2.0 * r + w,
            corner_radius_mm: r,
        };
        let (_, vq) = Kernel::scallop(&domain, &bull, s, 0.0, None, &cfg).unwrap().variance();
        let (_, vball) = Kernel::scallop(&domain, &ball(r), s - w, 0.0, None, &cfg)
            .unwrap()
            .variance();
        let want = vball * (s - w) / s;
        assert!((vq - want).abs() < domain.dq().powi(2) / 4.0 + 1e-7, "{vq} vs {want}");
        // wider than the stepover: level
        let wide = Shape::Bull {
            diameter_mm: 2.0 * r + 2.0 * s,
            corner_radius_mm: r,
        };
        let (_, v) = Kernel::scallop(&domain, &wide, s, 0.0, None, &cfg).unwrap().variance();
        assert!(v < 1e-9, "{v}");
    }

    use super::*;

    #[test]
    fn scallop_lobe_has_the_variance_of_its_profile() {
        // var(t) for v uniform on ±s/2 with t = v/sqrt(r²−v²), by direct quadrature over v
        let (r, s) = (0.5, 0.2);
        let n = 100_000;
        let var: f64 = (0..n)
            .map(|k| {
                let v = -s / 2.0 + s * (k as f64 + 0.5) / n as f64;
                (v / (r * r - v * v).sqrt()).powi(2)
            })
            .sum::<f64>()
            / n as f64;
        let domain = SlopeDomain::square(512, 1.0);
        let k = Kernel::scallop(&domain, &ball(r), s, 0.0, None, &NdfConfig::default()).unwrap();
        let (vp, vq) = k.variance();
        assert!(vp < 1e-6, "no slope along the passes: {vp}");
        // bilinear splatting adds at most dq²/6
        assert!((vq - var).abs() < domain.dq().powi(2) / 4.0 + 1e-6, "{vq} vs {var}");
        let k90 = Kernel::scallop(&domain, &ball(r), s, 90.0, None, &NdfConfig::default()).unwrap();
        let (vp90, vq90) = k90.variance();
        assert!((vp90 - vq).abs() < 1e-6 && vq90 < 1e-6);
    }

    #[test]
    fn convolution_adds_variances() {
        let domain = SlopeDomain::square(256, 1.5);
        let cfg = NdfConfig::default();
        let polish = Brdf::parse("beckmann:alpha=0.1").unwrap();
        let k = Kernel::scallop(&domain, &ball(0.5), 0.2, 30.0, Some(&polish), &cfg).unwrap();
        let (vp, vq) = k.variance();
        let ks = Kernel::scallop(&domain, &ball(0.5), 0.2, 30.0, None, &cfg).unwrap();
        let (sp, sq) = ks.variance();
        assert!(
            ((vp + vq) - (sp + sq + 0.01)).abs() < 2e-4,
            "{} vs {}",
            vp + vq,
            sp + sq + 0.01
        );
    }
}
