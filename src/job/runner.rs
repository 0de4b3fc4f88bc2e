//! The runner behind `brdfmill run`: each stage in order, its artifacts written as they are made. A job
//! with one target and a job with `[svbrdf]` regions run the same stages: each target's NDF and design loop,
//! the part (the one tile, or the regions' tiles composed by the label image), one program, its simulation,
//! and the verification (the single target's, or each region's against its own target). Only sequencing
//! lives here; what each stage computes is the stage's own `run`.

use super::artifacts::Out;
use super::outcome::empty_outcome;
pub use super::outcome::{Outcome, Progress, Stage};
use super::stages::{design_stage, facets_stage, ndf_stage, program_and_cut, scallop_lobe, stage_err, Cut, NdfStage};
use super::{JobError, Ready, RegionTarget, StageError};
use crate::base::heightfield::Heightfield;
use crate::stages::facets::Tile;
use crate::stages::ndf::format::DensityOf;
use crate::stages::ndf::NdfFile;
use crate::stages::svbrdf;
use crate::stages::verify::regions::{RegionInput, RegionsInput};
use crate::stages::verify::{self, report, VerifyInput};
use std::path::Path;

/// The job as it ran, in the output folder.
pub const JOB_AS_RUN: &str = "job.toml";

/// The polish lobe's Beckmann α when the job names none (the moving-light pictures only).
const DEFAULT_POLISH_ALPHA: f64 = 0.06;

/// Run the stages in order up to and including `until`, writing each artifact to `out` as it is made;
/// `progress` hears of every stage's start and end, of every design round and of each region.
pub fn run(ready: &Ready, out: &Path, until: Stage, progress: &mut dyn FnMut(Progress)) -> Result<Outcome, JobError> {
    let mut o = Out::new(out, &ready.job.name, &ready.dir)?;
    // the job as it runs (overrides applied, budgets derived): what `brdfmill compare` measures a scan with
    o.write(JOB_AS_RUN, ready.job.to_toml().map_err(stage_err("run"))?.as_bytes())?;
    let mut outcome = empty_outcome(ready);
    let targets = prepare_targets(ready, &mut o, progress)?;

    o.start(progress, Stage::Ndf);
    let nds = ndf_all(ready, &targets, &mut o, &mut outcome)?;
    o.done(progress, Stage::Ndf)?;
    if until == Stage::Ndf {
        return o.finish(outcome);
    }

    o.start(progress, Stage::Facets);
    let designed = design_all(ready, &targets, &nds, &mut o, &mut outcome, progress)?;
    o.done(progress, Stage::Facets)?;
    if until == Stage::Facets {
        return o.finish(outcome);
    }

    let (part, part_file) = designed.part();
    let Some(cut) = program_and_cut(ready, part, part_file, until, &mut o, &mut outcome, progress)? else {
        return o.finish(outcome);
    };

    o.start(progress, Stage::Verify);
    match &ready.labels {
        Some(labels) => {
            let run = RegionsRun {
                targets: &targets,
                nds: &nds,
                labels,
            };
            verify_regions(ready, &run, designed, cut, &mut o, &mut outcome)?;
        }
        None => verify_single(ready, &targets[0], &nds[0], designed, cut, &mut o, &mut outcome)?,
    }
    o.done(progress, Stage::Verify)?;
    outcome.report = Some(out.join("report.html"));
    o.finish(outcome)
}

/// The targets as the stages read them: a MERL file the job asks for (`target.merl_from`) is written first,
/// into the output folder, and the target read back from it.
fn prepare_targets(
    ready: &Ready,
    o: &mut Out,
    progress: &mut dyn FnMut(Progress),
) -> Result<Vec<RegionTarget>, JobError> {
    let mut targets = ready.targets.clone();
    if let Some(m) = &ready.merl {
        let (target, spec, file, said) = m
            .write(o.dir(), &targets[0].spec)
            .map_err(|e| stage_err::<StageError>("ndf")(StageError::Input(e.0)))?;
        targets[0].target = target;
        targets[0].spec = spec;
        o.written_elsewhere(file);
        progress(Progress::Prepared(&said));
    }
    Ok(targets)
}

/// Each target's NDF stage (`ndf{suffix}.json`, `.png`), with the warnings of its grid.
fn ndf_all(
    ready: &Ready,
    targets: &[RegionTarget],
    o: &mut Out,
    outcome: &mut Outcome,
) -> Result<Vec<NdfStage>, JobError> {
    let (tool, stepover) = (ready.toolpath.cutting_shape(), ready.toolpath.stepover_mm);
    let mut nds = vec![];
    for t in targets {
        let nd = ndf_stage(ready, &t.target, &t.suffix(), &tool, stepover, o)?;
        let warnings = crate::stages::ndf::grid_warning(&nd.ndf).map(|w| match t.name.as_str() {
            "" => w,
            name => format!("region `{name}`: {w}"),
        });
        outcome.warnings.extend(warnings);
        nds.push(nd);
    }
    Ok(nds)
}

