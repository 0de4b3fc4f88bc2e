//! `brdfmill compare SCAN --job OUTDIR`: a scan of the milled part against the job that made it.
//!
//! The job is read back from its output folder (`job.toml`, its paths from `run.json`'s `job_dir`) and its
//! target's NDF remade; the scan is registered to the simulated cut (`sim.x3p`,
//! [`crate::base::register`]: quarter turns and small angles, translation, tilt and offset), read onto the
//! simulation's grid, and measured exactly as the verdict measures the cut ([`Gauge`]): in the
//! verdict's window of whole tiles when the scan covers it, otherwise in the largest window of whole tiles
//! it covers in the part's interior. The simulated cut is measured in the same window beside it, so the
//! two columns differ only by what the part differs from the simulation.
//!
//! The scan passes when it registers (its slopes agree with the simulated cut's to at least
//! [`CompareConfig::min_correlation`]: a scan of another part does not) and its figures meet the job's
//! tolerances. A drawn highlight's target is refused (the verdict judges it by the image, which needs the
//! design). Written into the output folder: `compare.json`, `compare.html`, `difference.png` (scan − simulation)
//! and `ndf-scan.json` (the scan's NDF, `ndf.json`'s format).

use super::runner::JOB_AS_RUN;
use super::stages::ndf_of;
use super::{Job, JobError, StageError};
use crate::base::heightfield::Heightfield;
use crate::base::plot::{Canvas, Heatmap, Scale};
use crate::base::register::{self, Grid, Registered};
use crate::base::scan::Scan;
use crate::stages::ndf::format::DensityOf;
use crate::stages::ndf::{self, NdfFile};
use crate::stages::verify::milled::{reach_cells, Window};
use crate::stages::verify::report::{self, Figure};
use crate::stages::verify::{Gauge, SurfaceMetrics, Tolerances};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The simulated cut a job's output folder holds.
pub const SIM_X3P: &str = "sim.x3p";

/// How a scan is compared.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompareConfig {
    /// The least agreement of its slopes with the simulated cut's at which the scan is taken to be of
    /// this part.
    pub min_correlation: f64,
    /// The pitch of a `.npy` scan, µm (an X3P file carries its own).
    pub pitch_um: Option<f64>,
}

impl Default for CompareConfig {
    fn default() -> Self {
        Self {
            min_correlation: 0.95,
            pitch_um: None,
        }
    }
}

/// The registration as `compare.json` records it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationFigures {
    /// The whole rotation of the simulation's frame in the scan's, degrees (quarter turns and the small angle).
    pub rotation_deg: f64,
    /// The translation, mm, in the scan's frame (the simulation's centre lands at the scan's centre plus it).
    pub shift_mm: [f64; 2],
    /// The scan was read with its rows in reverse order (its instrument counts rows from the other edge)
    /// before the rotation and translation.
    #[serde(default)]
    pub mirrored: bool,
    /// The scan's tilt against the simulated cut, removed, degrees.
    pub tilt_deg: f64,
    /// The height offset removed, µm.
    pub offset_um: f64,
    /// The coarse search's best normalised cross-correlation.
    pub coarse_correlation: f64,
    /// Correlation of the registered scan's heights with the simulated cut's over their overlap.
    pub correlation: f64,
    /// Agreement of their slopes, each the difference across one stepover
    /// ([`crate::base::register`]): what decides that the scan is of this part (heights alone are
    /// dominated by the relief's long waves, which another design of the same target shares).
    pub slope_correlation: f64,
    /// The least slope agreement taken as a scan of this part.
    pub min_correlation: f64,
    /// Share of the simulated cut the scan covers.
    pub coverage: f64,
    /// RMS of the registered scan less the simulated cut over the overlap, µm.
    pub residual_rms_um: f64,
    /// The slopes' agreement reaches `min_correlation`.
    pub registered: bool,
}

