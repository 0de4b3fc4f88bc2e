//! `JOB.toml`: every stage of the pipeline in one documented, versioned file, and the runner behind
//! `brdfmill run`.
//!
//! ```toml
//! version = 1
//! name = "isotropic GGX, aluminium"
//!
//! [target]
//! brdf = "ggx:alpha=0.3,material=aluminium"  # any BRDF spec (see README)
//! base = "scallop"                           # the base lobe deconvolved: "scallop" (the finishing raster's
//!                                            # own lobe, computed from the bit and stepover), "none", or a spec
//! polish = "beckmann:alpha=0.05"             # optional: the material's own polish lobe (with base = "scallop"
//!                                            # it is convolved into the base; the milled NDF is blurred by it)
//!
//! [machine]
//! profile = "../machines/grbl-3018.toml"     # relative to this file
//!
//! [ndf]        # NdfConfig: res, max_angle_deg, iterations, tolerance, [ndf.half_angle]
//! [facets]     # FacetsConfig: facets_x, facets_y, facet_mm, pitch_um, seed, max_slope_deg, ... [facets.anneal]
//! [toolpath]   # ToolpathConfig: tool, rough_tool, stock, area_mm, scallop_um, angle_deg, strategy, ...
//! [simulate]   # pitch_um, arc_tolerance_um
//! [verify]     # incident_deg, prefilter_um, [verify.tolerances]
//! ```
//!
//! Unknown keys are refused with their line; the machine profile, the tool and the combination of
//! parameters are checked before any work starts ([`Job::load`]).

use crate::brdf::Brdf;
use crate::facets::{self, FacetsConfig, TileFile};
use crate::ndf::{self, Kernel, NdfConfig, NdfFile};
use crate::optics::geometric;
use crate::simulate::{self, SimulateConfig, ToolShape};
use crate::toolpath::{self, machine::Machine, machine::ToolKind, raster, ToolpathConfig};
use crate::verify::{self, metrics, render, report, Metrics, Tolerances};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The job format version this build reads.
pub const VERSION: u32 = 1;

/// `[target]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSection {
    /// The target BRDF spec.
    pub brdf: String,
    /// `"scallop"`, `"none"` or a BRDF spec.
    #[serde(default = "default_base")]
    pub base: String,
    /// The material's own polish lobe (a BRDF spec), optional.
    #[serde(default)]
    pub polish: Option<String>,
}

fn default_base() -> String {
    "scallop".into()
}

/// `[machine]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    /// Machine profile path, relative to the job file.
    pub profile: String,
}

/// `[simulate]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateSection {
    /// Stock grid pitch, µm.
    pub pitch_um: f64,
    /// Arc linearisation tolerance, µm.
    pub arc_tolerance_um: f64,
}

impl Default for SimulateSection {
    fn default() -> Self {
        Self {
            pitch_um: 5.0,
            arc_tolerance_um: 0.1,
        }
    }
}

/// `[verify]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VerifySection {
    /// Incident angles of the BRDF slices and albedos, degrees.
    pub incident_deg: Vec<f64>,
    /// Gaussian pre-filter of the milled heights before their slopes are taken, σ in µm (0: none).
    pub prefilter_um: f64,
    /// Tolerances of the verdict.
    pub tolerances: Tolerances,
}

impl Default for VerifySection {
    fn default() -> Self {
        Self {
            incident_deg: vec![0.0, 30.0, 60.0],
            prefilter_um: 0.0,
            tolerances: Tolerances::default(),
        }
    }
}

/// A job file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Job {
    /// [`VERSION`].
    pub version: u32,
    /// A name for the report.
    pub name: String,
    /// The target.
    pub target: TargetSection,
    /// The machine.
    pub machine: MachineSection,
    /// NDF stage.
    #[serde(default)]
    pub ndf: NdfConfig,
    /// Facets stage.
    #[serde(default)]
    pub facets: FacetsConfig,
    /// Toolpath stage.
    #[serde(default)]
    pub toolpath: ToolpathConfig,
    /// Simulation.
    #[serde(default)]
    pub simulate: SimulateSection,
    /// Verification.
    #[serde(default)]
    pub verify: VerifySection,
}

