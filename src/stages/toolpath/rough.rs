//! Roughing: layers at the roughing tool's depth of cut that cut only where material remains.
//!
//! The roughing tool's CL surface raised by the allowance, `c(x) = CL_rough(x) + leave`, is the lowest the
//! roughing may go. Layer `k` sits at `L_k = −k·doc`; the tip follows `z_k(x) = max(L_k, c(x))`. After layer
//! `k − 1` the stock under the tip's path stands at `z_{k−1}(x)`, so layer `k` removes material at `x` only
//! if `z_k(x) < z_{k−1}(x)`, i.e. `c(x) < L_{k−1}`: elsewhere the tip would retrace the surface it already
//! left (air). Each pass is split into the runs where it cuts; gaps shorter than [`GAP_DIAMETERS`] tool
//! diameters are ridden through (a hop costs a retract and a plunge), longer ones are hopped over at safe
//! z. The allowance is half the *finishing* tool's depth of cut (at most a third of the roughing tool's),
//! so the finishing passes start within their own depth of cut wherever the roughing tool reaches.

use super::build::Builder;
use super::raster::{self, RotatedDesign};
use super::simplify;
use crate::cut::dropcutter::DropCutter;
use crate::cut::machine::CuttingData;
use crate::cut::tool::Shape;
use crate::gcode::moves::P3;
use rayon::prelude::*;

/// Air gaps up to this many roughing-tool diameters are ridden through instead of hopped over. Half a
/// diameter: at two, a relief reaching the area's edges rode most of each pass in air (roughing air 14–21%
/// of its length on the acceptance tests' edge tile, 0–4% at half a diameter), at 1% more time on the
/// default job (the hops cost a retract and a ramped entry each).
pub const GAP_DIAMETERS: f64 = 0.5;

/// The most roughing layers a program may have (a depth of cut of 1e-9 mm would ask for 10⁹).
pub const MAX_LAYERS: usize = 10_000;

/// Roughing stepover for an allowance `leave`: a ball's scallop equal to the allowance, half a flat's
/// diameter, a bull's flat part plus its corners' scallop; at most 0.8 D.
pub fn stepover_mm(shape: Shape, leave: f64) -> f64 {
    match shape.normalized() {
        Shape::Ball { diameter_mm } => raster::stepover_for_scallop(diameter_mm / 2.0, leave).min(0.8 * diameter_mm),
        Shape::Flat { diameter_mm } => diameter_mm / 2.0,
        Shape::Bull {
            diameter_mm,
            corner_radius_mm: rc,
        } => (diameter_mm - 2.0 * rc + raster::stepover_for_scallop(rc, leave)).min(0.8 * diameter_mm),
    }
}

/// Height of the ridges between paths `stepover` apart: a ball's scallop, none for a flat, a bull's corner
/// scallop over what its flat part does not cover, mm.
pub fn scallop_mm(shape: Shape, stepover: f64) -> f64 {
    match shape.normalized() {
        Shape::Ball { diameter_mm } => raster::scallop_for_stepover(diameter_mm / 2.0, stepover),
        Shape::Flat { .. } => 0.0,
        Shape::Bull {
            diameter_mm,
            corner_radius_mm: rc,
        } => raster::scallop_for_stepover(rc, (stepover - (diameter_mm - 2.0 * rc)).max(0.0)),
    }
}

/// The roughing passes at `c(x) = CL_rough + leave` and the number of layers they need.
pub struct RoughPlan {
    /// Rows at the allowance surface, in increasing u.
    pub rows: Vec<Vec<P3>>,
    /// Layers of `doc` down to the lowest allowance point.
    pub layers: usize,
    /// Roughing stepover, mm.
    pub stepover_mm: f64,
    /// Height of the ridges the roughing tool leaves between its paths, mm (0 for a flat end mill).
    pub scallop_mm: f64,
}

/// The rows of the roughing tool and the layer count (unbounded counts are the caller's to refuse).
pub fn plan(design: &RotatedDesign, rdc: &DropCutter, shape: Shape, doc: f64, leave: f64) -> RoughPlan {
    let (vmin, vmax) = design.v_range();
    let rs = stepover_mm(shape, leave);
    let vs = raster::pass_positions(vmin, vmax, rs);
    let rows: Vec<Vec<P3>> = vs.par_iter().map(|v| design.pass(rdc, *v, |z| z + leave)).collect();
    let floor = rows.iter().flatten().map(|p| p[2]).fold(0.0, f64::min);
    let layers = (-floor / doc - 1e-9).ceil().max(0.0) as usize;
    RoughPlan {
        rows,
        layers,
        stepover_mm: rs,
        scallop_mm: scallop_mm(shape, rs),
    }
}

/// The runs of a pass where `cut` holds: index ranges with one point kept at each end (so the tool enters
/// and leaves along the surface), gaps up to `gap` points merged.
pub fn cutting_runs(cut: &[bool], gap: usize) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = vec![];
    let last = cut.len().saturating_sub(1);
    for (i, c) in cut.iter().enumerate() {
        if *c {
            let lo = i.saturating_sub(1);
            match runs.last_mut() {
                Some(r) if lo <= r.1 + gap => r.1 = (i + 1).min(last),
                _ => runs.push((lo, (i + 1).min(last))),
            }
        }
    }
    runs
}

