//! The report's table of what was run: the job's parameters (the setup sheet is `setup`).

use super::Ready;
use crate::stages::facets::Tile;
use crate::stages::ndf::Ndf;
use crate::stages::simulate::Simulation;

/// The parameters table. `beyond_cone`: the target's mass beyond the machinable cone as the verdict measured
/// it (`metrics.json` `measurement.target_mass_beyond_cone`), so that the report and the file give one
/// figure; None (several targets): the steepest-facet row gives the limit alone.
pub(super) fn parameters(
    ready: &Ready,
    n: &Ndf,
    tile: &Tile,
    sim: &Simulation,
    beyond_cone: Option<f64>,
) -> Vec<(String, String)> {
    let job = &ready.job;
    let tool = ready
        .machine
        .tool(&job.toolpath.tool)
        .map(|t| {
            format!(
                "{} ({} mm ball), stock {}",
                t.id,
                t.diameter_mm(),
                job.toolpath.stock.name()
            )
        })
        .unwrap_or_else(|e| e.to_string());
    vec![
        ("target BRDF".into(), n.brdf_spec.clone()),
        ("base lobe".into(), n.base_spec.clone().unwrap_or_else(|| "none".into())),
        (
            "NDF grid".into(),
            format!("{}² over |p|,|q| ≤ tan {}°", job.ndf.res, job.ndf.max_angle_deg),
        ),
        (
            "deconvolution".into(),
            format!(
                "{} iterations, {}",
                n.deconvolution.iterations,
                n.deconvolution.stopped_by.describe()
            ),
        ),
        (
            "facets".into(),
            format!(
                "{}×{} of {} mm at {} µm, seed {}; {}",
                job.facets.facets_x,
                job.facets.facets_y,
                job.facets.facet_mm,
                job.facets.pitch_um,
                job.facets.seed,
                design_method(&job.design)
            ),
        ),
        (
            "steepest facet".into(),
            match beyond_cone {
                Some(beyond) => format!(
                    "{:.1}°, from {}; {:.2}% of the target's distribution lies beyond it, where no facet can draw it",
                    job.facets.max_slope_deg,
                    ready.slope_cap_from,
                    beyond * 100.0
                ),
                None => format!("{:.1}°, from {}", job.facets.max_slope_deg, ready.slope_cap_from),
            },
        ),
        ("relief".into(), relief_line(job, tile)),
        (
            "steps between facets".into(),
            match tile.refined {
                Some(r) => format!(
                    "none: the tile was refined into a continuous surface (iteration {} of {}, on a {:.1} µm grid); the facets it started from stepped by {:.1} µm rms",
                    r.chosen,
                    r.iterations,
                    r.model_pitch_mm * 1e3,
                    tile.seams.rms_um
                ),
                None => format!(
                    "{:.1} µm rms, {:.1} µm at most (annealed with the exact step term, weight {})",
                    tile.seams.rms_um,
                    tile.seams.max_interior_um.max(tile.seams.max_seam_um),
                    job.facets.anneal.step_weight
                ),
            },
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
            format!(
                "{} ({})",
                ready.machine.name,
                crate::base::io::tidy(&ready.machine_path).display()
            ),
        ),
        ("tool".into(), tool),
        (
            "area".into(),
            format!("{} × {} mm", job.toolpath.area_mm[0], job.toolpath.area_mm[1]),
        ),
        (
            "simulation".into(),
            format!(
                "{} µm pitch, {} cells; arcs cut as chords of at most {} µm sagitta ({})",
                job.simulate.pitch_um,
                sim.stats.cells[0] * sim.stats.cells[1],
                sim.stats.arc_tolerance_um,
                match job.simulate.arc_tolerance_um {
                    Some(_) => "the job's `simulate.arc_tolerance_um`",
                    None if sim.stats.arc_tolerance_um > crate::job::EXACT_ARC_TOLERANCE_UM => {
                        "as the controller draws them: its arc tolerance, GRBL's `$12`"
                    }
                    None => "the arcs as written: the controller follows them",
                }
            ),
        ),
    ]
}