/// `compare.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// `"brdfmill-compare"`.
    pub format: String,
    /// Format version.
    pub version: u32,
    /// The scan file.
    pub scan_file: String,
    /// The job's output folder.
    pub job_dir: String,
    /// The registration.
    pub registration: RegistrationFigures,
    /// The cells measured, on the simulated cut's grid (absent: the scan does not register, and is not
    /// measured).
    pub window: Option<Window>,
    /// The window is the verdict's own (else the largest of whole tiles the scan covers).
    pub window_is_verdicts: bool,
    /// The scan's figures against the target, with the verdict's tolerances.
    pub scan: Option<SurfaceMetrics>,
    /// The simulated cut's in the same window (the verdict's `milled` when the window is the verdict's).
    pub simulated: Option<SurfaceMetrics>,
    /// The tolerances.
    pub tolerances: Tolerances,
    /// The scan registers and meets every tolerance.
    pub pass: bool,
    /// Why not, one line each.
    pub reasons: Vec<String>,
}

/// Compare the scan at `scan_path` with the job whose output folder is `job_out`; write the comparison into
/// `out`. A scan that cannot be measured (no whole tile covered, unreadable) is an error; one that is
/// measured and falls short is a comparison with `pass` false.
pub fn compare(scan_path: &Path, job_out: &Path, out: &Path, cfg: &CompareConfig) -> Result<Comparison, JobError> {
    let input = |e: String| JobError::Stage {
        stage: "compare",
        error: StageError::Input(e),
    };
    let ready = reload(job_out)?;
    if ready.labels.is_some() {
        return Err(input(
            "the job has `[svbrdf]` regions: compare measures a job with one target".into(),
        ));
    }
    if ready.target().highlight().is_some() {
        // the verdict judges a drawn highlight by the image's correlation, which needs the design's NDF
        return Err(input(
            "the job's target is a drawn highlight: compare measures a target given as a BRDF or a surface (the highlight's check is not made for a scan yet)".into(),
        ));
    }
    let job = &ready.job;
    let sim = Scan::read(&job_out.join(SIM_X3P), None).map_err(|e| input(e.to_string()))?;
    let scan = Scan::read(scan_path, cfg.pitch_um).map_err(|e| input(e.to_string()))?;
    let plan = &ready.toolpath;
    let (tool, stepover) = (plan.cutting_shape(), plan.stepover_mm);
    let (nd, reg) = rayon::join(
        || ndf_of(&ready, ready.target(), &tool, stepover),
        || {
            register::register(
                &Grid::whole(&sim.hf),
                &Grid {
                    nx: scan.hf.nx,
                    ny: scan.hf.ny,
                    pitch_mm: scan.hf.pitch_mm,
                    z: scan.hf.z_mm.clone(),
                    valid: scan.valid.clone(),
                },
                stepover,
            )
        },
    );
    let nd = nd?;
    let reg = reg.map_err(|e| input(format!("{}: {e}", scan_path.display())))?;
    let f = &job.facets;
    let gauge = Gauge {
        target: ready.target(),
        ndf: &nd.ndf,
        ndf_config: &job.ndf,
        base: nd.kernel.as_ref(),
        base_is_scallop: job.target.base == "scallop",
        polish: nd.polish.as_ref(),
        tool,
        stepover_mm: stepover,
        raster_angle_deg: job.toolpath.angle_deg,
        cone_deg: f.max_slope_deg,
        tile_mm: [f.facets_x as f64 * f.facet_mm, f.facets_y as f64 * f.facet_mm],
        tile_pitch_mm: f.pitch_um * 1e-3,
    };
    let vcfg = &job.verify;
    let figures = RegistrationFigures {
        rotation_deg: reg.pose.rotation_deg(),
        shift_mm: reg.pose.shift_mm,
        mirrored: reg.pose.mirrored,
        tilt_deg: reg.tilt_deg,
        offset_um: reg.pose.plane[0] * 1e3,
        coarse_correlation: reg.coarse_correlation,
        correlation: reg.correlation,
        slope_correlation: reg.slope_correlation,
        min_correlation: cfg.min_correlation,
        coverage: reg.coverage,
        residual_rms_um: reg.residual_rms_um,
        registered: reg.slope_correlation >= cfg.min_correlation,
    };
    let mut comparison = Comparison {
        format: "brdfmill-compare".into(),
        version: 1,
        scan_file: scan_path.display().to_string(),
        job_dir: job_out.display().to_string(),
        pass: false,
        registration: figures,
        window: None,
        window_is_verdicts: false,
        scan: None,
        simulated: None,
        tolerances: vcfg.tolerances,
        reasons: vec![],
    };
    if !comparison.registration.registered {
        // not this part: nothing to measure it against
        let r = &comparison.registration;
        comparison.reasons.push(format!(
            "The scan does not register to this job's cut: at its best pose (rotation {:.2}°, {:.0}% of the cut covered) its slopes agree with the simulated cut's to {:.3}, below {:.2}, with {:.1} µm rms left between them. It is a scan of another part, or of this part where it differs from the simulation by more than its facets; it is not measured.",
            r.rotation_deg,
            r.coverage * 100.0,
            r.slope_correlation,
            cfg.min_correlation,
            r.residual_rms_um
        ));
        write(out, &comparison, None, &reg, &sim.hf).map_err(JobError::from)?;
        return Ok(comparison);
    }
    let verdicts = gauge.window(vcfg, &sim.hf).map_err(|e| input(e.to_string()))?;
    let margin = gauge.margin(sim.hf.pitch_mm);
    // measured cells the slopes reach beyond the window, and the pre-filter's ±3σ (it runs over the whole
    // grid, where a missing point holds no height)
    let reach = reach_cells(sim.hf.pitch_mm, stepover)
        .saturating_add((3.0 * vcfg.prefilter_um * 1e-3 / sim.hf.pitch_mm).ceil() as usize);
    let (window, own) = if covered(&reg.scan, &verdicts, reach) {
        (verdicts, true)
    } else {
        let w = largest_window(&reg.scan, margin, reach, gauge.tile_mm).ok_or_else(|| {
            input(format!(
                "{}: the registered scan covers {:.0}% of the simulated cut but no whole {} × {} mm tile of the part's interior (at least {:.2} mm inside its edge): a scan must hold a tile and {:.3} mm around it to be measured as the verdict measures the cut",
                scan_path.display(),
                reg.coverage * 100.0,
                gauge.tile_mm[0],
                gauge.tile_mm[1],
                margin as f64 * sim.hf.pitch_mm,
                reach as f64 * sim.hf.pitch_mm,
            ))
        })?;
        (w, false)
    };
    let scanned = Heightfield {
        nx: reg.scan.nx,
        ny: reg.scan.ny,
        pitch_mm: reg.scan.pitch_mm,
        periodic: false,
        z_mm: reg.scan.z.clone(),
    };
    let measure = |hf: &Heightfield| gauge.measure(vcfg, hf, &window);
    let ((scan_ndf, scan_outside, _), (sim_ndf, _, _)) = match rayon::join(|| measure(&scanned), || measure(&sim.hf)) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => return Err(input(e.to_string())),
    };
    let (scan_m, sim_m) = (gauge.metrics(vcfg, &scan_ndf), gauge.metrics(vcfg, &sim_ndf));
    comparison
        .reasons
        .extend(scan_m.checks.iter().filter(|c| !c.pass).map(|c| {
            format!(
                "The scan's {} is {:.4}, needs {} (the simulated cut's in the same window: {:.4}).",
                c.name,
                c.value,
                c.tolerance,
                sim_m
                    .checks
                    .iter()
                    .find(|s| s.name == c.name)
                    .map_or(f64::NAN, |s| s.value)
            )
        }));
    comparison.pass = scan_m.pass;
    comparison.window = Some(window);
    comparison.window_is_verdicts = own;
    comparison.scan = Some(scan_m);
    comparison.simulated = Some(sim_m);
    let ndfs = Ndfs {
        target: &nd.ndf,
        scan: &scan_ndf,
        scan_outside,
        sim: &sim_ndf,
    };
    write(out, &comparison, Some(ndfs), &reg, &sim.hf).map_err(JobError::from)?;
    Ok(comparison)
}

