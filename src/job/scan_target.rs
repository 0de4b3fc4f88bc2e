//! A measured surface as a job's target (`target.surface`): its keys checked, its spec built, and, for the
//! wave-optics estimate, the Kirchhoff slice at normal incidence computed here, above both the BRDF stage
//! that reads the scan and the optics stage that diffracts it (docs/JOB.md, [`crate::stages::brdf::surface`]).

use super::targets::RegionTarget;
use super::TargetSection;
use crate::base::geometry::Vec3;
use crate::base::scan::Scan;
use crate::stages::brdf::surface::{self, Method};
use crate::stages::brdf::{Brdf, Model};
use crate::stages::optics::wave::{self, OpticalSurface, WaveConfig};
use std::path::Path;

/// The wave estimate's default wavelength, µm (green, as `analyze`'s).
pub const DEFAULT_WAVELENGTH_UM: f64 = 0.55;

/// The wave estimate's default coherence σ, µm (the seed's 10 µm, after Werner et al. 2017).
pub const DEFAULT_SIGMA_UM: f64 = 10.0;

/// Coherence windows per axis of the wave estimate.
const WINDOWS: usize = 3;

/// Refuse the `surface_*` keys without `target.surface`.
pub(super) fn no_surface_keys(t: &TargetSection) -> Result<(), String> {
    for (key, given) in [
        ("surface_pitch_um", t.surface_pitch_um.is_some()),
        ("surface_filter_um", t.surface_filter_um.is_some()),
        ("surface_method", t.surface_method.is_some()),
        ("surface_wavelength_um", t.surface_wavelength_um.is_some()),
        ("surface_sigma_um", t.surface_sigma_um.is_some()),
    ] {
        if given {
            return Err(format!("`target.{key}` goes with `target.surface`"));
        }
    }
    Ok(())
}

/// The wave settings of a `"wave"` surface target.
pub fn wave_config(t: &TargetSection) -> WaveConfig {
    WaveConfig {
        wavelength_um: t.surface_wavelength_um.unwrap_or(DEFAULT_WAVELENGTH_UM),
        sigma_um: t.surface_sigma_um.unwrap_or(DEFAULT_SIGMA_UM),
        windows: WINDOWS,
        ..Default::default()
    }
}

/// `target.surface` → the job's single target: the `surface:` spec of the scan (resolved against the job's
/// folder) with its pitch, pre-filter and material, read; with `surface_method = "wave"`, its density
/// replaced by the wave-optics estimate.
pub(super) fn single(t: &TargetSection, scan: &str, dir: &Path) -> Result<RegionTarget, String> {
    if !t.brdf.trim().is_empty() || t.highlight.is_some() {
        return Err("give one of `target.brdf`, `target.highlight` or `target.surface`".into());
    }
    if t.highlight_extent_deg.is_some() {
        return Err("`target.highlight_extent_deg` goes with `target.highlight`".into());
    }
    if t.merl_from.is_some() {
        return Err("`target.merl_from` goes with a `merl:` `target.brdf`, not `target.surface`".into());
    }
    let method = t.surface_method.unwrap_or(Method::Geometric);
    if method == Method::Wave && t.surface_filter_um.is_some() {
        return Err(
            "`target.surface_filter_um` goes with the geometric estimate: the wave estimate resolves what the light \
             does with detail below its wavelength itself"
                .into(),
        );
    }
    if method == Method::Geometric && (t.surface_wavelength_um.is_some() || t.surface_sigma_um.is_some()) {
        return Err(
            "`target.surface_wavelength_um` and `target.surface_sigma_um` go with `target.surface_method = \"wave\"`"
                .into(),
        );
    }
    if scan.contains(',') {
        return Err(format!("`target.surface`: the path `{scan}` must not contain a comma"));
    }
    let mut spec = format!("surface:{scan}");
    if let Some(p) = t.surface_pitch_um {
        spec += &format!(",pitch_um={p}");
    }
    if let Some(f) = t.surface_filter_um {
        spec += &format!(",filter_um={f}");
    }
    if let Some(m) = &t.material {
        if m.contains(',') || m.contains('=') {
            return Err(format!("`target.material`: `{m}` is not a material name"));
        }
        spec += &format!(",material={}", m.trim());
    }
    let spec = super::resolve_spec(&spec, dir);
    let mut target = Brdf::parse(&spec).map_err(|e| format!("`target.surface`: {e}"))?;
    if method == Method::Wave {
        let cfg = wave_config(t);
        let Model::Surface(s) = &target.model else {
            unreachable!("a surface: spec reads as a surface")
        };
        let (density, unrepresented) = wave_density(&s.path, t.surface_pitch_um, &cfg)?;
        target.model = Model::Surface(Box::new(
            s.with_density(&density, Method::Wave, unrepresented)
                .map_err(|e| format!("`target.surface`: {e}"))?,
        ));
    }
    Ok(RegionTarget {
        name: String::new(),
        color: [0; 3],
        spec,
        target,
    })
}