/// The parameters table of a job with `[svbrdf]`: the shared settings, then each region's target and tile.
pub(super) fn region_parameters(
    ready: &Ready,
    ndfs: &[&Ndf],
    tiles: &[Tile],
    part: &crate::stages::svbrdf::Part,
    sim: &Simulation,
) -> Vec<(String, String)> {
    const PER_TARGET: [&str; 5] = [
        "target BRDF",
        "deconvolution",
        "relief",
        "steps between facets",
        "arrangement energy",
    ];
    let mut rows: Vec<(String, String)> = parameters(ready, ndfs[0], &tiles[0], sim, None)
        .into_iter()
        .filter(|(k, _)| !PER_TARGET.contains(&k.as_str()))
        .collect();
    if let Some(l) = &ready.labels {
        rows.insert(
            0,
            (
                "label image".into(),
                format!("{} ({} × {} px over the area)", l.path.display(), l.width, l.height),
            ),
        );
    }
    for ((reg, n), (t, off)) in ready.targets.iter().zip(ndfs).zip(tiles.iter().zip(&part.offsets_mm)) {
        rows.push((
            format!("region `{}` ({})", reg.name, crate::stages::svbrdf::hex(reg.color)),
            format!(
                "{}; {} deconvolution iterations; tile {}; offset {off:+.3} mm in the part; {}",
                n.brdf_spec,
                n.deconvolution.iterations,
                relief_line(&ready.job, t),
                match t.refined {
                    Some(_) => "refined into a continuous surface".to_string(),
                    None => format!("steps {:.1} µm rms", t.seams.rms_um),
                }
            ),
        ));
    }
    rows.push((
        "composed part".into(),
        format!(
            "{:.3} mm relief, tiles aligned by their {}",
            part.relief_mm,
            match part.alignment {
                crate::stages::svbrdf::Alignment::Mean => "mean heights",
                crate::stages::svbrdf::Alignment::Top => "tops (mean alignment would exceed the relief budget)",
            }
        ),
    ));
    rows
}

/// The tile's relief against its budget, and what kept it there.
fn relief_line(job: &super::Job, tile: &Tile) -> String {
    let (lo, hi) = tile.heightfield.range();
    let relief = hi - lo;
    let budget = job.facets.max_relief_mm;
    if budget <= 0.0 {
        return format!("{relief:.3} mm (no budget)");
    }
    if tile.refined.is_some() {
        return format!(
            "{relief:.3} mm of a {budget:.3} mm budget (`facets.max_relief_mm`): the refinement holds its surface above the budget's floor"
        );
    }
    let a = &tile.arrangement;
    let corners = crate::stages::facets::relief::relief_mm(&a.p, &a.q, &tile.z_mm, tile.config.facet_mm);
    let held = corners >= budget - 1e-6;
    format!(
        "{relief:.3} mm of a {budget:.3} mm budget (`facets.max_relief_mm`: the finishing tool's flutes less 10% unless the job sets it); {}",
        if held {
            "the budget held it: the heights are the least-squares ones within it, with deliberate steps where facets were held"
        } else {
            "the annealed arrangement (step term) and the Poisson heights stayed within it unaided"
        }
    )
}

/// The design method and correction in words (`design.method`, `design.correction`).
fn design_method(d: &crate::stages::design::DesignConfig) -> String {
    use crate::stages::design::{Correction, DesignMethod};
    let shape = match d.method {
        DesignMethod::FlatFacets => "flat facets",
        DesignMethod::CurvedFacets => "curved facets (each a dome over its cell of the target)",
        DesignMethod::Refined => {
            "curved facets, then refined as a continuous surface (its slopes transported onto the target, kept integrable and within the ball's reach)"
        }
    };
    let loop_ = match d.correction {
        Correction::Scale => "slopes scaled per axis by the design rounds",
        Correction::Shape => "the aim reweighted cell by cell by the design rounds",
    };
    format!("{shape}, {loop_}")
}