/// The facets stage's products: each target's tile and its figure, and with `[svbrdf]` the part composed
/// from them.
struct Designed {
    scallop: crate::stages::ndf::Kernel,
    tiles: Vec<Tile>,
    figures: Vec<report::Figure>,
    composed: Option<svbrdf::Part>,
}

impl Designed {
    /// The design the program cuts, and its file.
    fn part(&self) -> (&Heightfield, &'static str) {
        match &self.composed {
            Some(p) => (&p.heightfield, "part.npy"),
            None => (&self.tiles[0].heightfield, "tile.npy"),
        }
    }
}

/// Each target's design loop and tile (`tile{suffix}.*`); with `[svbrdf]` the part composed by the label
/// image (`part.npy`, `part.png`, `labels.png`).
fn design_all(
    ready: &Ready,
    targets: &[RegionTarget],
    nds: &[NdfStage],
    o: &mut Out,
    outcome: &mut Outcome,
    progress: &mut dyn FnMut(Progress),
) -> Result<Designed, JobError> {
    let plan = &ready.toolpath;
    let (tool, stepover) = (plan.cutting_shape(), plan.stepover_mm);
    let scallop = scallop_lobe(ready, &nds[0], &tool, stepover)?;
    let mut designed = Designed {
        scallop,
        tiles: vec![],
        figures: vec![],
        composed: None,
    };
    for (t, nd) in targets.iter().zip(nds) {
        if !t.name.is_empty() {
            progress(Progress::Region(&t.name));
        }
        let d = design_stage(ready, nd, &t.target, &designed.scallop, stepover, progress)?;
        let (rounds, chosen, arrangements) = (d.rounds.clone(), d.chosen, d.arrangements.clone());
        let (tile, mut fig) = facets_stage(&nd.ndf, d.tile, &t.suffix(), o)?;
        if t.name.is_empty() {
            outcome.rounds = (rounds, chosen);
            outcome.arrangements = arrangements;
            let (lo, hi) = tile.heightfield.range();
            outcome.relief_mm = Some(hi - lo);
        } else {
            fig.title = format!("Design tile of region `{}`", t.name);
        }
        designed.figures.push(fig);
        designed.tiles.push(tile);
    }
    if let Some(labels) = &ready.labels {
        let part = compose(ready, targets, &designed.tiles, labels, o)?;
        designed.figures.push(part.1);
        outcome.relief_mm = Some(part.0.relief_mm);
        designed.composed = Some(part.0);
    }
    Ok(designed)
}

/// The regions' tiles composed into the part by the label image: `part.npy`, `part.png`, `labels.png`.
fn compose(
    ready: &Ready,
    targets: &[RegionTarget],
    tiles: &[Tile],
    labels: &svbrdf::Labels,
    o: &mut Out,
) -> Result<(svbrdf::Part, report::Figure), JobError> {
    let hfs: Vec<&Heightfield> = tiles.iter().map(|t| &t.heightfield).collect();
    let part = svbrdf::compose(&hfs, labels, ready.job.facets.max_relief_mm).map_err(stage_err("facets"))?;
    o.npy("part.npy", &part.heightfield)?;
    let fig = report::Figure::new(
        "Composed part",
        format!(
            "The part's design: each region's tile where the label image says, laid from the work origin with one period, the tiles' {} heights aligned (offsets {}); relief {:.3} mm.",
            match part.alignment {
                svbrdf::Alignment::Mean => "mean",
                svbrdf::Alignment::Top => "top (mean alignment would exceed the relief budget)",
            },
            targets
                .iter()
                .zip(&part.offsets_mm)
                .map(|(g, off)| format!("`{}` {:+.3} mm", g.name, off))
                .collect::<Vec<_>>()
                .join(", "),
            part.relief_mm
        ),
        &part.heightfield.relief_png("composed part", 1024),
    );
    o.write("part.png", &fig.png())?;
    o.write("labels.png", &labels.figure(1024).to_png())?;
    Ok((part, fig))
}