/// The NDFs a measured scan is shown with.
struct Ndfs<'a> {
    target: &'a ndf::Ndf,
    scan: &'a crate::base::slope::SlopeGrid,
    scan_outside: f64,
    sim: &'a crate::base::slope::SlopeGrid,
}

/// The job as it ran, from its output folder.
pub(super) fn reload(job_out: &Path) -> Result<super::Ready, JobError> {
    let invalid = |reason: String| JobError::Invalid {
        path: job_out.display().to_string(),
        reason,
    };
    let state = job_out.join(super::outcome::RUN_STATE);
    let text = std::fs::read_to_string(&state).map_err(|e| {
        invalid(format!(
            "cannot read {}: {e} (is this the output folder of `brdfmill run`?)",
            state.display()
        ))
    })?;
    let run: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(format!("{}: {e}", state.display())))?;
    if run.get("state").and_then(|s| s.as_str()) != Some("complete") {
        return Err(invalid(format!(
            "{}: the run did not complete (state `{}`)",
            state.display(),
            run.get("state").and_then(|s| s.as_str()).unwrap_or("missing")
        )));
    }
    let dir = run.get("job_dir").and_then(|d| d.as_str()).ok_or_else(|| {
        invalid(format!(
            "{}: no `job_dir` (written by a brdfmill before `compare`): run the job again",
            state.display()
        ))
    })?;
    let job_file = job_out.join(JOB_AS_RUN);
    if !job_file.is_file() {
        return Err(invalid(format!(
            "no {} (written by a brdfmill before `compare`): run the job again",
            JOB_AS_RUN
        )));
    }
    Job::load_in(&job_file, &PathBuf::from(dir))
}

