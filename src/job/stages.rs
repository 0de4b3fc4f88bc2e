//! The job's steps around each stage: what a stage needs from the job's plan and the earlier stages, and the
//! artifacts it writes. Only sequencing and writing live here; what each stage computes is the stage's own.

use super::artifacts::Out;
use super::outcome::{Outcome, Progress, Stage};
use super::{resolve_spec, JobError, Ready, StageError};
use crate::base::heightfield::Heightfield;
use crate::cut::tool::Shape;
use crate::stages::brdf::Brdf;
use crate::stages::design::{self, DesignInput};
use crate::stages::facets::{self, Tile, TileFile};
use crate::stages::ndf::{self, Kernel, Ndf, NdfFile};
use crate::stages::simulate::{self, Deviation, SimFile, Simulation};
use crate::stages::toolpath;
use crate::stages::verify::report;

/// A stage's error as the job's, keeping it as the source.
pub(super) fn stage_err<E: Into<StageError>>(stage: &'static str) -> impl Fn(E) -> JobError {
    move |e| JobError::Stage { stage, error: e.into() }
}

/// The NDF stage's products.
pub(super) struct NdfStage {
    pub(super) ndf: Ndf,
    pub(super) kernel: Option<Kernel>,
    pub(super) polish: Option<Brdf>,
}

/// The design loop around the facets for `target`'s NDF stage `nd`.
pub(super) fn design_stage(
    ready: &Ready,
    nd: &NdfStage,
    target: &Brdf,
    scallop: &Kernel,
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
            tool: ready.toolpath.cutting_shape(),
            stepover_mm: stepover,
            raster_angle_deg: job.toolpath.angle_deg,
            cov_band: tol.cov_ratio,
            corr_min: tol.ndf_corr_min,
            l1_max: tol.ndf_l1_max,
            highlight: target.highlight(),
            highlight_corr_min: tol.highlight_corr_min,
            chords: design_chords(ready),
        },
        &mut |p| match p {
            crate::stages::design::Progress::Arrangement(r) => progress(Progress::Arrangement(r)),
            crate::stages::design::Progress::Round(r) => progress(Progress::Round(r)),
        },
    )
    .map_err(stage_err("facets"))
}

/// The chords along the finishing passes the design loop's model cuts: the program's lines, which the
/// one-sided simplification keeps within `toolpath.tolerance_um` of the CL surface (as the plan raised it
/// to the machine's grid), and the chords the verdict's simulation cuts arcs as (GRBL's `$12`; none where it
/// follows arcs), their sagittas added. `None` when the passes lie at an angle to the grid.
fn design_chords(ready: &Ready) -> Option<crate::cut::chords::PassChords> {
    let arc_um = ready.job.simulate.config(&ready.toolpath).arc_tolerance_um;
    // a program written without arcs (`toolpath.arcs = false`) gives the controller none to chord
    let chords_um = if ready.toolpath.cfg.arcs && arc_um > super::EXACT_ARC_TOLERANCE_UM {
        arc_um
    } else {
        0.0
    };
    let sag_um = chords_um + ready.toolpath.cfg.tolerance_um;
    if sag_um <= 0.0 {
        return None;
    }
    Some(crate::cut::chords::PassChords {
        sag_mm: sag_um * 1e-3,
        along: crate::cut::chords::PassAxis::of_angle(ready.job.toolpath.angle_deg)?,
    })
}

/// The program and its simulated cut.
pub(super) struct Cut {
    pub(super) program: toolpath::Toolpath,
    /// The cut on the declared machine (its backlash, runout and step grid).
    pub(super) sim: Simulation,
    /// The same program on a perfect machine; `None` when the profile declares no error.
    pub(super) sim_ideal: Option<Simulation>,
    pub(super) dev: Deviation,
    pub(super) figures: [report::Figure; 3],
}

