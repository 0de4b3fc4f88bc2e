//! The runner behind `brdfmill run`: each stage in order, its artifacts written as they are made. Only
//! sequencing lives here; what each stage computes is the stage's own `run`.

use super::{resolve_spec, JobError, Ready};
use crate::cut::tool::Shape;
use crate::stages::brdf::Brdf;
use crate::stages::design::{self, DesignInput, Round};
use crate::stages::facets::{self, Tile, TileFile};
use crate::stages::ndf::{self, Kernel, Ndf, NdfFile};
use crate::stages::simulate::{self, Deviation, SimFile, SimulateConfig, Simulation};
use crate::stages::toolpath::{self, raster};
use crate::stages::verify::{self, report, Metrics, VerifyInput};
use std::path::{Path, PathBuf};

/// Pipeline stages, in order (for progress reporting and `--until`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
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

    /// The stage of a name (`ndf`, `facets`, `toolpath`, `simulate`, `verify`).
    pub fn parse(s: &str) -> Option<Stage> {
        [
            Stage::Ndf,
            Stage::Facets,
            Stage::Toolpath,
            Stage::Simulate,
            Stage::Verify,
        ]
        .into_iter()
        .find(|st| st.name() == s)
    }
}

/// The name of the run-state file in the output folder: `"state": "running"` from the first stage until the
/// last one asked for has written its artifacts, then `"complete"`. A run that was interrupted (Ctrl-C, a
/// crash, a full disk) leaves `"running"` behind, so its folder never passes for a finished run.
pub const RUN_STATE: &str = "run.json";