/// A job that cannot run, or a stage that failed.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// The job file is wrong: the message names the key and the reason.
    #[error("{path}: {reason}")]
    Invalid {
        /// The job file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A stage failed.
    #[error("{stage}: {message}")]
    Stage {
        /// Which stage.
        stage: &'static str,
        /// Its error.
        message: String,
    },
    /// An output could not be written.
    #[error(transparent)]
    Write(#[from] crate::io::WriteError),
}

/// A job checked and ready to run: the parsed inputs it needs.
pub struct Ready {
    /// The job.
    pub job: Job,
    /// The job file's folder.
    pub dir: PathBuf,
    /// The target BRDF.
    pub target: Brdf,
    /// The machine.
    pub machine: Machine,
    /// Path of the machine profile.
    pub machine_path: PathBuf,
}

impl Job {
    /// Read a job file and check everything that can be checked before work starts.
    pub fn load(path: &Path) -> Result<Ready, JobError> {
        let invalid = |reason: String| JobError::Invalid {
            path: path.display().to_string(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| invalid(format!("cannot read the job file: {e}")))?;
        let raw: toml::Value = toml::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        match raw.get("version").and_then(|v| v.as_integer()) {
            Some(v) if v == VERSION as i64 => {}
            Some(v) => {
                return Err(invalid(format!(
                    "`version` = {v}: this build reads job files of version {VERSION}"
                )))
            }
            None => return Err(invalid(format!("missing `version` (expected version = {VERSION})"))),
        }
        let job: Job = toml::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let target =
            Brdf::parse(&resolve_spec(&job.target.brdf, &dir)).map_err(|e| invalid(format!("`target.brdf`: {e}")))?;
        if !matches!(job.target.base.as_str(), "scallop" | "none") {
            Brdf::parse(&resolve_spec(&job.target.base, &dir)).map_err(|e| invalid(format!("`target.base`: {e}")))?;
        }
        if let Some(p) = &job.target.polish {
            Brdf::parse(&resolve_spec(p, &dir)).map_err(|e| invalid(format!("`target.polish`: {e}")))?;
        }
        let machine_path = dir.join(&job.machine.profile);
        let machine = Machine::load(&machine_path).map_err(|e| invalid(format!("`machine.profile`: {e}")))?;
        let tool = machine
            .tool(&job.toolpath.tool)
            .map_err(|e| invalid(format!("`toolpath.tool`: {e}")))?;
        if tool.kind != ToolKind::Ball {
            return Err(invalid(format!(
                "`toolpath.tool` = `{}` is {:?}: finishing needs a ball-nose",
                tool.id, tool.kind
            )));
        }
        job.ndf.validate().map_err(|e| invalid(e.to_string()))?;
        job.facets.validate().map_err(|e| invalid(e.to_string()))?;
        if tool.diameter_mm > job.facets.facet_mm + 1e-9 {
            return Err(invalid(format!(
                "impossible combination: `toolpath.tool` `{}` is {} mm across, larger than a facet (`facets.facet_mm` = {} mm); the bit could not cut one facet's plane",
                tool.id, tool.diameter_mm, job.facets.facet_mm
            )));
        }
        let [ax, ay] = job.toolpath.area_mm;
        if ax > machine.travel.x_mm || ay > machine.travel.y_mm {
            return Err(invalid(format!(
                "impossible combination: `toolpath.area_mm` = [{ax}, {ay}] is larger than the machine's travel {}×{} mm ({})",
                machine.travel.x_mm,
                machine.travel.y_mm,
                machine_path.display()
            )));
        }
        if !(ax > 0.0 && ay > 0.0) {
            return Err(invalid(format!(
                "`toolpath.area_mm` must be positive, got [{ax}, {ay}]"
            )));
        }
        if job.simulate.pitch_um.is_nan() || job.simulate.pitch_um <= 0.0 {
            return Err(invalid(format!(
                "`simulate.pitch_um` must be positive, got {}",
                job.simulate.pitch_um
            )));
        }
        if job.verify.incident_deg.iter().any(|t| !(0.0..90.0).contains(t)) || job.verify.incident_deg.is_empty() {
            return Err(invalid("`verify.incident_deg` must list angles in [0, 90)".into()));
        }
        Ok(Ready {
            job,
            dir,
            target,
            machine,
            machine_path,
        })
    }
}

/// Paths in `merl:`, `rgl:` and `csv:` specs are relative to the job file.
fn resolve_spec(spec: &str, dir: &Path) -> String {
    for kind in ["merl:", "rgl:", "csv:"] {
        if let Some(rest) = spec.strip_prefix(kind) {
            let (path, tail) = rest
                .split_once(',')
                .map(|(a, b)| (a, format!(",{b}")))
                .unwrap_or((rest, String::new()));
            let p = Path::new(path.trim());
            let full = if p.is_absolute() { p.to_path_buf() } else { dir.join(p) };
            return format!("{kind}{}{tail}", full.display());
        }
    }
    spec.to_string()
}

/// Pipeline stages, for progress reporting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// BRDF → NDF.
    Ndf,
    /// NDF → tile.
    Facets,
    /// Tile → G-code.
    Toolpath,
    /// G-code → milled surface.
    Simulate,
    /// Metrics, figures, report.
    Verify,
}

impl Stage {
    /// Display name.
    pub fn name(&self) -> &'static str {
        match self {
            Stage::Ndf => "ndf",
            Stage::Facets => "facets",
            Stage::Toolpath => "toolpath",
            Stage::Simulate => "simulate",
            Stage::Verify => "verify",
        }
    }
}