/// Every cell of `win` and `reach` cells around it measured.
fn covered(g: &Grid, win: &Window, reach: usize) -> bool {
    let (i0, j0) = (win.i0.checked_sub(reach), win.j0.checked_sub(reach));
    let (Some(i0), Some(j0)) = (i0, j0) else {
        return false;
    };
    let (i1, j1) = (
        (win.i0 + win.nx).saturating_add(reach),
        (win.j0 + win.ny).saturating_add(reach),
    );
    if i1 > g.nx || j1 > g.ny {
        return false;
    }
    (j0..j1).all(|j| g.valid[j * g.nx + i0..j * g.nx + i1].iter().all(|v| *v))
}

/// The largest window of whole tiles inside the part's interior (`margin` cells from its edge) whose cells
/// and `reach` around them are all measured; `None` when not even one tile is.
fn largest_window(g: &Grid, margin: usize, reach: usize, tile_mm: [f64; 2]) -> Option<Window> {
    let p = g.pitch_mm;
    // missing points counted over every rectangle from the origin
    let w = g.nx + 1;
    let mut sat = vec![0u32; w * (g.ny + 1)];
    for j in 0..g.ny {
        for i in 0..g.nx {
            sat[(j + 1) * w + i + 1] =
                u32::from(!g.valid[j * g.nx + i]) + sat[j * w + i + 1] + sat[(j + 1) * w + i] - sat[j * w + i];
        }
    }
    let missing = |i0: usize, j0: usize, i1: usize, j1: usize| {
        sat[j1 * w + i1] + sat[j0 * w + i0] - sat[j0 * w + i1] - sat[j1 * w + i0]
    };
    let inner = [g.nx.checked_sub(2 * margin)?, g.ny.checked_sub(2 * margin)?];
    let most = [
        (inner[0] as f64 * p / tile_mm[0] + 1e-9).floor() as usize,
        (inner[1] as f64 * p / tile_mm[1] + 1e-9).floor() as usize,
    ];
    let mut sizes: Vec<(usize, usize)> = (1..=most[0]).flat_map(|a| (1..=most[1]).map(move |b| (a, b))).collect();
    sizes.sort_by_key(|&(a, b)| std::cmp::Reverse(a * b));
    for (kx, ky) in sizes {
        let nx = ((kx as f64 * tile_mm[0] / p).round() as usize).min(inner[0]);
        let ny = ((ky as f64 * tile_mm[1] / p).round() as usize).min(inner[1]);
        // every position while there are at most a million of them, else every fourth (each test is O(1))
        let positions = (inner[0] - nx + 1) * (inner[1] - ny + 1);
        let step = if positions <= 1_000_000 { 1 } else { 4 };
        let mut j0 = margin;
        while j0 + ny <= margin + inner[1] {
            let mut i0 = margin;
            while i0 + nx <= margin + inner[0] {
                let (a, b) = (i0.saturating_sub(reach), j0.saturating_sub(reach));
                let (c, d) = (
                    (i0 + nx).saturating_add(reach).min(g.nx),
                    (j0 + ny).saturating_add(reach).min(g.ny),
                );
                if missing(a, b, c, d) == 0 {
                    return Some(Window::new(i0, j0, nx, ny, [kx, ky], p));
                }
                i0 += step;
            }
            j0 += step;
        }
    }
    None
}

