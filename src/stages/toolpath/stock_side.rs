//! The stock side of the toolpath: roughing, the stock it leaves (swept with the simulator's closed form)
//! and the finishing tool's intermediate levels wherever that stock would have it cut deeper than its depth
//! of cut. [`super::run`] builds it beside the finishing raster, which needs only the CL rows.

use super::build::Builder;
use super::plan::limit;
use super::{link_points, raster, rough, LinkMemo, ToolpathError};
use crate::base::heightfield::Heightfield;
use crate::cut::dropcutter;
use crate::cut::machine::{self, Machine, Tool};
use crate::cut::tool::Shape;
use crate::gcode::moves::{self, Move, P3};
use rayon::prelude::*;

/// What the stock side of [`super::run`] works from.
pub(super) struct StockSide<'a> {
    pub(super) machine: &'a Machine,
    pub(super) design: &'a raster::RotatedDesign,
    /// The finishing tool's cutter over the design.
    pub(super) dc: &'a dropcutter::DropCutter<'a>,
    pub(super) tool: &'a Tool,
    pub(super) rough: &'a Tool,
    pub(super) cut: &'a machine::CuttingData,
    pub(super) rough_cut: &'a machine::CuttingData,
    pub(super) start: P3,
    /// The finishing CL's depth, mm (positive).
    pub(super) depth: f64,
    pub(super) vs: &'a [f64],
    pub(super) raw: &'a [Vec<P3>],
    pub(super) stepover: f64,
    pub(super) feed: f64,
    pub(super) tol: f64,
    /// Fit `G2`/`G3` arcs to the finishing levels' runs too (`toolpath.arcs`).
    pub(super) arcs: bool,
    /// The final raster's strategy: one-way final passes make one-way levels too, in the same direction, so
    /// that a machine's backlash shifts both alike (levels run both ways ride at the final cutter location
    /// where the stock allows, and there a shift against the final raster's gouges by backlash × slope).
    pub(super) strategy: super::Strategy,
}

/// The program up to the final finishing raster.
pub(super) struct StockBuilt<'a> {
    pub(super) builder: Builder<'a>,
    pub(super) layers: usize,
    pub(super) levels: usize,
    pub(super) tool_changes: usize,
    /// The finishing tool's cutter location over the stock as the final raster finds it, per raw pass row
    /// (the lowest its tip can sit there without touching the stock), mm.
    pub(super) stock_cl: Vec<Vec<f64>>,
}

/// Roughing whenever the finishing tool could not take the depth in one cut (the allowance is half the
/// finishing tool's depth of cut, at most a third of the roughing tool's), then the finishing tool's
/// intermediate levels over the stock the roughing left; the finishing tool is in the spindle at the end.
pub(super) fn stock_side<'a>(s: &StockSide<'a>) -> Result<StockBuilt<'a>, ToolpathError> {
    let (design, tool, rough, cut, rough_cut) = (s.design, s.tool, s.rough, s.cut, s.rough_cut);
    let rough_needed = s.depth > cut.max_depth_of_cut_mm + 1e-9;
    let leave = (0.5 * cut.max_depth_of_cut_mm).min(rough_cut.max_depth_of_cut_mm / 3.0);
    let rshape = rough.shape.normalized();
    let rdc = design.cutter(rshape);
    let rp = rough_needed.then(|| rough::plan(design, &rdc, rshape, rough_cut.max_depth_of_cut_mm, leave));
    let layers = rp.as_ref().map_or(0, |p| p.layers);
    let mut b = Builder::new(s.machine, s.start);
    let mut tool_changes = 0usize;
    if let Some(rp) = rp.as_ref().filter(|p| p.layers > 0) {
        b.start_tool(rough, rough_cut);
        tool_changes += 1;
        let memo = LinkMemo {
            design,
            dc: &rdc,
            seen: Default::default(),
        };
        let link = |a: P3, e: P3, zl: f64| memo.points(a, e, |z| (z + leave).max(zl));
        rough::emit(
            &mut b,
            rp,
            rough_cut,
            rough.diameter_mm(),
            design.hf.pitch_mm,
            (s.tol, s.arcs.then(|| s.machine.write_resolution_mm())),
            &link,
        );
        if rough.id != tool.id {
            b.stop_tool();
        }
    }
    if tool_changes == 0 || rough.id != tool.id {
        b.start_tool(tool, cut);
        tool_changes += 1;
    }
    // the stock the roughing left, on the design's `(u, v)` grid, so the finishing knows what remains
    let mut stock = Heightfield::flat(design.hf.nx, design.hf.ny, design.hf.pitch_mm, false, 0.0);
    if layers > 0 {
        lower_stock(design, &mut stock, &b.moves, s.start, rshape, |_, _| {});
    }
    let (levels, stock_cl) = intermediate_levels(&mut b, s, &mut stock)?;
    Ok(StockBuilt {
        builder: b,
        layers,
        levels,
        tool_changes,
        stock_cl,
    })
}