/// What the run produced.
pub struct Outcome {
    /// The metrics.
    pub metrics: Metrics,
    /// Files written, in order.
    pub artifacts: Vec<PathBuf>,
    /// Per stage, seconds.
    pub timings: Vec<(Stage, f64)>,
    /// The report's path.
    pub report: PathBuf,
}

fn stage_err(stage: &'static str) -> impl Fn(String) -> JobError {
    move |message| JobError::Stage { stage, message }
}

/// Run every stage in order, writing each artifact to `out` as it is made. `progress(stage, started)` is
/// called when a stage starts (`true`) and ends (`false`).
pub fn run(ready: &Ready, out: &Path, progress: &mut dyn FnMut(Stage, bool)) -> Result<Outcome, JobError> {
    let job = &ready.job;
    let mut artifacts = vec![];
    let mut timings = vec![];
    let mut clock = std::time::Instant::now();
    let mut lap = |stage: Stage, timings: &mut Vec<(Stage, f64)>| {
        timings.push((stage, clock.elapsed().as_secs_f64()));
        clock = std::time::Instant::now();
    };
    let tool = ready
        .machine
        .tool(&job.toolpath.tool)
        .map_err(stage_err("toolpath"))?
        .clone();
    let r = tool.radius_mm();
    let stepover = if job.toolpath.stepover_mm > 0.0 {
        job.toolpath.stepover_mm
    } else {
        raster::stepover_for_scallop(r, job.toolpath.scallop_um * 1e-3)
    };

    // 1. ndf
    progress(Stage::Ndf, true);
    let domain = job.ndf.domain();
    let polish = match &job.target.polish {
        Some(p) => Some(Brdf::parse(&resolve_spec(p, &ready.dir)).map_err(|e| stage_err("ndf")(e.to_string()))?),
        None => None,
    };
    let kernel = match job.target.base.as_str() {
        "none" => None,
        "scallop" => Some(
            Kernel::scallop(&domain, r, stepover, job.toolpath.angle_deg, polish.as_ref(), &job.ndf)
                .map_err(|e| stage_err("ndf")(e.to_string()))?,
        ),
        spec => {
            let b = Brdf::parse(&resolve_spec(spec, &ready.dir)).map_err(|e| stage_err("ndf")(e.to_string()))?;
            Some(Kernel::from_brdf(&b, &domain, &job.ndf).map_err(|e| stage_err("ndf")(e.to_string()))?)
        }
    };
    let n =
        ndf::run_with_kernel(&job.ndf, &ready.target, kernel.as_ref()).map_err(|e| stage_err("ndf")(e.to_string()))?;
    let ndf_file = NdfFile::from(&n);
    write(out, "ndf.json", ndf_file.to_json().as_bytes(), &mut artifacts)?;
    write(out, "ndf.png", &ndf::render_pair_png(&n).to_png(), &mut artifacts)?;
    progress(Stage::Ndf, false);
    lap(Stage::Ndf, &mut timings);

    // 2. facets
    progress(Stage::Facets, true);
    let tile = facets::run(&job.facets, &n.target).map_err(|e| stage_err("facets")(e.to_string()))?;
    let tile_file = TileFile::new(
        &tile,
        facets::format::Source {
            ndf: "ndf.json".into(),
            brdf: n.brdf_spec.clone(),
            base: n.base_spec.clone(),
        },
        "tile.npy",
    );
    let tile_png = tile.relief_png();
    write(out, "tile.json", tile_file.to_json().as_bytes(), &mut artifacts)?;
    tile.heightfield.write_npy(&out.join("tile.npy"))?;
    artifacts.push(out.join("tile.npy"));
    write(out, "tile.png", &tile_png.to_png(), &mut artifacts)?;
    write(out, "tile.stl", &tile.stl(), &mut artifacts)?;
    progress(Stage::Facets, false);
    lap(Stage::Facets, &mut timings);

    // 3. toolpath
    progress(Stage::Toolpath, true);
    let mut tcfg = job.toolpath.clone();
    if tcfg.job == ToolpathConfig::default().job {
        tcfg.job = job.name.clone();
    }
    let program =
        toolpath::run(&tcfg, &tile.heightfield, &ready.machine).map_err(|e| stage_err("toolpath")(e.to_string()))?;
    write(out, "program.nc", program.gcode.as_bytes(), &mut artifacts)?;
    write(
        out,
        "program.json",
        serde_json::to_string_pretty(&program.summary).unwrap().as_bytes(),
        &mut artifacts,
    )?;
    progress(Stage::Toolpath, false);
    lap(Stage::Toolpath, &mut timings);

    // 4. simulate
    progress(Stage::Simulate, true);
    let shape = ToolShape::Ball {
        diameter_mm: tool.diameter_mm,
    };
    let scfg = SimulateConfig {
        tool: shape,
        pitch_um: job.simulate.pitch_um,
        arc_tolerance_um: job.simulate.arc_tolerance_um,
        machine: Some(ready.machine.clone()),
        ..Default::default()
    };
    let sim = simulate::run(&program.gcode, &scfg).map_err(|e| stage_err("simulate")(e.to_string()))?;
    let dev = simulate::deviation(&sim, &tile.heightfield, &shape);
    sim.heightfield.write_npy(&out.join("sim.npy"))?;
    artifacts.push(out.join("sim.npy"));
    let sim_png = sim.heightfield.relief_png("simulated milled surface", 1024);
    write(out, "sim.png", &sim_png.to_png(), &mut artifacts)?;
    let dev_png = dev.to_png("simulated − design", 1024);
    write(out, "deviation.png", &dev_png.to_png(), &mut artifacts)?;
    write(
        out,
        "sim.json",
        serde_json::to_string_pretty(&(&sim.stats, &dev)).unwrap().as_bytes(),
        &mut artifacts,
    )?;
    progress(Stage::Simulate, false);
    lap(Stage::Simulate, &mut timings);

    // 5. verify
    progress(Stage::Verify, true);
    let v = &job.verify;
    let tol = v.tolerances;
    let facet_slopes: Vec<(f64, f64)> = tile
        .arrangement
        .p
        .iter()
        .copied()
        .zip(tile.arrangement.q.iter().copied())
        .collect();
    let (design_raw, _) = geometric::ndf_of_slopes(&facet_slopes, domain);
    let design = match &kernel {
        Some(k) => normalised(k.convolve(&design_raw)),
        None => design_raw,
    };
    // the milled surface away from the stock's edge: the outer r is only grazed by the bit, and the next r is
    // cut by ball positions on one side only (the tool centre stays inside the area)
    let margin = ((2.0 * r + 2.0 * tile.heightfield.pitch_mm) / sim.heightfield.pitch_mm).ceil() as usize;
    let (milled_raw, outside) = geometric::ndf(&sim.heightfield, domain, v.prefilter_um, margin);
    let polish_kernel = match &polish {
        Some(p) if job.target.base == "scallop" => {
            Some(Kernel::from_brdf(p, &domain, &job.ndf).map_err(|e| stage_err("verify")(e.to_string()))?)
        }
        _ => None,
    };
    let milled = match &polish_kernel {
        Some(k) => normalised(k.convolve(&milled_raw)),
        None => milled_raw.clone(),
    };
    let design_m = metrics::measure(&n.observed, &design, &ready.target, &v.incident_deg, &tol);
    let milled_m = metrics::measure(&n.observed, &milled, &ready.target, &v.incident_deg, &tol);
    let mut notes = explain(&milled_m, &design_m, &dev, &tol, r, stepover, outside, job);
    if tile.sampling.steep_mass > 1e-4 {
        notes.push(format!(
            "{:.2}% of the target NDF's mass lies beyond the machinable limit of {}° and was dropped from the facets.",
            tile.sampling.steep_mass * 100.0,
            job.facets.max_slope_deg
        ));
    }
    // Wave optics of a patch of the milled surface (normal incidence, λ = 0.55 µm, σ = 10 µm) beside the
    // geometric BRDF of the same patch, and the diffraction check of the scallop period.
    let (wave_png, wave_albedo) = wave_patch(
        &sim.heightfield,
        margin,
        ready.target.material,
        job.facets.max_slope_deg,
    )
    .map_err(|e| stage_err("verify")(e))?;
    write(out, "wave.png", &wave_png.to_png(), &mut artifacts)?;
    let o_std = n.observed_stats.cov[0][0].max(n.observed_stats.cov[1][1]).sqrt();
    let diffraction = crate::optics::wave::diffraction_warning(stepover, 0.55, (2.0 * o_std).atan(), 10.0);
    if let Some(w) = &diffraction {
        notes.push(format!("Diffraction: {w}"));
    }
    let reference = format!(
        "the observed half-angle distribution O of `{}`; the design is convolved with the base lobe `{}`, the milled surface with {}",
        n.brdf_spec,
        n.base_spec.as_deref().unwrap_or("none"),
        polish_kernel.as_ref().map(|k| format!("the polish lobe `{}`", k.label)).unwrap_or_else(|| "nothing (the simulation models the whole base lobe)".into())
    );
    let metrics = Metrics {
        version: 1,
        pass: milled_m.pass,
        design: design_m,
        milled: milled_m,
        tolerances: tol,
        reference,
        notes,
        diffraction,
    };
    write(
        out,
        "metrics.json",
        serde_json::to_string_pretty(&metrics).unwrap().as_bytes(),
        &mut artifacts,
    )?;

    // figures
    let ndf_row = crate::plot::Canvas::hstack(&[
        ndf::render_png(&n.observed, "target: observed O"),
        ndf::render_png(&design, "design tile ⊛ base lobe"),
        ndf::render_png(&milled, "milled (simulated)"),
    ]);
    let design_brdf = geometric::MicrofacetBrdf::new(design.clone(), ready.target.material);
    let milled_brdf = geometric::MicrofacetBrdf::new(milled.clone(), ready.target.material);
    let tf = |a: &crate::geometry::Vec3, b: &crate::geometry::Vec3| ready.target.eval(a, b);
    let df = |a: &crate::geometry::Vec3, b: &crate::geometry::Vec3| design_brdf.eval(a, b);
    let mf = |a: &crate::geometry::Vec3, b: &crate::geometry::Vec3| milled_brdf.eval(a, b);
    let items: [(&str, render::BrdfFn); 3] = [("target", &tf), ("design tile", &df), ("milled", &mf)];
    let slices = render::slices(&items, &v.incident_deg);
    let spheres = render::sphere_row(&items, 260, 1.0);
    let figures = vec![
        report::Figure {
            title: "NDFs".into(),
            caption: "Slope densities P22 (log scale over four decades) on the target's grid: the target's observed distribution, the design tile's facets blurred by the base lobe, and the simulated milled surface.".into(),
            png: ndf_row.to_png(),
        },
        report::Figure {
            title: "BRDF slices".into(),
            caption: "f·cosθo (luminance) in the plane of incidence for each incident angle.".into(),
            png: slices.to_png(),
        },
        report::Figure {
            title: "Rendered preview".into(),
            caption: "Spheres of the target material and of the fabricated surfaces' microfacet BRDFs under the same two lights (orthographic view, raster direction horizontal).".into(),
            png: spheres.to_png(),
        },
        report::Figure {
            title: "Wave optics of the milled surface".into(),
            caption: format!(
                "Kirchhoff BRDF (FFT, λ = 0.55 µm, Gaussian coherence σ = 10 µm, 3×3 windows) of a 0.4 mm patch of the simulated surface at normal incidence, beside the geometric microfacet BRDF of the same patch. Wave albedo {wave_albedo:.3}. Scallop stepover {:.1} µm: {}",
                stepover * 1000.0,
                if metrics.diffraction.is_some() { "its diffraction orders fall inside the lobe (see Why)." } else { "no resolved diffraction orders inside the lobe." }
            ),
            png: wave_png.to_png(),
        },
        report::Figure {
            title: "Design tile".into(),
            caption: format!("The periodic facet heightfield ({}×{} facets of {} mm), shaded relief tinted by height.", job.facets.facets_x, job.facets.facets_y, job.facets.facet_mm),
            png: tile_png.to_png(),
        },
        report::Figure {
            title: "Simulated milled surface".into(),
            caption: format!("The stock after the program, simulated at {} µm.", job.simulate.pitch_um),
            png: sim_png.to_png(),
        },
        report::Figure {
            title: "Deviation from the design".into(),
            caption: format!(
                "Simulated minus design height. Largest material left {:.2} µm, largest gouge {:.2} µm; {:.2}% of the interior is unreachable for a {} mm ball.",
                dev.max_over_um, dev.max_under_um, dev.unreachable_fraction * 100.0, tool.diameter_mm
            ),
            png: dev_png.to_png(),
        },
    ];
    let s = &program.summary;
    let parameters = vec![
        ("target BRDF".into(), n.brdf_spec.clone()),
        ("base lobe".into(), n.base_spec.clone().unwrap_or_else(|| "none".into())),
        (
            "NDF grid".into(),
            format!("{}² over |p|,|q| ≤ tan {}°", job.ndf.res, job.ndf.max_angle_deg),
        ),
        (
            "deconvolution".into(),
            format!(
                "{} iterations ({:?})",
                n.deconvolution.iterations, n.deconvolution.stopped_by
            ),
        ),
        (
            "facets".into(),
            format!(
                "{}×{} of {} mm at {} µm, seed {}",
                job.facets.facets_x, job.facets.facets_y, job.facets.facet_mm, job.facets.pitch_um, job.facets.seed
            ),
        ),
        (
            "arrangement energy".into(),
            format!(
                "{:.2}% of random, {} valleys (random {:.0})",
                100.0 * tile.anneal.energy.total() / tile.anneal.energy_random.total(),
                tile.anneal.energy.valleys,
                tile.anneal.energy_random.valleys
            ),
        ),
        (
            "machine".into(),
            format!("{} ({})", ready.machine.name, ready.machine_path.display()),
        ),
        (
            "tool".into(),
            format!(
                "{} ({} mm ball), stock {:?}",
                tool.id, tool.diameter_mm, job.toolpath.stock
            ),
        ),
        (
            "area".into(),
            format!("{} × {} mm", job.toolpath.area_mm[0], job.toolpath.area_mm[1]),
        ),
        (
            "simulation".into(),
            format!(
                "{} µm pitch, {} cells",
                job.simulate.pitch_um,
                sim.stats.cells[0] * sim.stats.cells[1]
            ),
        ),
    ];
    let prog = vec![
        ("lines".into(), s.lines.to_string()),
        (
            "stepover".into(),
            format!("{:.4} mm (scallop {:.3} µm)", s.stepover_mm, s.scallop_um),
        ),
        (
            "passes".into(),
            format!(
                "{} finishing, {} roughing layers",
                s.finishing_passes, s.roughing_layers
            ),
        ),
        (
            "path".into(),
            format!("{:.1} mm cutting, {:.1} mm rapid", s.feed_length_mm, s.rapid_length_mm),
        ),
        ("estimated time".into(), toolpath::hms(s.estimated_s)),
        (
            "feed / spindle".into(),
            format!("{} mm/min, {} rpm", s.feed_mm_min, s.spindle_rpm),
        ),
        (
            "gouge check".into(),
            format!(
                "{} CL points, deepest {:.4} µm below the design",
                s.checked_points,
                s.max_gouge_um.max(0.0)
            ),
        ),
    ];
    let mut listed: Vec<(String, String)> = artifacts
        .iter()
        .map(|p| (p.file_name().unwrap().to_string_lossy().to_string(), describe(p)))
        .collect();
    listed.push(("report.html".into(), describe(Path::new("report.html"))));
    let html = report::Report {
        title: job.name.clone(),
        metrics: &metrics,
        figures,
        parameters,
        program: prog,
        artifacts: listed,
    }
    .to_html();
    write(out, "report.html", html.as_bytes(), &mut artifacts)?;
    progress(Stage::Verify, false);
    lap(Stage::Verify, &mut timings);
    Ok(Outcome {
        metrics,
        artifacts,
        timings,
        report: out.join("report.html"),
    })
}

