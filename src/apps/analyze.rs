//! `brdfmill analyze`: a measured or simulated surface → its NDF and BRDF, geometric and wave — the
//! heightfield-to-BRDF half of the loop.
//!
//! Input: an X3P file (invalid points handled: slopes skip every difference touching one; the wave
//! optics see them filled by iterated neighbour averaging, see [`crate::base::x3p`]) or a `.npy` heightfield in mm
//! with its pitch. The mean plane is removed first (least squares over the valid points) and reported.
//! Output, atomically into the folder: `ndf.png`, `brdf_slices.png` (geometric and wave at normal
//! incidence over the same `ψ̄` window), `surface.png`, `analysis.json` ([`Analysis`]) and `report.html`
//! (one offline page, images as `data:` URIs).

use crate::base::geometry::Vec3;
use crate::base::heightfield::Heightfield;
use crate::base::plot::escape_markup as esc;
use crate::base::plot::{Canvas, Heatmap, Scale};
use crate::base::scan::{Scan, ScanError};
use crate::base::slope::SlopeDomain;
use crate::base::surface::ndf_of_slopes;
use crate::stages::optics::figures::wave_vs_geometric_png;
use crate::stages::optics::geometric::MicrofacetBrdf;
use crate::stages::optics::wave::{self, OpticalSurface, WaveConfig};
use base64::Engine;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Settings of the analysis.
#[derive(Clone, Debug)]
pub struct Config {
    /// Sample pitch of a `.npy` input, µm (X3P files carry their own).
    pub pitch_um: Option<f64>,
    /// Wavelength, µm.
    pub wavelength_um: f64,
    /// Coherence σ, µm.
    pub sigma_um: f64,
    /// Coherence windows per axis for the wave slice.
    pub windows: usize,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            pitch_um: None,
            wavelength_um: 0.55,
            sigma_um: 10.0,
            windows: 3,
        }
    }
}