/// The toolpath and simulate stages for `design` (written as `design_file`): `None` when `until` stops
/// before the cut is simulated (the outcome has the program's numbers once it is made).
pub(super) fn program_and_cut(
    ready: &Ready,
    design: &Heightfield,
    design_file: &str,
    until: Stage,
    o: &mut Out,
    outcome: &mut Outcome,
    progress: &mut dyn FnMut(Progress),
) -> Result<Option<Cut>, JobError> {
    o.start(progress, Stage::Toolpath);
    let mut program = toolpath_stage(ready, design, o)?;
    o.done(progress, Stage::Toolpath)?;
    outcome.program = Some(program.summary.clone());
    if until == Stage::Toolpath {
        return Ok(None);
    }
    o.start(progress, Stage::Simulate);
    let shape = ready.toolpath.cutting_shape();
    let declared = ready.job.simulate.config(&ready.toolpath);
    // the cut on a perfect machine as well when the machine declares errors (`milled_ideal`), measured by
    // its surface only, so swept deepest first; independent of the declared cut, so both at once
    let ideal_cfg = (!declared.accuracy().is_perfect()).then_some(crate::stages::simulate::SimulateConfig {
        ideal: true,
        surface_only: true,
        ..declared
    });
    let texts = program.texts();
    let (declared_cut, sim_ideal) = rayon::join(
        || simulate_stage(ready, shape, &program, design, design_file, o),
        || {
            ideal_cfg
                .as_ref()
                .map(|cfg| simulate::run_files(&texts, cfg).map_err(stage_err("simulate")))
                .transpose()
        },
    );
    let (sim, dev, figures) = declared_cut?;
    let sim_ideal = sim_ideal?;
    // the air the simulation found, beside the program's numbers
    program.summary.air_feed_mm = Some(sim.stats.air_feed_mm);
    program.summary.air_feed_s = Some(sim.stats.air_feed_s);
    outcome.program = Some(program.summary.clone());
    write_summary(&program.summary, o)?;
    o.done(progress, Stage::Simulate)?;
    if until == Stage::Simulate {
        return Ok(None);
    }
    Ok(Some(Cut {
        program,
        sim,
        sim_ideal,
        dev,
        figures,
    }))
}

/// The design heightfield → `program.nc` (GRBL with several tools: `program-1.nc`, `program-2.nc`, … one per
/// tool), `tool.tbl` for LinuxCNC, `program.json`.
fn toolpath_stage(ready: &Ready, design: &Heightfield, o: &mut Out) -> Result<toolpath::Toolpath, JobError> {
    let program = ready.toolpath.run(design).map_err(stage_err("toolpath"))?;
    for f in &program.files {
        o.write(&f.summary.file, f.gcode.as_bytes())?;
    }
    if ready.machine.dialect == crate::gcode::Dialect::Linuxcnc {
        o.write(
            crate::gcode::TOOL_TABLE_FILE,
            crate::gcode::tool_table(&ready.machine).as_bytes(),
        )?;
    }
    write_summary(&program.summary, o)?;
    Ok(program)
}

/// `program.json`.
fn write_summary(s: &toolpath::Summary, o: &mut Out) -> Result<(), JobError> {
    let summary = serde_json::to_string_pretty(s).map_err(stage_err("toolpath"))?;
    o.write("program.json", summary.as_bytes())
}

/// `target` → NDF: the base lobe (the finishing raster's scallop lobe by default), Lucy–Richardson,
/// `ndf{suffix}.json`, `ndf{suffix}.png`.
pub(super) fn ndf_stage(
    ready: &Ready,
    target: &Brdf,
    suffix: &str,
    tool: &Shape,
    stepover: f64,
    o: &mut Out,
) -> Result<NdfStage, JobError> {
    let nd = ndf_of(ready, target, tool, stepover)?;
    o.write(
        &format!("ndf{suffix}.json"),
        NdfFile::from(&nd.ndf).to_json().as_bytes(),
    )?;
    o.write(&format!("ndf{suffix}.png"), &ndf::render_pair_png(&nd.ndf).to_png())?;
    Ok(nd)
}

/// The NDF stage's products for `target`, written nowhere (`brdfmill compare` remakes them from `job.toml`).
pub(super) fn ndf_of(ready: &Ready, target: &Brdf, tool: &Shape, stepover: f64) -> Result<NdfStage, JobError> {
    let job = &ready.job;
    let domain = job.ndf.domain();
    let polish = match &job.target.polish {
        Some(p) => Some(Brdf::parse(&resolve_spec(p, &ready.dir)).map_err(stage_err("ndf"))?),
        None => None,
    };
    let kernel = match job.target.base.as_str() {
        "none" => None,
        "scallop" => Some(
            Kernel::scallop(
                &domain,
                tool,
                stepover,
                job.toolpath.angle_deg,
                polish.as_ref(),
                &job.ndf,
            )
            .map_err(stage_err("ndf"))?,
        ),
        spec => {
            let b = Brdf::parse(&resolve_spec(spec, &ready.dir)).map_err(stage_err("ndf"))?;
            Some(Kernel::from_brdf(&b, &domain, &job.ndf).map_err(stage_err("ndf"))?)
        }
    };
    let n = ndf::run_with_kernel(&job.ndf, target, kernel.as_ref()).map_err(stage_err("ndf"))?;
    Ok(NdfStage { ndf: n, kernel, polish })
}