/// The wave and geometric BRDFs of a 0.4 mm patch at the centre of the milled surface's interior.
fn wave_patch(
    hf: &crate::heightfield::Heightfield,
    margin: usize,
    material: Option<crate::brdf::ConductorIor>,
    max_slope_deg: f64,
) -> Result<(crate::plot::Canvas, f64), String> {
    use crate::optics::wave::{self, OpticalSurface, WaveConfig};
    let p = hf.pitch_mm;
    let side = ((0.4 / p).round() as usize)
        .min(hf.nx.saturating_sub(2 * margin))
        .min(hf.ny.saturating_sub(2 * margin));
    if side < 16 {
        return Err("the milled surface is too small for a wave-optics patch".into());
    }
    let (i0, j0) = ((hf.nx - side) / 2, (hf.ny - side) / 2);
    let mut patch = crate::heightfield::Heightfield::flat(side, side, p, false, 0.0);
    for j in 0..side {
        for i in 0..side {
            patch.z_mm[j * side + i] = hf.at(i0 + i, j0 + j);
        }
    }
    let max_slope = max_slope_deg.to_radians().tan();
    let (geo_ndf, _) = geometric::ndf(&patch, crate::slope::SlopeDomain::square(129, 1.2 * max_slope), 0.0, 1);
    let geo = geometric::MicrofacetBrdf::new(geo_ndf, material);
    let surf = OpticalSurface::new(&patch).map_err(|e| e.to_string())?;
    let cfg = WaveConfig {
        material,
        ..Default::default()
    };
    let wi = crate::geometry::Vec3::z();
    let slice = wave::fft_slice(&surf, &wi, &cfg).map_err(|e| e.to_string())?;
    Ok((
        crate::analyze::wave_vs_geometric_png(&slice, &geo, &wi, max_slope),
        slice.albedo(),
    ))
}