/// Lower `stock` (on the design's `(u, v)` grid, nowhere above 0) by what `moves` from `start` cut, with the
/// simulator's closed-form sweep ([`crate::cut::stock::sweep_into`]), calling `lowered(i, j)` for each
/// cell they lowered.
fn lower_stock(
    design: &raster::RotatedDesign,
    stock: &mut Heightfield,
    moves: &[Move],
    start: P3,
    bit: Shape,
    lowered: impl FnMut(usize, usize),
) {
    use crate::cut::sweep::{Segment, SegmentKind};
    let (c, s) = design.cos_sin();
    let uv = |p: P3| [p[0] * c + p[1] * s, -p[0] * s + p[1] * c, p[2]];
    let mut at = start;
    let mut segs = vec![];
    for m in moves::expand_arcs(moves, start).iter() {
        if let Move::Rapid(p) | Move::Feed(p, _) = *m {
            if p != at {
                segs.push(Segment {
                    from: uv(at),
                    to: uv(p),
                    kind: SegmentKind::Feed,
                    line: 0,
                    tool: 0,
                    feed_mm_min: 0.0,
                });
            }
            at = p;
        }
    }
    let grid = crate::cut::stock::Grid {
        x0: design.u0,
        y0: design.v0,
        pitch: stock.pitch_mm,
        nx: stock.nx,
        ny: stock.ny,
    };
    use crate::cut::stock::{sweep_into, Order};
    sweep_into(&grid, &mut stock.z_mm, 0.0, bit, &segs, Order::DeepestFirst, lowered);
}

/// Gaps between a finishing level's runs up to this many finishing-tool diameters are ridden at
/// `max(CL, S − doc)` instead of hopped over. A ridden gap still cuts wherever the stock stands above the
/// design (after roughing, nearly everywhere), while a hop is a retract, a descent through air and an
/// entry. On the default job (2 mm roughing ball, then the 0.5 mm ball; 2026-12-05): half a diameter (the
/// roughing layers' figure, [`rough::GAP_DIAMETERS`]) 1:00:50 with 3:08 feeding through air; one diameter
/// 0:59:53, 2:54; two 0:57:10, 2:36; four 0:56:46, 3:02; eight 0:57:10, 4:07.
pub const LEVEL_GAP_DIAMETERS: f64 = 2.0;

/// Columns per block of the stock's change map ([`stock_cl_rows`]).
const CHANGE_BLOCK: usize = 64;

/// The CL surface of `cutter` over `stock` (open edges) along each pass `vs[k]`, at its columns `cols[k]`, into `rows[k]`.
/// With `changed` (per stock row, per [`CHANGE_BLOCK`] columns: whether the stock there was lowered since
/// `rows` was computed), only the columns whose cutter covers a changed block are recomputed: the others'
/// samples are the same, so are their values.
fn stock_cl_rows(
    design: &raster::RotatedDesign,
    stock: &Heightfield,
    cutter: Shape,
    vs: &[f64],
    cols: &[std::ops::Range<usize>],
    rows: &mut [Vec<f64>],
    changed: Option<&[bool]>,
) {
    let sdc = dropcutter::DropCutter::new(stock, cutter, dropcutter::Edge::Open);
    let (p, nx, ny) = (design.hf.pitch_mm, design.hf.nx, design.hf.ny);
    let nb = nx.div_ceil(CHANGE_BLOCK);
    let r = cutter.radius_mm();
    // blocks either side an output block's cutter reaches into
    let reach = ((r / p).ceil() as usize + 1).div_ceil(CHANGE_BLOCK);
    rows.par_iter_mut().zip(vs).zip(cols).for_each(|((row, v), c)| {
        let y = v - design.v0;
        let Some(changed) = changed else {
            sdc.row_from(y, c.start, row);
            return;
        };
        let jc = y / p - 0.5;
        let j0 = ((jc - r / p).floor() - 1.0).max(0.0) as usize;
        let j1 = (((jc + r / p).ceil() + 1.0).max(0.0) as usize).min(ny.saturating_sub(1));
        let mut dirty = vec![false; nb];
        for j in j0..=j1 {
            for (b, _) in changed[j * nb..(j + 1) * nb].iter().enumerate().filter(|(_, c)| **c) {
                dirty[b.saturating_sub(reach)..(b + reach + 1).min(nb)].fill(true);
            }
        }
        let mut b = 0;
        while b < nb {
            if !dirty[b] {
                b += 1;
                continue;
            }
            let e = (b..nb).find(|&e| !dirty[e]).unwrap_or(nb);
            let (lo, hi) = ((b * CHANGE_BLOCK).max(c.start), (e * CHANGE_BLOCK).min(c.end));
            if lo < hi {
                sdc.row_from(y, lo, &mut row[lo - c.start..hi - c.start]);
            }
            b = e;
        }
    });
}