/// The analysis failed.
#[derive(Debug, thiserror::Error)]
pub enum AnalyzeError {
    /// The surface could not be read (the error names the file).
    #[error(transparent)]
    Scan(#[from] crate::base::scan::ScanError),
    /// The input is unusable (named file, reason).
    #[error("{path}: {message}")]
    Input {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The wave optics refused.
    #[error(transparent)]
    Wave(#[from] wave::WaveError),
    /// An output could not be written.
    #[error(transparent)]
    Write(#[from] crate::base::io::WriteError),
}

/// `analysis.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Analysis {
    /// Format version.
    pub version: u32,
    /// The input file.
    pub source: String,
    /// Samples `(x, y)`.
    pub size: [usize; 2],
    /// Pitch, µm.
    pub pitch_um: f64,
    /// Invalid (missing) points.
    pub missing_points: usize,
    /// Mean plane removed: slopes `(∂z/∂x, ∂z/∂y)`.
    pub tilt_removed: [f64; 2],
    /// RMS height after plane removal, µm.
    pub rms_height_um: f64,
    /// Slopes used for the NDF (differences touching a missing point skipped).
    pub slope_count: usize,
    /// Slope mean `(p, q)` after plane removal.
    pub slope_mean: [f64; 2],
    /// Slope covariance `[[pp, pq], [pq, qq]]`.
    pub slope_cov: [[f64; 2]; 2],
    /// Half-width of the slope grid of the NDF.
    pub ndf_max_slope: f64,
    /// Fraction of slopes outside the NDF grid.
    pub ndf_outside: f64,
    /// Wave settings.
    pub wave: WaveConfig,
    /// The wave slice's directional albedo at normal incidence (F = 1: the fraction of light in the slice).
    pub wave_albedo: f64,
    /// Relative L1 between the wave and geometric slope marginals along x and y.
    pub wave_vs_geometric_l1: [f64; 2],
    /// Wave / geometric slope variance along x and y.
    pub wave_vs_geometric_variance_ratio: [f64; 2],
    /// FFT vs Gabor relative L2 on a 9×9 box around specular, one window, texels = the FFT spacing.
    pub fft_vs_gabor_l2: f64,
    /// Notes on what was done to the data.
    pub notes: Vec<String>,
}

fn png_uri(c: &Canvas) -> String {
    format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(c.to_png())
    )
}

/// The analysis's notes: the reader's warnings, the plane removed, the missing points, the wave resampling.
fn notes(
    warnings: &[String],
    tilt: [f64; 2],
    missing: usize,
    hf: &Heightfield,
    wcfg: &WaveConfig,
    windows: usize,
) -> Vec<String> {
    let mut notes: Vec<String> = warnings.iter().map(|w| format!("Warning: {w}.")).collect();
    notes.push(format!(
        "Mean plane removed: slopes {:.5}, {:.5} ({:.3}°).",
        tilt[0],
        tilt[1],
        tilt[0].hypot(tilt[1]).atan().to_degrees()
    ));
    if missing > 0 {
        notes.push(format!(
            "{missing} missing points: slopes skip every difference touching one; the wave optics see them \
             filled by iterated averaging of valid neighbours."
        ));
    }
    notes.push(format!(
        "Wave optics: the heightfield is resampled (bicubic Catmull–Rom) from {:.3} µm to {:.4} µm (λ/4); {} \
         coherence windows of σ = {} µm at normal incidence.",
        hf.pitch_mm * 1e3,
        wcfg.sample(),
        windows,
        wcfg.sigma_um
    ));
    notes
}

/// What the wave optics can resolve of a surface this small or this coarse.
fn resolution_warnings(hf: &Heightfield, cfg: &Config) -> Vec<String> {
    let mut warnings = Vec::new();
    let side_um = (hf.nx.min(hf.ny) as f64) * hf.pitch_mm * 1e3;
    if side_um < 8.0 * cfg.sigma_um {
        warnings.push(format!(
            "the surface is {side_um:.1} µm across, less than the 8σ = {:.0} µm a coherence window needs: the wave optics see it as periodic and resolve only a few directions",
            8.0 * cfg.sigma_um
        ));
    }
    if hf.pitch_mm * 1e3 > cfg.sigma_um {
        warnings.push(format!(
            "the pitch {:.2} µm is larger than the coherence σ = {} µm: one sample per coherence area, so the wave optics see facets, not the surface's detail",
            hf.pitch_mm * 1e3,
            cfg.sigma_um
        ));
    }
    warnings
}

/// Run the analysis of `input` and write every artifact into `out`.
pub fn run(cfg: &Config, input: &Path, out: &Path) -> Result<Analysis, AnalyzeError> {
    let bad = |message: String| AnalyzeError::Input {
        path: input.to_path_buf(),
        message,
    };
    let npy = input.extension().is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    if npy && cfg.pitch_um.is_none() {
        return Err(bad("a .npy heightfield needs --pitch-um".into()));
    }
    let mut scan = Scan::read(input, cfg.pitch_um).map_err(|e| match e {
        ScanError::Input { path, message } => AnalyzeError::Input {
            path,
            message: message.replace("the pitch must be", "--pitch-um must be"),
        },
        e => e.into(),
    })?;
    let mut warnings = std::mem::take(&mut scan.warnings);
    warnings.extend(resolution_warnings(&scan.hf, cfg));
    let tilt = scan.level();
    let rms = scan.rms_height_um();
    let (hf, missing) = (&scan.hf, scan.missing);
    // slopes, skipping differences that touch a missing point
    let slopes = scan.slopes(0.0);
    if slopes.is_empty() {
        return Err(bad("no slope could be formed from valid points".into()));
    }
    let n = slopes.len() as f64;
    let mean = [
        slopes.iter().map(|s| s.0).sum::<f64>() / n,
        slopes.iter().map(|s| s.1).sum::<f64>() / n,
    ];
    let mut cov = [[0.0; 2]; 2];
    for (p, q) in &slopes {
        let (dp, dq) = (p - mean[0], q - mean[1]);
        cov[0][0] += dp * dp / n;
        cov[0][1] += dp * dq / n;
        cov[1][1] += dq * dq / n;
    }
    cov[1][0] = cov[0][1];
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !(rms.is_finite() && finite(&hf.z_mm) && finite(&[cov[0][0], cov[0][1], cov[1][1]])) {
        // heights of 1e300, or a plane through them, overflow: no figure of such a surface means anything
        return Err(bad(format!(
            "heights (after removing the best-fit plane) or their slopes at a {} µm pitch overflow a 64-bit \
             float (rms {rms:e} µm): the heights must be in mm, and finite",
            hf.pitch_mm * 1e3
        )));
    }
    let mut mags: Vec<f64> = slopes.iter().map(|(p, q)| p.abs().max(q.abs())).collect();
    mags.sort_by(f64::total_cmp);
    let p99 = mags[((mags.len() - 1) as f64 * 0.99) as usize];
    let max_slope = (1.5 * p99).clamp(0.02, 2.0);
    let domain = SlopeDomain::square(129, max_slope);
    let (ndf, outside) = ndf_of_slopes(&slopes, domain);
    let geo = MicrofacetBrdf::new(ndf.clone(), None);

    // wave optics at normal incidence
    let wcfg = WaveConfig {
        wavelength_um: cfg.wavelength_um,
        sigma_um: cfg.sigma_um,
        windows: cfg.windows,
        ..Default::default()
    };
    let surf = OpticalSurface::new(hf)?;
    let wi = Vec3::new(0.0, 0.0, 1.0);
    let slice = wave::fft_slice(&surf, &wi, &wcfg)?;
    let (p, wx, wy) = wave::slope_marginals(&slice);
    let (gx, gy) = wave::geometric_marginals(&slopes, &p, &slice, wcfg.sigma_um);
    let one = WaveConfig {
        windows: 1,
        ..wcfg.clone()
    };
    let check = wave::fft_slice(&surf, &wi, &one)?;
    let l2 = wave::compare_fft_gabor(&surf, &check, &one, one.sample(), 4)?;

    // figures
    let ndf_png = Heatmap {
        values: &ndf.density,
        nx: domain.nx,
        ny: domain.ny,
        x_range: (domain.p_min, domain.p_max),
        y_range: (domain.q_min, domain.q_max),
        title: "NDF of the surface (slope density P22)".into(),
        x_label: "p = dz/dx".into(),
        y_label: "q = dz/dy".into(),
        value_label: "P22 (log10)".into(),
        scale: Scale::Log { decades: 4.0 },
        value_max: None,
        value_min: None,
        plot_px: 480,
        rgb: None,
    }
    .render();
    let slices_png = wave_vs_geometric_png(&slice, &geo, &wi, max_slope);
    let surface_png = hf.relief_png("surface (mean plane removed, missing points filled)", 900);

    let notes = notes(&warnings, tilt, missing, hf, &wcfg, slice.windows);
    let analysis = Analysis {
        version: 1,
        source: input.display().to_string(),
        size: [hf.nx, hf.ny],
        pitch_um: hf.pitch_mm * 1e3,
        missing_points: missing,
        tilt_removed: tilt,
        rms_height_um: rms,
        slope_count: slopes.len(),
        slope_mean: mean,
        slope_cov: cov,
        ndf_max_slope: max_slope,
        ndf_outside: outside,
        wave: wcfg.clone(),
        wave_albedo: slice.albedo(),
        wave_vs_geometric_l1: [
            crate::base::distance::relative_l1(&wx, &gx),
            crate::base::distance::relative_l1(&wy, &gy),
        ],
        wave_vs_geometric_variance_ratio: [
            crate::base::distance::weighted_variance(&p, &wx) / crate::base::distance::weighted_variance(&p, &gx),
            crate::base::distance::weighted_variance(&p, &wy) / crate::base::distance::weighted_variance(&p, &gy),
        ],
        fft_vs_gabor_l2: l2,
        notes,
    };
    ndf_png.save_png(&out.join("ndf.png"))?;
    slices_png.save_png(&out.join("brdf_slices.png"))?;
    surface_png.save_png(&out.join("surface.png"))?;
    let json = serde_json::to_string_pretty(&analysis).unwrap_or_default();
    crate::base::io::write_atomic(&out.join("analysis.json"), json.as_bytes())?;
    let html = report_html(
        &analysis,
        &[
            (&surface_png, "Surface"),
            (&ndf_png, "NDF"),
            (&slices_png, "BRDF slices at normal incidence"),
        ],
    );
    crate::base::io::write_atomic(&out.join("report.html"), html.as_bytes())?;
    Ok(analysis)
}

fn report_html(a: &Analysis, figs: &[(&Canvas, &str)]) -> String {
    let mut h = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>brdfmill analyze</title>\
         <style>body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}\
         img{max-width:100%;border:1px solid #ddd}</style></head><body>",
    );
    h.push_str(&format!("<h1>brdfmill analyze — {}</h1><ul>", esc(&a.source)));
    for n in &a.notes {
        h.push_str(&format!("<li>{}</li>", esc(n)));
    }
    h.push_str("</ul><table>");
    let rows = [
        (
            "size",
            format!("{} × {} samples at {:.3} µm", a.size[0], a.size[1], a.pitch_um),
        ),
        ("missing points", a.missing_points.to_string()),
        ("RMS height", format!("{:.4} µm", a.rms_height_um)),
        (
            "slope covariance",
            format!(
                "[[{:.3e}, {:.3e}], [{:.3e}, {:.3e}]]",
                a.slope_cov[0][0], a.slope_cov[0][1], a.slope_cov[1][0], a.slope_cov[1][1]
            ),
        ),
        ("slopes outside the NDF grid", format!("{:.4}%", 100.0 * a.ndf_outside)),
        ("wave albedo (F = 1)", format!("{:.4}", a.wave_albedo)),
        (
            "wave vs geometric slope marginals (x, y)",
            format!(
                "relative L1 {:.3}, {:.3}; variance ratio {:.3}, {:.3}",
                a.wave_vs_geometric_l1[0],
                a.wave_vs_geometric_l1[1],
                a.wave_vs_geometric_variance_ratio[0],
                a.wave_vs_geometric_variance_ratio[1]
            ),
        ),
        ("FFT vs Gabor (relative L2)", format!("{:.4}", a.fft_vs_gabor_l2)),
    ];
    for (k, v) in rows {
        h.push_str(&format!("<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(&v)));
    }
    h.push_str("</table>");
    for (c, t) in figs {
        h.push_str(&format!(
            "<h2>{}</h2><img alt=\"{}\" src=\"{}\">",
            esc(t),
            esc(t),
            png_uri(c)
        ));
    }
    h.push_str("<p><small>Generated by brdfmill. Self-contained: it needs no network.</small></p></body></html>\n");
    h
}