fn normalised(mut g: crate::slope::SlopeGrid) -> crate::slope::SlopeGrid {
    g.normalise();
    g
}

fn write(out: &Path, name: &str, bytes: &[u8], artifacts: &mut Vec<PathBuf>) -> Result<(), JobError> {
    let p = out.join(name);
    crate::io::write_atomic(&p, bytes)?;
    artifacts.push(p);
    Ok(())
}

fn describe(p: &Path) -> String {
    match p.file_name().and_then(|n| n.to_str()).unwrap_or("") {
        "ndf.json" => "target NDF and observed distribution (versioned JSON)",
        "ndf.png" => "observed and target NDF",
        "tile.json" => "facet tile: slopes, heights, stats",
        "tile.npy" => "tile heightfield, mm (NumPy)",
        "tile.png" => "tile shaded relief",
        "tile.stl" => "faceted solid of one tile (binary STL, mm)",
        "program.nc" => "G-code",
        "program.json" => "G-code summary",
        "sim.npy" => "simulated milled heightfield, mm (NumPy)",
        "sim.png" => "simulated surface shaded relief",
        "deviation.png" => "simulated minus design",
        "sim.json" => "simulation and deviation statistics",
        "metrics.json" => "verification metrics and verdict",
        "wave.png" => "wave (Kirchhoff) and geometric BRDF of a milled patch",
        "report.html" => "this report",
        _ => "",
    }
    .to_string()
}