/// `compare.json`, `difference.png`, `compare.html` and, when the scan was measured, `ndf-scan.json`.
fn write(
    out: &Path,
    c: &Comparison,
    ndfs: Option<Ndfs>,
    reg: &Registered,
    sim: &Heightfield,
) -> Result<(), crate::base::io::WriteError> {
    use crate::base::io::write_atomic;
    let json = serde_json::to_string_pretty(c).unwrap_or_default();
    write_atomic(&out.join("compare.json"), json.as_bytes())?;
    let diff = difference(reg, sim);
    write_atomic(&out.join("difference.png"), &diff.to_png())?;
    let mut figures = vec![Figure::new(
        "Scan − simulated cut",
        format!(
            "The registered scan less the simulated cut, µm, where the scan covers the part (grey: not covered), on a scale of ±3 rms; the scan's tilt ({:.3}°) and offset ({:.1} µm) against the cut are removed. RMS {:.2} µm.",
            unsigned_zero(c.registration.tilt_deg, 3),
            unsigned_zero(c.registration.offset_um, 1),
            c.registration.residual_rms_um
        ),
        &diff,
    )];
    if let Some(n) = ndfs {
        write_atomic(
            &out.join("ndf-scan.json"),
            NdfFile::of_surface(n.target, DensityOf::Scan, n.scan, n.scan_outside)
                .to_json()
                .as_bytes(),
        )?;
        figures.push(Figure::new(
            "NDFs",
            "Slope densities P22 (log scale over four decades) on the target's grid: the target's observed distribution, the simulated cut's and the scan's, both measured in the same window as the verdict measures the cut.",
            &Canvas::hstack(&[
                ndf::render_png(&n.target.observed, "target: observed O"),
                ndf::render_png(n.sim, "simulated cut"),
                ndf::render_png(n.scan, "scan of the part"),
            ]),
        ));
    }
    write_atomic(&out.join("compare.html"), page(c, &figures).as_bytes())
}

/// The difference map, µm, on a colour scale of ±3 rms.
fn difference(reg: &Registered, sim: &Heightfield) -> Canvas {
    let g = &reg.scan;
    let values: Vec<f64> = (0..g.z.len())
        .map(|k| {
            if g.valid[k] {
                (g.z[k] - sim.z_mm[k]) * 1e3
            } else {
                f64::NAN
            }
        })
        .collect();
    let span = (3.0 * reg.residual_rms_um).max(0.1);
    let (w, h) = (g.nx as f64 * g.pitch_mm, g.ny as f64 * g.pitch_mm);
    Heatmap {
        values: &values,
        nx: g.nx,
        ny: g.ny,
        x_range: (0.0, w),
        y_range: (0.0, h),
        title: "scan − simulated cut".into(),
        x_label: "x (mm)".into(),
        y_label: "y (mm)".into(),
        value_label: "µm".into(),
        scale: Scale::Linear,
        value_max: Some(span),
        value_min: Some(-span),
        plot_px: 560,
        rgb: None,
    }
    .render()
}