/// One level of passes that cut only where material remains.
pub struct Level<'a> {
    /// The tip's path of every pass, already in cutting order and direction.
    pub rows: &'a [Vec<P3>],
    /// Per point: whether it removes material.
    pub cut: &'a [Vec<bool>],
    /// Cutting feed, mm/min.
    pub feed_mm_min: f64,
    /// Distance between passes, mm (a pass's start this close to the last one's end is linked to it).
    pub stepover_mm: f64,
    /// Air gaps up to this many points are ridden through.
    pub gap_points: usize,
    /// Grid pitch, mm.
    pub pitch_mm: f64,
    /// Simplification tolerance, mm.
    pub tol_mm: f64,
    /// Per point, when known: the tool's cutter location over the stock as the level meets it (the lowest
    /// its tip can sit there without touching it), mm. A run's entry then descends straight to just above
    /// it instead of ramping from a depth of cut above the run (the finishing levels know their stock).
    pub stock_cl: Option<&'a [Vec<f64>]>,
    /// Fit arcs in the pass plane to each run on this write resolution, mm ([`super::arcs::fit`]): the
    /// finishing levels follow the curved CL surface wherever it is above the level, which as lines alone
    /// is one block per CL point on a convex stretch, and so do the roughing layers over the allowance
    /// surface. `None`: straight blocks.
    pub arc_resolution_mm: Option<f64>,
}

/// Emit one level: each pass's cutting runs; the next pass's first run is linked along the surface
/// (`link` gives its points) when it starts beside the last run's end, every other run is approached from
/// safe z.
pub fn emit_level(b: &mut Builder, lv: &Level, link: &dyn Fn(P3, P3) -> Vec<P3>) {
    let mut first = true;
    let mut row_end: Option<P3> = None;
    for (r, (row, cut)) in lv.rows.iter().zip(lv.cut).enumerate() {
        for (n, (i0, i1)) in cutting_runs(cut, lv.gap_points).into_iter().enumerate() {
            let stock_cl = lv.stock_cl.map(|s| s[r][i0]);
            let run = simplify::simplify(&row[i0..=i1], lv.tol_mm);
            if run.is_empty() {
                continue;
            }
            let near = row_end.is_some_and(|e| {
                let d = ((e[0] - run[0][0]).powi(2) + (e[1] - run[0][1]).powi(2)).sqrt();
                n == 0 && d <= 1.5 * lv.stepover_mm + 2.0 * lv.pitch_mm
            });
            if first || !near {
                b.approach(&run, stock_cl);
                first = false;
            } else {
                let l = link(b.at, run[0]);
                b.path(&simplify::simplify(&l, lv.tol_mm), lv.feed_mm_min);
            }
            match lv.arc_resolution_mm {
                Some(q) => {
                    let raw = &row[i0..=i1];
                    let pieces = super::arcs::fit(raw, lv.tol_mm, q, super::arcs::pass_plane(raw));
                    b.pieces(&pieces, lv.feed_mm_min);
                }
                None => b.path(&run[1..], lv.feed_mm_min),
            }
            row_end = Some(b.at);
        }
    }
}

/// Emit the roughing layers of `rp` with the roughing tool's data (see the module documentation), its
/// blocks simplified within `tol` and fitted with arcs on `arc_resolution_mm` when given;
/// `link(a, b, z_layer)` gives the points of a link along the allowance surface.
pub fn emit(
    b: &mut Builder,
    rp: &RoughPlan,
    cut: &CuttingData,
    diameter_mm: f64,
    pitch_mm: f64,
    (tol, arc_resolution_mm): (f64, Option<f64>),
    link: &dyn Fn(P3, P3, f64) -> Vec<P3>,
) {
    let doc = cut.max_depth_of_cut_mm;
    let gap_points = (GAP_DIAMETERS * diameter_mm / pitch_mm).ceil() as usize;
    for k in 1..=rp.layers {
        let (zl, zp) = (-(k as f64) * doc, -((k - 1) as f64) * doc);
        b.moves.push(crate::gcode::moves::Move::Comment("roughing layer"));
        let mut rows = Vec::with_capacity(rp.rows.len());
        let mut cuts = Vec::with_capacity(rp.rows.len());
        for (r, row) in rp.rows.iter().enumerate() {
            let mut raw = row.clone();
            if r % 2 == 1 {
                raw.reverse();
            }
            // material remains above this layer only where the allowance surface is below the last one
            cuts.push(raw.iter().map(|p| p[2] < zp - 1e-9).collect::<Vec<bool>>());
            rows.push(raw.iter().map(|p| [p[0], p[1], p[2].max(zl)]).collect::<Vec<P3>>());
        }
        let lv = Level {
            rows: &rows,
            cut: &cuts,
            feed_mm_min: cut.feed_mm_min,
            stepover_mm: rp.stepover_mm,
            gap_points,
            pitch_mm,
            tol_mm: tol,
            stock_cl: None,
            arc_resolution_mm,
        };
        // no stock above the layer before but the ridges between its paths
        b.entry_ceiling_z = zp + rp.scallop_mm + super::build::ENTRY_MARGIN_MM;
        emit_level(b, &lv, &|a, e| link(a, e, zl));
    }
    b.entry_ceiling_z = f64::INFINITY;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_cover_cutting_points_and_merge_short_gaps() {
        let z = [0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0];
        let cut = |zp: f64| -> Vec<bool> { z.iter().map(|z| *z < zp).collect() };
        assert_eq!(cutting_runs(&cut(-0.5), 0), vec![(1, 4), (7, 9)]);
        assert_eq!(cutting_runs(&cut(-0.5), 3), vec![(1, 9)]);
        assert!(cutting_runs(&cut(-2.0), 3).is_empty(), "all air below the last level");
    }
}