/// Plain-word explanations of where the milled surface falls short and why.
#[allow(clippy::too_many_arguments)]
fn explain(
    milled: &verify::SurfaceMetrics,
    design: &verify::SurfaceMetrics,
    dev: &simulate::deviation::Deviation,
    tol: &Tolerances,
    r: f64,
    stepover: f64,
    outside: f64,
    job: &Job,
) -> Vec<String> {
    let mut notes = vec![];
    if !design.pass {
        notes.push(format!(
            "The design tile itself misses (correlation {:.3}, variance ratio {:.3}/{:.3}): {} facets sample the NDF coarsely; more facets or a wider base lobe smooth it.",
            design.ndf_corr,
            design.cov_ratio[0],
            design.cov_ratio[1],
            job.facets.facets_x * job.facets.facets_y
        ));
    }
    if milled.ndf_corr < tol.ndf_corr_min {
        notes.push(format!(
            "Milled NDF correlation {:.3} is {:.3} short of {}.",
            milled.ndf_corr,
            tol.ndf_corr_min - milled.ndf_corr,
            tol.ndf_corr_min
        ));
    }
    for (k, axis) in ["x", "y"].iter().enumerate() {
        let c = milled.cov_ratio[k];
        if c < tol.cov_ratio[0] || c > tol.cov_ratio[1] {
            let why = if c > 1.0 {
                format!(
                    "wider than the target: the ball (r = {r} mm) rounds the convex facet edges into slopes between the facets', and the scallops (stepover {stepover:.4} mm) add slope across the raster"
                )
            } else {
                "narrower than the target: the ball cannot reach concave corners, so steep facet slopes near valleys are cut shallower".to_string()
            };
            notes.push(format!("Slope variance along {axis} is {c:.3}× the target's, {why}."));
        }
    }
    if dev.unreachable_fraction > 0.001 {
        notes.push(format!(
            "{:.2}% of the surface is unreachable for the {} mm ball (concave corners narrower than the bit); there the milled slopes are the bit's, not the design's.",
            dev.unreachable_fraction * 100.0,
            2.0 * r
        ));
    }
    if outside > 1e-3 {
        notes.push(format!(
            "{:.2}% of the milled slopes fall outside the NDF grid (walls at facet steps).",
            outside * 100.0
        ));
    }
    notes
}