/// The finishing raster's scallop lobe with the material's polish: the base lobe when that is the scallop
/// lobe, otherwise made here (the as-milled model and the milled measurement use it either way).
pub(super) fn scallop_lobe(ready: &Ready, nd: &NdfStage, tool: &Shape, stepover: f64) -> Result<Kernel, JobError> {
    let job = &ready.job;
    match &nd.kernel {
        Some(k) if job.target.base == "scallop" => Ok(k.clone()),
        _ => Kernel::scallop(
            &job.ndf.domain(),
            tool,
            stepover,
            job.toolpath.angle_deg,
            nd.polish.as_ref(),
            &job.ndf,
        )
        .map_err(stage_err("facets")),
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
    o.write(&format!("tile{suffix}.png"), &tile_figure.png())?;
    o.write(&format!("tile{suffix}.stl"), &tile.stl())?;
    Ok((tile, tile_figure))
}

/// G-code → milled surface and its deviation from the design: `sim.npy`, `sim.x3p`, `sim.png`, `deviation.png`,
/// `sim.json`.
fn simulate_stage(
    ready: &Ready,
    shape: Shape,
    program: &toolpath::Toolpath,
    design: &Heightfield,
    design_file: &str,
    o: &mut Out,
) -> Result<(Simulation, Deviation, [report::Figure; 3]), JobError> {
    let job = &ready.job;
    let scfg = job.simulate.config(&ready.toolpath);
    let sim = simulate::run_files(&program.texts(), &scfg).map_err(stage_err("simulate"))?;
    let dev = simulate::deviation(&sim, design, &shape);
    o.npy("sim.npy", &sim.heightfield)?;
    o.x3p("sim.x3p", &sim.heightfield)?;
    let sim_canvas = sim.heightfield.relief_png("simulated milled surface", 1024);
    let sim_figure = report::Figure::new(
        "Simulated milled surface",
        format!(
            "The stock after the program, simulated at {} µm.",
            job.simulate.pitch_um
        ),
        &sim_canvas,
    );
    o.write("sim.png", &sim_figure.png())?;
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
    o.write("deviation.png", &dev_figure.png())?;
    let pair_figure = side_by_side_figure(&sim, &dev, &shape);
    o.write("design-vs-cut.png", &pair_figure.png())?;
    o.write(
        "sim.json",
        SimFile::new(
            &sim,
            &scfg,
            &program.summary.file_names().join(" + "),
            Some(&dev),
            Some(design_file.into()),
        )
        .to_json()
        .as_bytes(),
    )?;
    Ok((sim, dev, [pair_figure, sim_figure, dev_figure]))
}

/// The design and the cut side by side over a window at the centre of the area
/// ([`simulate::side_by_side`]); when there is no such window (nothing assessed), a figure that says so.
fn side_by_side_figure(sim: &Simulation, dev: &Deviation, shape: &Shape) -> report::Figure {
    let title = "Design and cut, side by side";
    match simulate::side_by_side(sim, dev, simulate::side_by_side::WINDOW_MM) {
        Some(s) => {
            let [x0, y0, x1, y1] = s.window_mm;
            report::Figure::new(
                title,
                format!(
                    "The design (left) and the simulated cut (right) over the same {:.2} × {:.2} mm at the centre of the \
                     area (X {x0:.2} to {x1:.2}, Y {y0:.2} to {y1:.2} mm), on one height scale; below, both along the \
                     dashed line, and their difference. Over this window the cut stands {:.2} µm rms from the design \
                     where the {} mm ball can reach it; {:.1}% of it is out of its reach (concave corners narrower than \
                     the bit, where the cut stands above the design).",
                    x1 - x0,
                    y1 - y0,
                    s.rms_reachable_um,
                    shape.diameter_mm(),
                    s.unreachable_fraction * 100.0,
                ),
                &s.canvas,
            )
        }
        None => report::Figure::new(
            title,
            "No window of the area was assessed against the design (the stock is narrower than two tool diameters), so there is nothing to set side by side.",
            &crate::base::plot::Canvas::new(8, 8),
        ),
    }
}