/// The wave-optics slope density of a scan: levelled, its Kirchhoff slice at normal incidence by FFT over
/// coherence windows, mapped to half-vector slopes ([`wave::slope_density`]) on the target's grid; and the
/// share of the scan the slice cannot hold — its slopes of `|∇h| ≥ 1/ξ3 = 0.5`, which this model sends beyond
/// the horizon, and whatever of the slice falls off the grid — to be counted beyond it.
pub fn wave_density(
    path: &Path,
    pitch_um: Option<f64>,
    cfg: &WaveConfig,
) -> Result<(crate::base::slope::SlopeGrid, f64), String> {
    let err = |e: String| format!("`target.surface`: {e}");
    if cfg.size() > MAX_WAVE_FFT {
        return Err(format!(
            "`target.surface_sigma_um` = {} µm at `target.surface_wavelength_um` = {} µm needs {}² FFTs per coherence \
             window; at most {MAX_WAVE_FFT}² (σ ≤ {:.1} µm at this wavelength)",
            cfg.sigma_um,
            cfg.wavelength_um,
            cfg.size(),
            MAX_WAVE_FFT as f64 * cfg.sample() / 8.0
        ));
    }
    let mut scan = Scan::read(path, pitch_um).map_err(|e| err(e.to_string()))?;
    scan.level();
    let surf = OpticalSurface::new(&scan.hf).map_err(|e| err(e.to_string()))?;
    let slice =
        wave::fft_slice(&surf, &Vec3::new(0.0, 0.0, 1.0), cfg).map_err(|e| err(format!("{}: {e}", path.display())))?;
    let (grid, off_grid) = wave::slope_density(&slice, surface::domain());
    let slopes = scan.slopes(0.0);
    let limit = 1.0 / slice.xi3;
    let steep = slopes.iter().filter(|(p, q)| p.hypot(*q) >= limit).count() as f64 / slopes.len().max(1) as f64;
    Ok((grid, steep + (1.0 - steep) * off_grid))
}

/// The largest FFT side of the wave estimate (a 2048² complex grid is 64 MB per window in flight).
pub const MAX_WAVE_FFT: usize = 2048;