/// Intermediate finishing levels where the finishing tool would otherwise cut deeper than its depth of cut
/// `doc`. With `S` the CL surface of the finishing tool over the stock as it stands (the lowest its tip can
/// sit without touching it), the tip engages `S − z` deep. While some point has `S − CL > doc`, a level runs
/// at `z = S − doc` over the points where `S − CL > doc` (each run keeps one point at `CL` at either end;
/// gaps up to [`LEVEL_GAP_DIAMETERS`] tool diameters are ridden at `max(CL, S − doc)`), and the stock is then re-swept with that
/// level's moves ([`lower_stock`]), so each level is measured against the stock the one before it left, not
/// against an estimate. Points within the depth of cut are left to the final raster, which then engages at
/// most `doc` everywhere. Returns the number of levels and `S` along each pass after them.
fn intermediate_levels(
    b: &mut Builder,
    s: &StockSide,
    stock: &mut Heightfield,
) -> Result<(usize, Vec<Vec<f64>>), ToolpathError> {
    let (design, dc, vs, finals, strategy) = (s.design, s.dc, s.vs, s.raw, s.strategy);
    let (doc, stepover, feed, tol) = (s.cut.max_depth_of_cut_mm, s.stepover, s.feed, s.tol);
    let gap_points = (LEVEL_GAP_DIAMETERS * dc.cutter().diameter_mm() / design.hf.pitch_mm).ceil() as usize;
    let relief = -finals.iter().flatten().map(|p| p[2]).fold(0.0, f64::min);
    // each level lowers S by doc where it is above CL + doc; a few more than relief/doc cover the rounding
    let most = (relief / doc).ceil() as usize + 3;
    let cols: Vec<std::ops::Range<usize>> = vs.iter().map(|v| design.pass_columns(*v)).collect();
    debug_assert!(cols.iter().zip(finals).all(|(c, f)| c.len() == f.len()));
    let mut s_rows: Vec<Vec<f64>> = cols.iter().map(|c| vec![0.0; c.len()]).collect();
    let cutter = dc.cutter();
    stock_cl_rows(design, stock, cutter, vs, &cols, &mut s_rows, None);
    let mut levels = 0;
    loop {
        // the stock never stands above its top
        let over = |f: &P3, s: f64| s.min(0.0) - f[2];
        let worst = finals
            .iter()
            .zip(&s_rows)
            .flat_map(|(f, s)| f.iter().zip(s).map(|(f, s)| over(f, *s)))
            .fold(0.0, f64::max);
        if worst <= doc + 1e-6 {
            return Ok((levels, s_rows));
        }
        if levels >= most.min(rough::MAX_LAYERS) {
            return Err(limit(
                "max_depth_of_cut_mm",
                format!("{levels} finishing levels of {doc} mm still leave {worst:.4} mm of stock"),
            ));
        }
        b.moves.push(Move::Comment("finishing: intermediate level"));
        let mut rows = Vec::with_capacity(finals.len());
        let mut cuts = Vec::with_capacity(finals.len());
        let mut stock_cls = Vec::with_capacity(finals.len());
        for (r, (f, s)) in finals.iter().zip(&s_rows).enumerate() {
            let mut scl = s.clone();
            let mut pts: Vec<P3> = f
                .iter()
                .zip(s)
                .map(|(f, s)| [f[0], f[1], f[2].max(s.min(0.0) - doc)])
                .collect();
            let mut cut: Vec<bool> = f.iter().zip(s).map(|(f, s)| over(f, *s) > doc + 1e-6).collect();
            // oriented as the final raster's pass on this row
            if strategy.reverses(r) {
                pts.reverse();
                cut.reverse();
                scl.reverse();
            }
            rows.push(pts);
            cuts.push(cut);
            stock_cls.push(scl);
        }
        let lv = rough::Level {
            rows: &rows,
            cut: &cuts,
            feed_mm_min: feed,
            stepover_mm: stepover,
            gap_points,
            pitch_mm: design.hf.pitch_mm,
            tol_mm: tol,
            stock_cl: Some(&stock_cls),
            arc_resolution_mm: s.arcs.then(|| s.machine.write_resolution_mm()),
        };
        let (m0, at0) = (b.moves.len(), b.at);
        {
            let sdc = dropcutter::DropCutter::new(stock, cutter, dropcutter::Edge::Open);
            let link = |a: P3, e: P3| {
                link_points(design, dc, a, e, |z| z)
                    .into_iter()
                    .map(|p| {
                        let (u, v) = design.to_uv(p[0], p[1]);
                        let s = sdc.point(u - design.u0, v - design.v0).min(0.0);
                        [p[0], p[1], p[2].max(s - doc)]
                    })
                    .collect()
            };
            rough::emit_level(b, &lv, &link);
        }
        let nb = stock.nx.div_ceil(CHANGE_BLOCK);
        let mut changed = vec![false; nb * stock.ny];
        lower_stock(design, stock, &b.moves[m0..], at0, cutter, |i, j| {
            changed[j * nb + i / CHANGE_BLOCK] = true;
        });
        stock_cl_rows(design, stock, cutter, vs, &cols, &mut s_rows, Some(&changed));
        levels += 1;
    }
}