/// What `run` reports as it goes.
pub enum Progress<'a> {
    /// A stage starts.
    Started(Stage),
    /// A stage has written its artifacts.
    Finished(Stage),
    /// The design loop modelled a candidate arrangement (before the first round).
    Arrangement(&'a Round),
    /// The design loop finished a round.
    Round(&'a Round),
    /// A job with `[svbrdf]`: the design rounds that follow are this region's.
    Region(&'a str),
}

/// What the run produced.
pub struct Outcome {
    /// The metrics (`None` when the run stopped before verification, or for a job with `[svbrdf]`).
    pub metrics: Option<Metrics>,
    /// A job with `[svbrdf]`: the regions' metrics (`None` before verification).
    pub regions: Option<verify::RegionsMetrics>,
    /// The program's numbers (`None` when the run stopped before the toolpath).
    pub program: Option<toolpath::Summary>,
    /// The tile's relief (highest minus lowest point), mm (`None` before the facets).
    pub relief_mm: Option<f64>,
    /// Files written, in order.
    pub artifacts: Vec<PathBuf>,
    /// Bytes written in all.
    pub bytes_written: u64,
    /// Per stage, seconds.
    pub timings: Vec<(Stage, f64)>,
    /// The report's path (`None` before verification).
    pub report: Option<PathBuf>,
    /// The design loop's rounds and the one chosen (index), empty before the facets.
    pub rounds: (Vec<Round>, usize),
    /// The candidate arrangements' first rounds (the best became round 1), empty before the facets.
    pub arrangements: Vec<Round>,
    /// The steepest facet, degrees, and where it came from.
    pub slope_cap: (f64, String),
    /// What the run noticed about its input that the user should know (e.g. target mass beyond the NDF
    /// grid), whatever the verdict.
    pub warnings: Vec<String>,
}

/// `run.json`: the state of the run in its folder (see [`RUN_STATE`]).
fn write_state(o: &mut Out, job: &str, done: &[(Stage, f64)], state: &str) -> Result<(), JobError> {
    let v = serde_json::json!({
        "format": "brdfmill-run",
        "version": 1,
        "job": job,
        "state": state,
        "stages_done": done.iter().map(|(s, _)| s.name()).collect::<Vec<_>>(),
    });
    let p = o.dir.join(RUN_STATE);
    crate::base::io::write_atomic(&p, serde_json::to_string_pretty(&v).unwrap_or_default().as_bytes())?;
    Ok(())
}

pub(super) fn stage_error(stage: &'static str, e: impl std::fmt::Display) -> JobError {
    JobError::Stage {
        stage,
        message: e.to_string(),
    }
}

pub(super) fn stage_err<E: std::fmt::Display>(stage: &'static str) -> impl Fn(E) -> JobError {
    move |e| JobError::Stage {
        stage,
        message: e.to_string(),
    }
}

/// The NDF stage's products.
pub(super) struct NdfStage {
    pub(super) ndf: Ndf,
    pub(super) kernel: Option<Kernel>,
    pub(super) polish: Option<Brdf>,
}

/// Artifacts written so far, in order, and the stages' times.
pub(super) struct Out<'a> {
    dir: &'a Path,
    written: Vec<PathBuf>,
    job: String,
    timings: Vec<(Stage, f64)>,
    clock: std::time::Instant,
}

impl<'a> Out<'a> {
    /// Start a run into `dir`: `run.json` says it is running.
    pub(super) fn new(dir: &'a Path, job: &str) -> Result<Self, JobError> {
        let mut o = Out {
            dir,
            written: vec![],
            job: job.to_string(),
            timings: vec![],
            clock: std::time::Instant::now(),
        };
        o.state("running")?;
        Ok(o)
    }

    pub(super) fn write(&mut self, name: &str, bytes: &[u8]) -> Result<(), JobError> {
        let p = self.dir.join(name);
        crate::base::io::write_atomic(&p, bytes)?;
        self.written.push(p);
        Ok(())
    }

    /// Write a heightfield as `.npy`.
    pub(super) fn npy(&mut self, name: &str, hf: &crate::base::heightfield::Heightfield) -> Result<(), JobError> {
        let p = self.dir.join(name);
        hf.write_npy(&p)?;
        self.written.push(p);
        Ok(())
    }

    fn state(&mut self, state: &str) -> Result<(), JobError> {
        let (job, done) = (self.job.clone(), std::mem::take(&mut self.timings));
        let r = write_state(self, &job, &done, state);
        self.timings = done;
        r
    }

    /// The report's artifact table of the files written so far.
    pub(super) fn listed(&self) -> Vec<(String, String)> {
        listed(&self.written)
    }

    /// A stage starts.
    pub(super) fn start(&mut self, progress: &mut dyn FnMut(Progress), stage: Stage) {
        progress(Progress::Started(stage));
        self.clock = std::time::Instant::now();
    }

    /// A stage has written its artifacts: its time is kept and `run.json` lists it.
    pub(super) fn done(&mut self, progress: &mut dyn FnMut(Progress), stage: Stage) -> Result<(), JobError> {
        progress(Progress::Finished(stage));
        self.timings.push((stage, self.clock.elapsed().as_secs_f64()));
        self.state("running")
    }

    /// The run is complete: `run.json` says so, and the outcome gets the files, their bytes and the times.
    pub(super) fn finish(mut self, mut outcome: Outcome) -> Result<Outcome, JobError> {
        self.state("complete")?;
        outcome.bytes_written = self
            .written
            .iter()
            .filter_map(|p| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum();
        outcome.artifacts = self.written;
        outcome.timings = self.timings;
        Ok(outcome)
    }
}

/// The finishing tool's stepover, mm: given, or from the scallop height.
pub(super) fn stepover_mm(ready: &Ready, r: f64) -> f64 {
    let t = &ready.job.toolpath;
    if t.stepover_mm > 0.0 {
        t.stepover_mm
    } else {
        raster::stepover_for_scallop(r, t.scallop_um * 1e-3)
    }
}

/// An outcome with nothing in it yet.
pub(super) fn empty_outcome(ready: &Ready) -> Outcome {
    Outcome {
        metrics: None,
        regions: None,
        program: None,
        relief_mm: None,
        artifacts: vec![],
        bytes_written: 0,
        timings: vec![],
        report: None,
        rounds: (vec![], 0),
        arrangements: vec![],
        slope_cap: (ready.job.facets.max_slope_deg, ready.slope_cap_from.clone()),
        warnings: vec![],
    }
}

/// Run the stages in order up to and including `until`, writing each artifact to `out` as it is made;
/// `progress` hears of every stage's start and end and of every design round. A job with `[svbrdf]`
/// runs the regions' runner (`job::regions`).
pub fn run(ready: &Ready, out: &Path, until: Stage, progress: &mut dyn FnMut(Progress)) -> Result<Outcome, JobError> {
    if ready.labels.is_some() {
        return super::regions::run(ready, out, until, progress);
    }
    let job = &ready.job;
    let mut o = Out::new(out, &job.name)?;
    let tool = ready
        .machine
        .tool(&job.toolpath.tool)
        .map_err(stage_err("toolpath"))?
        .clone();
    let r = tool.radius_mm();
    let stepover = stepover_mm(ready, r);
    let mut outcome = empty_outcome(ready);
    o.start(progress, Stage::Ndf);
    let nd = ndf_stage(ready, &ready.target, "", r, stepover, &mut o)?;
    outcome.warnings.extend(crate::stages::ndf::grid_warning(&nd.ndf));
    o.done(progress, Stage::Ndf)?;
    if until == Stage::Ndf {
        return o.finish(outcome);
    }

    o.start(progress, Stage::Facets);
    let scallop = scallop_lobe(ready, &nd, r, stepover)?;
    let d = design_stage(ready, &nd, &ready.target, &scallop, &tool, stepover, progress)?;
    let (tile, tile_figure) = facets_stage(&nd.ndf, d.tile, "", &mut o)?;
    outcome.rounds = (d.rounds, d.chosen);
    outcome.arrangements = d.arrangements;
    o.done(progress, Stage::Facets)?;
    let (lo, hi) = tile.heightfield.range();
    outcome.relief_mm = Some(hi - lo);
    if until == Stage::Facets {
        return o.finish(outcome);
    }

    let Some(cut) = program_and_cut(
        ready,
        &tile.heightfield,
        "tile.npy",
        &tool,
        until,
        &mut o,
        &mut outcome,
        progress,
    )?
    else {
        return o.finish(outcome);
    };
    let Cut {
        program,
        sim,
        dev,
        figures: sim_figures,
    } = cut;

    o.start(progress, Stage::Verify);
    let v = verify::run(
        &job.verify,
        &VerifyInput {
            target: &ready.target,
            ndf: &nd.ndf,
            ndf_config: &job.ndf,
            base: nd.kernel.as_ref(),
            polish: nd.polish.as_ref(),
            base_is_scallop: job.target.base == "scallop",
            tile: &tile,
            sim: &sim,
            deviation: &dev,
            tool_radius_mm: r,
            stepover_mm: stepover,
            raster_angle_deg: job.toolpath.angle_deg,
            cone_deg: job.facets.max_slope_deg,
            rounds: &outcome.rounds.0,
            arrangements: &outcome.arrangements,
        },
    )
    .map_err(stage_err("verify"))?;
    o.write("wave.png", &v.wave_png.to_png())?;
    let metrics_json = serde_json::to_string_pretty(&v.metrics).map_err(stage_err("verify"))?;
    o.write("metrics.json", metrics_json.as_bytes())?;
    let mut figures = v.figures;
    figures.push(tile_figure);
    figures.extend(sim_figures);
    let html = report::Report {
        title: job.name.clone(),
        verdict: report::Verdict::Single(&v.metrics),
        figures,
        parameters: super::summary::parameters(ready, &nd.ndf, &tile, &sim),
        program: super::summary::program(ready, &program.summary, outcome.relief_mm.unwrap_or(0.0), &dev),
        artifacts: o.listed(),
    }
    .to_html();
    o.write("report.html", html.as_bytes())?;
    o.done(progress, Stage::Verify)?;
    outcome.metrics = Some(v.metrics);
    outcome.report = Some(out.join("report.html"));
    o.finish(outcome)
}

/// The design loop around the facets for `target`'s NDF stage `nd`.
pub(super) fn design_stage(
    ready: &Ready,
    nd: &NdfStage,
    target: &Brdf,
    scallop: &Kernel,
    tool: &crate::cut::machine::Tool,
    stepover: f64,
    progress: &mut dyn FnMut(Progress),
) -> Result<crate::stages::design::Design, JobError> {
    let job = &ready.job;
    let tol = &job.verify.tolerances;
    design::run(
        &job.design,
        &job.facets,
        &DesignInput {
            ndf: &nd.ndf,
            base: nd.kernel.as_ref(),
            scallop,
            tool: Shape::Ball {
                diameter_mm: tool.diameter_mm(),
            },
            stepover_mm: stepover,
            raster_angle_deg: job.toolpath.angle_deg,
            cov_band: tol.cov_ratio,
            corr_min: tol.ndf_corr_min,
            l1_max: tol.ndf_l1_max,
            highlight: target.highlight(),
            highlight_corr_min: tol.highlight_corr_min,
        },
        &mut |p| match p {
            crate::stages::design::Progress::Arrangement(r) => progress(Progress::Arrangement(r)),
            crate::stages::design::Progress::Round(r) => progress(Progress::Round(r)),
        },
    )
    .map_err(stage_err("facets"))
}

/// The program and its simulated cut.
pub(super) struct Cut {
    pub(super) program: toolpath::Toolpath,
    pub(super) sim: Simulation,
    pub(super) dev: Deviation,
    pub(super) figures: [report::Figure; 2],
}

/// The toolpath and simulate stages for `design` (written as `design_file`): `None` when `until` stops
/// before the cut is simulated (the outcome has the program's numbers once it is made).
#[allow(clippy::too_many_arguments)]
pub(super) fn program_and_cut(
    ready: &Ready,
    design: &crate::base::heightfield::Heightfield,
    design_file: &str,
    tool: &crate::cut::machine::Tool,
    until: Stage,
    o: &mut Out,
    outcome: &mut Outcome,
    progress: &mut dyn FnMut(Progress),
) -> Result<Option<Cut>, JobError> {
    o.start(progress, Stage::Toolpath);
    let program = toolpath_stage(ready, design, o)?;
    o.done(progress, Stage::Toolpath)?;
    outcome.program = Some(program.summary.clone());
    if until == Stage::Toolpath {
        return Ok(None);
    }
    o.start(progress, Stage::Simulate);
    let shape = Shape::Ball {
        diameter_mm: tool.diameter_mm(),
    };
    let (sim, dev, figures) = simulate_stage(ready, shape, &program.gcode, design, design_file, o)?;
    o.done(progress, Stage::Simulate)?;
    if until == Stage::Simulate {
        return Ok(None);
    }
    Ok(Some(Cut {
        program,
        sim,
        dev,
        figures,
    }))
}

/// The design heightfield → `program.nc`, `program.json`.
fn toolpath_stage(
    ready: &Ready,
    design: &crate::base::heightfield::Heightfield,
    o: &mut Out,
) -> Result<toolpath::Toolpath, JobError> {
    let job = &ready.job;
    let tcfg = job.toolpath_config();
    let program = toolpath::run(&tcfg, design, &ready.machine).map_err(stage_err("toolpath"))?;
    o.write("program.nc", program.gcode.as_bytes())?;
    let summary = serde_json::to_string_pretty(&program.summary).map_err(stage_err("toolpath"))?;
    o.write("program.json", summary.as_bytes())?;
    Ok(program)
}

/// `target` → NDF: the base lobe (the finishing raster's scallop lobe by default), Lucy–Richardson,
/// `ndf{suffix}.json`, `ndf{suffix}.png`.
pub(super) fn ndf_stage(
    ready: &Ready,
    target: &Brdf,
    suffix: &str,
    r: f64,
    stepover: f64,
    o: &mut Out,
) -> Result<NdfStage, JobError> {
    let job = &ready.job;
    let domain = job.ndf.domain();
    let polish = match &job.target.polish {
        Some(p) => Some(Brdf::parse(&resolve_spec(p, &ready.dir)).map_err(|e| stage_error("ndf", e))?),
        None => None,
    };
    let kernel = match job.target.base.as_str() {
        "none" => None,
        "scallop" => Some(
            Kernel::scallop(&domain, r, stepover, job.toolpath.angle_deg, polish.as_ref(), &job.ndf)
                .map_err(|e| stage_error("ndf", e))?,
        ),
        spec => {
            let b = Brdf::parse(&resolve_spec(spec, &ready.dir)).map_err(|e| stage_error("ndf", e))?;
            Some(Kernel::from_brdf(&b, &domain, &job.ndf).map_err(|e| stage_error("ndf", e))?)
        }
    };
    let n = ndf::run_with_kernel(&job.ndf, target, kernel.as_ref()).map_err(|e| stage_error("ndf", e))?;
    o.write(&format!("ndf{suffix}.json"), NdfFile::from(&n).to_json().as_bytes())?;
    o.write(&format!("ndf{suffix}.png"), &ndf::render_pair_png(&n).to_png())?;
    Ok(NdfStage { ndf: n, kernel, polish })
}

/// The finishing raster's scallop lobe with the material's polish: the base lobe when that is the scallop
/// lobe, otherwise made here (the as-milled model and the milled measurement use it either way).
pub(super) fn scallop_lobe(ready: &Ready, nd: &NdfStage, r: f64, stepover: f64) -> Result<Kernel, JobError> {
    let job = &ready.job;
    match &nd.kernel {
        Some(k) if job.target.base == "scallop" => Ok(k.clone()),
        _ => Kernel::scallop(
            &job.ndf.domain(),
            r,
            stepover,
            job.toolpath.angle_deg,
            nd.polish.as_ref(),
            &job.ndf,
        )
        .map_err(|e| stage_error("facets", e)),
    }
}

/// The design loop's tile → `tile{suffix}.json`, `.npy`, `.png`, `.stl`. Returns the tile and its relief
/// report figure.
pub(super) fn facets_stage(n: &Ndf, tile: Tile, suffix: &str, o: &mut Out) -> Result<(Tile, report::Figure), JobError> {
    let tile_file = TileFile::new(
        &tile,
        facets::format::Source {
            ndf: format!("ndf{suffix}.json"),
            brdf: n.brdf_spec.clone(),
            base: n.base_spec.clone(),
        },
        &format!("tile{suffix}.npy"),
    );
    let tile_canvas = tile.relief_png();
    let c = &tile.config;
    let tile_figure = report::Figure::new(
        "Design tile",
        format!(
            "The periodic facet heightfield ({}×{} facets of {} mm), shaded relief tinted by height.",
            c.facets_x, c.facets_y, c.facet_mm
        ),
        &tile_canvas,
    );
    o.write(&format!("tile{suffix}.json"), tile_file.to_json().as_bytes())?;
    o.npy(&format!("tile{suffix}.npy"), &tile.heightfield)?;
    o.write(&format!("tile{suffix}.png"), &tile_figure.png)?;
    o.write(&format!("tile{suffix}.stl"), &tile.stl())?;
    Ok((tile, tile_figure))
}

/// G-code → milled surface and its deviation from the design: `sim.npy`, `sim.png`, `deviation.png`,
/// `sim.json`.
fn simulate_stage(
    ready: &Ready,
    shape: Shape,
    gcode: &str,
    design: &crate::base::heightfield::Heightfield,
    design_file: &str,
    o: &mut Out,
) -> Result<(Simulation, Deviation, [report::Figure; 2]), JobError> {
    let job = &ready.job;
    let scfg = SimulateConfig {
        tool: shape,
        // each tool of the program (roughing and finishing) swept with its own shape
        tools: simulate::tool_table(&ready.machine),
        pitch_um: job.simulate.pitch_um,
        arc_tolerance_um: job.simulate.arc_tolerance_um,
        machine: Some(ready.machine.clone()),
        ..Default::default()
    };
    let sim = simulate::run(gcode, &scfg).map_err(stage_err("simulate"))?;
    let dev = simulate::deviation(&sim, design, &shape);
    o.npy("sim.npy", &sim.heightfield)?;
    let sim_canvas = sim.heightfield.relief_png("simulated milled surface", 1024);
    let sim_figure = report::Figure::new(
        "Simulated milled surface",
        format!(
            "The stock after the program, simulated at {} µm.",
            job.simulate.pitch_um
        ),
        &sim_canvas,
    );
    o.write("sim.png", &sim_figure.png)?;
    let (dev_canvas, dev_range_um) = dev.to_png("simulated - design (µm)", 1024);
    let [lo, hi] = dev_range_um;
    let dev_figure = report::Figure::new(
        "Deviation from the design",
        format!(
            "Simulated minus design height where the {} mm ball can reach the design; grey where it cannot ({:.2}% of the interior: concave corners narrower than the bit) and in the edge band. \
             The colours span {lo:.2} to {hi:.2} µm (the 0.1 and 99.9 percentiles of the cells shown; cells beyond take the end colours). \
             Largest material left where reachable {:.2} µm, anywhere {:.2} µm (in the unreachable corners); deepest cut below the design (gouge) {:.2} µm.",
            shape.diameter_mm(),
            dev.unreachable_fraction * 100.0,
            dev.max_over_reachable_um,
            dev.max_over_um,
            dev.max_under_um.max(0.0),
        ),
        &dev_canvas,
    );
    o.write("deviation.png", &dev_figure.png)?;
    o.write(
        "sim.json",
        SimFile::new(&sim, &scfg, "program.nc", Some(&dev), Some(design_file.into()))
            .to_json()
            .as_bytes(),
    )?;
    Ok((sim, dev, [sim_figure, dev_figure]))
}

/// The artifact table of the report.
fn listed(written: &[PathBuf]) -> Vec<(String, String)> {
    let mut listed: Vec<(String, String)> = written
        .iter()
        .map(|p| {
            (
                p.file_name()
                    .map(|n| n.to_string_lossy().to_string())
                    .unwrap_or_default(),
                describe(p),
            )
        })
        .collect();
    listed.push(("report.html".into(), describe(Path::new("report.html"))));
    listed
}

fn describe(p: &Path) -> String {
    let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
    // a region's own files (`ndf-NAME.json`, `tile-NAME.npy`): what the single target's are, for that region
    if let Some((stem, ext)) = name.split_once('.') {
        if let Some((kind, region)) = stem.split_once('-') {
            if matches!(kind, "ndf" | "tile") {
                let what = describe(Path::new(&format!("{kind}.{ext}")));
                return format!("region `{region}`: {what}");
            }
        }
    }
    match name {
        "part.npy" => "the composed part's design heightfield, mm (NumPy)",
        "part.png" => "the composed part, shaded relief",
        "labels.png" => "the label map as read, in the regions' colours",
        "light.png" => "the simulated part under a moving light",
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