/// `compare.html`: the verdict and why first, then the registration, the figures side by side, and the
/// checks.
fn page(c: &Comparison, figures: &[Figure]) -> String {
    let mut h = String::new();
    h.push_str(&format!(
        "<p class=\"verdict {}\">{}</p>",
        if c.pass { "ok" } else { "no" },
        report::rich(&if c.pass {
            "The scan registers to the job's simulated cut and meets every tolerance against the target.".to_string()
        } else {
            "The scan falls short.".to_string()
        })
    ));
    if !c.reasons.is_empty() {
        h.push_str("<h2>Why</h2><ul>");
        for r in &c.reasons {
            h.push_str(&format!("<li>{}</li>", report::rich(r)));
        }
        h.push_str("</ul>");
    }
    let r = &c.registration;
    let rows: Vec<(String, String)> = vec![
        ("scan".into(), format!("`{}`", c.scan_file)),
        ("job".into(), format!("`{}`", c.job_dir)),
        (
            "rotation".into(),
            format!(
                "{:.3}° (the simulation's frame in the scan's){}",
                r.rotation_deg,
                if r.mirrored {
                    "; the scan read mirrored (its rows in reverse order: its instrument counts them from the other edge)"
                } else {
                    ""
                }
            ),
        ),
        (
            "translation".into(),
            format!(
                "{:.4}, {:.4} mm",
                unsigned_zero(r.shift_mm[0], 4),
                unsigned_zero(r.shift_mm[1], 4)
            ),
        ),
        ("tilt removed".into(), format!("{:.3}°", r.tilt_deg)),
        (
            "agreement with the simulated cut".into(),
            format!(
                "slopes {:.4} (at least {:.2} to register), heights {:.4}",
                r.slope_correlation, r.min_correlation, r.correlation
            ),
        ),
        ("residual".into(), format!("{:.2} µm rms", r.residual_rms_um)),
        (
            "coverage of the simulated cut".into(),
            format!("{:.1}%", r.coverage * 100.0),
        ),
        (
            "window measured".into(),
            match &c.window {
                Some(w) => format!(
                    "{} × {} tiles, {:.2} × {:.2} mm from cell ({}, {}){}",
                    w.tiles[0],
                    w.tiles[1],
                    w.size_mm[0],
                    w.size_mm[1],
                    w.i0,
                    w.j0,
                    if c.window_is_verdicts {
                        ", the verdict's own"
                    } else {
                        ": the verdict's is not all covered, so the largest of whole tiles the scan covers"
                    }
                ),
                None => "none: the scan does not register".into(),
            },
        ),
    ];
    h.push_str("<h2>Registration</h2>");
    h.push_str(&report::key_values(&rows));
    if let (Some(sim), Some(scan)) = (&c.simulated, &c.scan) {
        h.push_str("<h2>Metrics</h2><p>Both measured as the verdict measures the milled surface (slopes averaged over one stepover across the passes, the scallop lobe convolved back), in the same window, against the target's observed distribution.</p>");
        h.push_str(&report::checks_table(&[
            ("simulated cut", sim),
            ("scan of the part", scan),
        ]));
    }
    for f in figures {
        h.push_str(&report::figure_html(f));
    }
    report::page("brdfmill compare", &format!("scan of `{}`", c.job_dir), &h)
}

/// `v` rounded to `decimals` places, a zero without its sign (so that −0.00001 prints as 0.0000, not −0.0000).
fn unsigned_zero(v: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (v * scale).round() / scale + 0.0
}