/// The single target's verification: `wave.png`, `metrics.json`, `report.html`.
fn verify_single(
    ready: &Ready,
    target: &RegionTarget,
    nd: &NdfStage,
    designed: Designed,
    cut: Cut,
    o: &mut Out,
    outcome: &mut Outcome,
) -> Result<(), JobError> {
    let job = &ready.job;
    let Cut {
        program,
        sim,
        sim_ideal,
        dev,
        figures: sim_figures,
    } = cut;
    let tile = &designed.tiles[0];
    let input = VerifyInput {
        target: &target.target,
        ndf: &nd.ndf,
        ndf_config: &job.ndf,
        base: nd.kernel.as_ref(),
        polish: nd.polish.as_ref(),
        base_is_scallop: job.target.base == "scallop",
        tile,
        sim: &sim,
        ideal: sim_ideal.as_ref().map(|s| (s, ready.toolpath.tool.shape)),
        deviation: &dev,
        tool: ready.toolpath.cutting_shape(),
        stepover_mm: ready.toolpath.stepover_mm,
        raster_angle_deg: job.toolpath.angle_deg,
        cone_deg: job.facets.max_slope_deg,
        rounds: &outcome.rounds.0,
        arrangements: &outcome.arrangements,
    };
    // each machine error's cut is independent of the verdict's measurement: both at once keep both cores busy
    let (v, effects) = rayon::join(
        || verify::run(&job.verify, &input).map_err(stage_err("verify")),
        || machine_effects(ready, &program.texts(), &input),
    );
    let mut v = v?;
    v.metrics.machine_effects = effects?;
    v.metrics.notes.extend(ready.toolpath.notes.iter().cloned());
    o.write("wave.png", &v.wave_png.to_png())?;
    // the grids the verdict measured, so that any of its figures can be recomputed from data
    let milled_outside = v.metrics.measurement.as_ref().map_or(0.0, |m| m.outside_grid);
    for (name, what, grid, outside) in [
        ("ndf-design.json", DensityOf::Design, &v.design, v.design_outside_grid),
        ("ndf-milled.json", DensityOf::Milled, &v.milled, milled_outside),
    ] {
        o.write(
            name,
            NdfFile::of_surface(&nd.ndf, what, grid, outside).to_json().as_bytes(),
        )?;
    }
    let mut figures = std::mem::take(&mut v.figures);
    // a scan target's figures: one that cannot be drawn is a note, not a failed run
    match super::scan_target::figures(&job.target, &target.target, &sim.heightfield) {
        Ok(Some(scan)) => figures.extend(scan),
        Ok(None) => {}
        Err(e) => v
            .metrics
            .notes
            .push(format!("The scan's figures could not be drawn: {e}.")),
    }
    let metrics_json = serde_json::to_string_pretty(&v.metrics).map_err(stage_err("verify"))?;
    o.write("metrics.json", metrics_json.as_bytes())?;
    figures.extend(designed.figures);
    figures.extend(sim_figures);
    outcome.setup = super::setup::sheet(
        ready,
        &program.summary,
        outcome.relief_mm.unwrap_or(0.0),
        &dev,
        &sim.stats,
    );
    let html = report::Report {
        title: job.name.clone(),
        verdict: report::Verdict::Single(&v.metrics),
        figures,
        parameters: super::summary::parameters(
            ready,
            &nd.ndf,
            tile,
            &sim,
            v.metrics.measurement.as_ref().map(|m| m.target_mass_beyond_cone),
        ),
        program: outcome.setup.clone(),
        artifacts: o.listed(),
    }
    .to_html();
    o.write("report.html", html.as_bytes())?;
    outcome.metrics = Some(v.metrics);
    Ok(())
}

/// Each of the machine's declared errors alone (when it declares more than one): the program cut with only
/// that error and measured as the verdict measures the milled surface, so the report can say which error
/// moved what.
fn machine_effects(
    ready: &Ready,
    programs: &[&str],
    input: &VerifyInput,
) -> Result<Vec<verify::MachineEffect>, JobError> {
    let each = ready.toolpath.machine.accuracy().each();
    if each.len() < 2 {
        return Ok(vec![]);
    }
    let base = ready.job.simulate.config(&ready.toolpath);
    // the scallop lobe of the bit without runout, the same for every cut here that has none (each lobe
    // is an integral over the slope grid, worth computing once)
    let bit = ready.toolpath.tool.shape;
    let bit_lobe = if each.iter().any(|(_, acc, _)| acc.envelope(bit) == bit) {
        Some(
            crate::stages::ndf::Kernel::scallop(
                &input.ndf.config.domain(),
                &bit,
                input.stepover_mm,
                input.raster_angle_deg,
                input.polish,
                input.ndf_config,
            )
            .map_err(stage_err("verify"))?,
        )
    } else {
        None
    };
    let mut out = vec![];
    for (name, acc, alone) in each {
        let mut machine = ready.toolpath.machine.clone();
        machine.accuracy = Some(acc);
        // measured by its surface only, so swept deepest first
        let cfg = crate::stages::simulate::SimulateConfig {
            machine: Some(machine),
            surface_only: true,
            ..base.clone()
        };
        let sim = crate::stages::simulate::run_files(programs, &cfg).map_err(stage_err("simulate"))?;
        // measured with this cut's own scallop lobe (the runout's flat only when the runout is in the cut)
        let tool = acc.envelope(bit);
        let shared = bit_lobe.as_ref().filter(|_| tool == bit);
        let cut = VerifyInput {
            sim: &sim,
            tool,
            base: shared.or(input.base),
            base_is_scallop: shared.is_some(),
            ..*input
        };
        let m = verify::measure_shape(&ready.job.verify, &cut).map_err(stage_err("verify"))?;
        out.push(verify::MachineEffect {
            error: name.into(),
            what: if alone {
                acc.describe()
            } else {
                format!("{} µm TIR", ready.toolpath.machine.accuracy().runout_um)
            },
            alone,
            cov_ratio: m.cov_ratio,
            ndf_l1: m.ndf_l1,
            ndf_corr: m.ndf_corr,
        });
    }
    Ok(out)
}