/// The report's figures of a surface target: the scan beside the simulated replica, and the scan's BRDF
/// at normal incidence by both estimates (geometric from its pre-filtered slopes, wave from its Kirchhoff
/// slice), whichever of the two the job aimed at. `None` for any other target; an error (a scan too small for
/// the wave optics, say) the caller turns into a note.
pub(super) fn figures(
    t: &TargetSection,
    target: &Brdf,
    replica: &crate::base::heightfield::Heightfield,
) -> Result<Option<Vec<crate::stages::verify::report::Figure>>, String> {
    use crate::base::plot::Canvas;
    use crate::stages::optics::geometric::MicrofacetBrdf;
    use crate::stages::verify::report::Figure;
    let Model::Surface(s) = &target.model else {
        return Ok(None);
    };
    let err = |e: String| format!("`target.surface`: {e}");
    let npy = s.path.extension().is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    let mut scan = Scan::read(&s.path, npy.then_some(s.pitch_um)).map_err(|e| err(e.to_string()))?;
    scan.level();
    let [w_um, h_um] = [s.size[0] as f64 * s.pitch_um, s.size[1] as f64 * s.pitch_um];
    let pair = Canvas::hstack(&[
        scan.hf
            .relief_png(&format!("the scan, levelled ({w_um:.0} × {h_um:.0} µm)"), 720),
        replica.relief_png("the replica, simulated from the G-code", 480),
    ]);
    let f_pair = Figure::new(
        "The measured surface and its replica",
        format!(
            "Left: the scan `{}` ({}×{} points at {:.3} µm, {} missing and filled for display), its mean plane \
             ({:.4}, {:.4}) removed; RMS height {:.2} µm. Right: the milled part as the simulation cuts it. The replica \
             reproduces the scan's distribution of normals (the target), not its heights: its facets are hundreds of \
             times larger, so the two reflect alike without looking alike under a microscope.",
            s.path.display(),
            s.size[0],
            s.size[1],
            s.pitch_um,
            s.missing,
            s.tilt_removed[0],
            s.tilt_removed[1],
            s.rms_height_um,
        ),
        &pair,
    );
    // both estimates of the scan's BRDF, whatever the target used
    let filter_um = s.filter_um;
    // the geometric estimate is the target's own density when the job aimed at it
    let geo_grid = match s.method {
        Method::Geometric => s.density().clone(),
        Method::Wave => crate::base::surface::ndf_of_slopes(&scan.slopes(filter_um), surface::domain()).0,
    };
    let geo = MicrofacetBrdf::new(geo_grid, None);
    let cfg = wave_config(t);
    let surf = OpticalSurface::new(&scan.hf).map_err(|e| err(e.to_string()))?;
    let wi = Vec3::new(0.0, 0.0, 1.0);
    let slice = wave::fft_slice(&surf, &wi, &cfg).map_err(|e| err(e.to_string()))?;
    let slices = crate::stages::optics::figures::wave_vs_geometric_png(&slice, &geo, &wi, 0.6);
    let filtered = if filter_um > 0.0 {
        format!("pre-filtered by a Gaussian of σ {filter_um} µm")
    } else {
        "not pre-filtered".to_string()
    };
    let used = match s.method {
        Method::Geometric => format!("geometric ({filtered})"),
        Method::Wave => format!("wave, λ {} µm, coherence σ {} µm", cfg.wavelength_um, cfg.sigma_um),
    };
    let f_brdf = Figure::new(
        "The scan's BRDF: geometric and wave optics",
        format!(
            "The scan's BRDF at normal incidence (F = 1) by geometric optics (its slopes' NDF, {filtered}) and by \
             wave optics (Kirchhoff, λ {} µm, {}×{} coherence windows of σ {} µm), \
             over the same window of directions. The job aimed at the {used} estimate (`target.surface_method`).",
            cfg.wavelength_um, cfg.windows, cfg.windows, cfg.sigma_um
        ),
        &slices,
    );
    Ok(Some(vec![f_pair, f_brdf]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A roof of facets of slope ±0.1 along x, 200 µm wide, sampled at 1 µm: wide and smooth next to the
    /// wavelength, so the wave estimate meets geometric optics' closed form (stationary phase): two equal
    /// spikes at p = ±0.1, q = 0 — slope variance 0.01 along x and none along y, with either method.
    #[test]
    fn both_estimates_of_a_roof_find_its_two_facets() {
        let dir = tempfile::tempdir().unwrap();
        let (nx, ny, period) = (800usize, 200usize, 200usize);
        let z: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let t = (k % nx) % period;
                let tri = if t < period / 2 { t } else { period - t };
                0.1 * tri as f64 * 1e-3
            })
            .collect();
        crate::base::npy::write_f64_2d(&dir.path().join("roof.npy"), ny, nx, &z).unwrap();
        for method in [Method::Geometric, Method::Wave] {
            let t = TargetSection {
                surface: Some("roof.npy".into()),
                surface_pitch_um: Some(1.0),
                surface_method: Some(method),
                material: Some("aluminium".into()),
                ..Default::default()
            };
            let r = single(&t, "roof.npy", dir.path()).unwrap();
            let Model::Surface(s) = &r.target.model else { panic!() };
            assert_eq!(s.method, method);
            let st = s.density().stats();
            // the crests' differences read 0 in the geometric estimate (1 column in 100)
            assert!(
                (st.cov[0][0] / 0.01 - 1.0).abs() < 0.03,
                "{method:?}: var p {}",
                st.cov[0][0]
            );
            assert!(st.cov[1][1] < 2e-4, "{method:?}: var q {}", st.cov[1][1]);
            assert!(st.mean[0].abs() < 2e-3, "{method:?}: mean {:?}", st.mean);
            assert!(r.spec.starts_with("surface:") && r.spec.ends_with(",pitch_um=1,material=aluminium"));
        }
    }

    /// A sawtooth of unequal facets, 20 µm rising at slope 0.1 then 5 µm falling at 0.4 (period 25 µm,
    /// sampled at 0.5 µm): by area the steep facet is 1/5 of the surface. The wave estimate gives it that
    /// share; the geometric one 9/50 (of every 50 central differences, 9 straddle only falling steps, 2 a
    /// kink). The coherence σ is 30 µm so that each Gaussian window spans five periods and weighs every phase
    /// of the sawtooth alike (its weight's ripple at the period is exp(−2π²σ²/P²) ≈ e⁻²⁸); with σ 10 µm the
    /// nine windows sit near the steep facets and read it as 0.27 of the surface.
    #[test]
    fn both_estimates_weigh_unequal_facets_by_their_area() {
        let dir = tempfile::tempdir().unwrap();
        let (nx, ny, h_um) = (1200usize, 600usize, 0.5);
        let z: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let t = (k % nx) % 50;
                let up = if t <= 40 {
                    t as f64
                } else {
                    40.0 - 4.0 * (t - 40) as f64
                };
                0.1 * up * h_um * 1e-3
            })
            .collect();
        crate::base::npy::write_f64_2d(&dir.path().join("saw.npy"), ny, nx, &z).unwrap();
        for (method, want, tol) in [(Method::Geometric, 9.0 / 50.0, 0.005), (Method::Wave, 0.2, 0.02)] {
            let t = TargetSection {
                surface: Some("saw.npy".into()),
                surface_pitch_um: Some(h_um),
                surface_method: Some(method),
                surface_sigma_um: (method == Method::Wave).then_some(30.0),
                ..Default::default()
            };
            let r = single(&t, "saw.npy", dir.path()).unwrap();
            let Model::Surface(s) = &r.target.model else { panic!() };
            let g = s.density();
            let d = g.domain;
            let steep: f64 = (0..d.ny)
                .flat_map(|j| (0..d.nx).map(move |i| (i, j)))
                .filter(|&(i, _)| d.p_at(i) < -0.25)
                .map(|(i, j)| g.at(i, j))
                .sum::<f64>()
                * d.cell_area();
            println!("{method:?}: the steep facet's share {steep:.4} (want {want:.4})");
            assert!((steep - want).abs() < tol, "{method:?}: {steep} vs {want}");
            // no slope of this surface is as steep as 0.5: the wave estimate holds all of it
            assert!(s.outside < 1e-9, "{method:?}: outside {}", s.outside);
        }
    }

    /// The keys go together as docs/JOB.md says, and each refusal names the key.
    #[test]
    fn surface_keys_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let base = TargetSection {
            surface: Some("scan.x3p".into()),
            ..Default::default()
        };
        let cases = [
            (
                TargetSection {
                    brdf: "ggx:alpha=0.2".into(),
                    ..base.clone()
                },
                "one of",
            ),
            (
                TargetSection {
                    surface_method: Some(Method::Wave),
                    surface_filter_um: Some(2.0),
                    ..base.clone()
                },
                "surface_filter_um",
            ),
            (
                TargetSection {
                    surface_sigma_um: Some(5.0),
                    ..base.clone()
                },
                "surface_sigma_um",
            ),
            (
                TargetSection {
                    surface: Some("a,b.x3p".into()),
                    ..base.clone()
                },
                "comma",
            ),
            (base.clone(), "scan.x3p"),
        ];
        for (t, want) in cases {
            let e = single(&t, t.surface.as_deref().unwrap(), dir.path()).unwrap_err();
            assert!(e.contains(want), "`{e}` should name {want}");
        }
        let stray = TargetSection {
            brdf: "ggx:alpha=0.2".into(),
            surface_filter_um: Some(1.0),
            ..Default::default()
        };
        assert!(no_surface_keys(&stray).unwrap_err().contains("surface_filter_um"));
    }
}
