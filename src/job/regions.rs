//! The runner of a job with `[svbrdf]`: each region's NDF and design loop, the composed part, one program
//! for the whole part, its simulation, and each region verified against its own target (DESIGN.md §3.3,
//! §6.2). Only sequencing lives here, as in [`super::run`].

use super::run::{
    design_stage, empty_outcome, facets_stage, ndf_stage, program_and_cut, scallop_lobe, stage_err, stepover_mm, Cut,
    Out, Outcome, Progress, Stage,
};
use super::{JobError, Ready};
use crate::stages::svbrdf;
use crate::stages::verify::regions::{RegionInput, RegionsInput};
use crate::stages::verify::report;
use std::path::Path;

/// The polish lobe's Beckmann α when the job names none (the moving-light pictures only).
const DEFAULT_POLISH_ALPHA: f64 = 0.06;

/// Run a job with `[svbrdf]` up to `until` (see [`super::run::run`]). Each region's NDF and tile are written
/// as `ndf-NAME.*` and `tile-NAME.*`; the composed part as `part.npy`/`part.png`, the label map as
/// `labels.png`, the moving-light strip as `light.png`.
pub(super) fn run(
    ready: &Ready,
    out: &Path,
    until: Stage,
    progress: &mut dyn FnMut(Progress),
) -> Result<Outcome, JobError> {
    let job = &ready.job;
    let Some(labels) = ready.labels.as_ref() else {
        return Err(stage_err("facets")("the job has no label image"));
    };
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
    let mut nds = vec![];
    for reg in &ready.regions {
        let nd = ndf_stage(ready, &reg.target, &format!("-{}", reg.name), r, stepover, &mut o)?;
        outcome
            .warnings
            .extend(crate::stages::ndf::grid_warning(&nd.ndf).map(|w| format!("region `{}`: {w}", reg.name)));
        nds.push(nd);
    }
    o.done(progress, Stage::Ndf)?;
    if until == Stage::Ndf {
        return o.finish(outcome);
    }

    o.start(progress, Stage::Facets);
    let scallop = scallop_lobe(ready, &nds[0], r, stepover)?;
    let mut tiles = vec![];
    let mut figures = vec![];
    for (reg, nd) in ready.regions.iter().zip(&nds) {
        progress(Progress::Region(&reg.name));
        let d = design_stage(ready, nd, &reg.target, &scallop, &tool, stepover, progress)?;
        let (tile, mut fig) = facets_stage(&nd.ndf, d.tile, &format!("-{}", reg.name), &mut o)?;
        fig.title = format!("Design tile of region `{}`", reg.name);
        figures.push(fig);
        tiles.push(tile);
    }
    let hfs: Vec<&crate::base::heightfield::Heightfield> = tiles.iter().map(|t| &t.heightfield).collect();
    let part = svbrdf::compose(&hfs, labels, job.facets.max_relief_mm).map_err(stage_err("facets"))?;
    o.npy("part.npy", &part.heightfield)?;
    let part_fig = report::Figure::new(
        "Composed part",
        format!(
            "The part's design: each region's tile where the label image says, laid from the work origin with one period, the tiles' {} heights aligned (offsets {}); relief {:.3} mm.",
            match part.alignment {
                svbrdf::Alignment::Mean => "mean",
                svbrdf::Alignment::Top => "top (mean alignment would exceed the relief budget)",
            },
            ready
                .regions
                .iter()
                .zip(&part.offsets_mm)
                .map(|(g, off)| format!("`{}` {:+.3} mm", g.name, off))
                .collect::<Vec<_>>()
                .join(", "),
            part.relief_mm
        ),
        &part.heightfield.relief_png("composed part", 1024),
    );
    o.write("part.png", &part_fig.png)?;
    o.write("labels.png", &labels.figure(1024).to_png())?;
    figures.push(part_fig);
    outcome.relief_mm = Some(part.relief_mm);
    o.done(progress, Stage::Facets)?;
    if until == Stage::Facets {
        return o.finish(outcome);
    }

    let Some(cut) = program_and_cut(
        ready,
        &part.heightfield,
        "part.npy",
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
    // the moving light's lobe: the polish's roughness (a GGX or anisotropic polish by its mean α)
    let polish_alpha = match nds[0].polish.as_ref().map(|b| &b.model) {
        Some(crate::stages::brdf::Model::Microfacet(m)) => (m.alpha_x * m.alpha_y).sqrt(),
        _ => DEFAULT_POLISH_ALPHA,
    };
    let (metrics, vfigs) = crate::stages::verify::regions::run(
        &job.verify,
        &RegionsInput {
            regions: ready
                .regions
                .iter()
                .zip(&nds)
                .zip(&tiles)
                .map(|((g, nd), tile)| RegionInput {
                    name: &g.name,
                    spec: &g.spec,
                    target: &g.target,
                    ndf: &nd.ndf,
                    tile,
                })
                .collect(),
            labels,
            base: nds[0].kernel.as_ref(),
            scallop: &scallop,
            polish_alpha,
            sim: &sim,
            deviation: &dev,
            part: &part.heightfield,
            tool_radius_mm: r,
            stepover_mm: stepover,
            raster_angle_deg: job.toolpath.angle_deg,
            cone_deg: job.facets.max_slope_deg,
        },
    )
    .map_err(stage_err("verify"))?;
    if let Some(strip) = vfigs.iter().find(|f| f.title.contains("moving light")) {
        o.write("light.png", &strip.png)?;
    }
    let metrics_json = serde_json::to_string_pretty(&metrics).map_err(stage_err("verify"))?;
    o.write("metrics.json", metrics_json.as_bytes())?;
    let mut all = vfigs;
    all.extend(figures);
    all.extend(sim_figures);
    let html = report::Report {
        title: job.name.clone(),
        verdict: report::Verdict::Regions(&metrics),
        figures: all,
        parameters: super::summary::region_parameters(
            ready,
            &nds.iter().map(|n| &n.ndf).collect::<Vec<_>>(),
            &tiles,
            &part,
            &sim,
        ),
        program: super::summary::program(ready, &program.summary, part.relief_mm, &dev),
        artifacts: o.listed(),
    }
    .to_html();
    o.write("report.html", html.as_bytes())?;
    o.done(progress, Stage::Verify)?;
    outcome.regions = Some(metrics);
    outcome.report = Some(out.join("report.html"));
    o.finish(outcome)
}