/// What the regions' verification reads besides the cut.
struct RegionsRun<'a> {
    targets: &'a [RegionTarget],
    nds: &'a [NdfStage],
    labels: &'a svbrdf::Labels,
}

/// Each region against its own target (`light.png`, `metrics.json`, `report.html`).
fn verify_regions(
    ready: &Ready,
    run: &RegionsRun,
    designed: Designed,
    cut: Cut,
    o: &mut Out,
    outcome: &mut Outcome,
) -> Result<(), JobError> {
    let job = &ready.job;
    // the regions are judged on the declared machine's cut; their perfect-machine figures are not measured
    let Cut {
        program,
        sim,
        sim_ideal: _,
        dev,
        figures: sim_figures,
    } = cut;
    let Designed {
        scallop,
        tiles,
        figures: design_figures,
        composed,
    } = designed;
    let Some(composed) = composed else {
        return Err(stage_err("verify")(StageError::Input(
            "the regions' part was not composed".into(),
        )));
    };
    let (r, stepover) = (ready.toolpath.cutting_shape().radius_mm(), ready.toolpath.stepover_mm);
    // the moving light's lobe: the polish's roughness (a GGX or anisotropic polish by its mean α)
    let polish_alpha = match run.nds[0].polish.as_ref().map(|b| &b.model) {
        Some(crate::stages::brdf::Model::Microfacet(m)) => (m.alpha_x * m.alpha_y).sqrt(),
        _ => DEFAULT_POLISH_ALPHA,
    };
    let regions = run
        .targets
        .iter()
        .zip(run.nds)
        .zip(&tiles)
        .map(|((g, nd), tile)| RegionInput {
            name: &g.name,
            spec: &g.spec,
            target: &g.target,
            ndf: &nd.ndf,
            tile,
        })
        .collect();
    let (metrics, vfigs) = verify::regions::run(
        &job.verify,
        &RegionsInput {
            regions,
            labels: run.labels,
            base: run.nds[0].kernel.as_ref(),
            scallop: &scallop,
            polish_alpha,
            sim: &sim,
            deviation: &dev,
            part: &composed.heightfield,
            tool_radius_mm: r,
            stepover_mm: stepover,
            raster_angle_deg: job.toolpath.angle_deg,
            cone_deg: job.facets.max_slope_deg,
        },
    )
    .map_err(stage_err("verify"))?;
    if let Some(strip) = vfigs.iter().find(|f| f.title.contains("moving light")) {
        o.write("light.png", &strip.png())?;
    }
    let metrics_json = serde_json::to_string_pretty(&metrics).map_err(stage_err("verify"))?;
    o.write("metrics.json", metrics_json.as_bytes())?;
    let mut figures = vfigs;
    figures.extend(design_figures);
    figures.extend(sim_figures);
    let ndfs: Vec<&crate::stages::ndf::Ndf> = run.nds.iter().map(|n| &n.ndf).collect();
    outcome.setup = super::setup::sheet(ready, &program.summary, composed.relief_mm, &dev, &sim.stats);
    let html = report::Report {
        title: job.name.clone(),
        verdict: report::Verdict::Regions(&metrics),
        figures,
        parameters: super::summary::region_parameters(ready, &ndfs, &tiles, &composed, &sim),
        program: outcome.setup.clone(),
        artifacts: o.listed(),
    }
    .to_html();
    o.write("report.html", html.as_bytes())?;
    outcome.regions = Some(metrics);
    Ok(())
}
