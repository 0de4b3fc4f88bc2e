//! The stock heightfield and the parallel sweep over it.
//!
//! The stock is cut into square tiles of [`TILE`] cells, each stored contiguously and owned by one rayon task.
//! Every segment is binned, in program order, into the tiles its footprint's bounding box touches; each task
//! then sweeps its own tile's segments over its own cells, so no cell is ever written by two threads and the
//! result does not depend on the schedule.

use super::sweep::{Segment, SegmentKind};
use super::sweep::{Sweep, CUT_MM, LOWERED_MM};
use crate::cut::tool::Shape;
use rayon::prelude::*;

/// Side of a tile, cells.
pub const TILE: usize = 128;

/// Cells of a row tested together against a segment's lower bound before they are swept.
const CHUNK: usize = 16;

/// A regular grid of cell centres: cell `(i, j)` at `(x0 + (i + ½)·pitch, y0 + (j + ½)·pitch)`, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// x of the lower-left corner, mm.
    pub x0: f64,
    /// y of the lower-left corner, mm.
    pub y0: f64,
    /// Cell side, mm.
    pub pitch: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
}

/// What the sweep did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SweepReport {
    /// Cells under the segments' footprints (the row spans of their bounding stadiums), summed over segments;
    /// rows the sweep skips because nothing on them stands above the segment's reach count too.
    pub swept_cells: u64,
    /// Segments that could reach below the stock top (the others cannot remove anything).
    pub cutting_segments: usize,
    /// Indices of rapid (`G0`) segments that removed material, in program order.
    pub rapid_cuts: Vec<usize>,
    /// Indices of the segments that lowered some cell by more than [`CUT_MM`] when they ran (in program
    /// order; with [`Order::DeepestFirst`] meaningless, like `rapid_cuts`), ascending.
    pub cut_segments: Vec<usize>,
}

/// Sweep `segs` with `bit` over a stock flat at `top`; returns the heights row-major (`nx × ny`) and a report.
pub fn sweep(grid: &Grid, top: f64, bit: Shape, segs: &[Segment]) -> (Vec<f64>, SweepReport) {
    let mut z = vec![top; grid.nx * grid.ny];
    let report = sweep_into(grid, &mut z, top, bit, segs, Order::Program, |_, _| {});
    (z, report)
}

/// The order in which a tile's segments are swept. The stock is the same either way (a minimum); what
/// differs is the work, and which rapids are found cutting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// Program order: a rapid is reported when it removed material at the moment it ran.
    Program,
    /// The deepest segments first, so that the cells they lower let the rows and chunks of the shallower
    /// ones be skipped (a fifth less time on the default job's roughing, measured before rows and chunks
    /// were skipped by their highest cells). [`SweepReport::rapid_cuts`] is then meaningless: for stock
    /// models, not for checking a program.
    DeepestFirst,
}

/// Sweep `segs` with `bit` over the stock `z` as it stands (row-major `nx × ny` on `grid`, nowhere above
/// `top`), lowering it in place, and call `lowered(i, j)` for every cell the sweep lowered. Only the tiles
/// some segment reaches are visited, so a few moves over a large stock cost what their footprints cost.
pub fn sweep_into(
    grid: &Grid,
    z: &mut [f64],
    top: f64,
    bit: Shape,
    segs: &[Segment],
    order: Order,
    mut lowered: impl FnMut(usize, usize),
) -> SweepReport {
    assert_eq!(z.len(), grid.nx * grid.ny, "the stock is the grid's");
    let (tx, ty) = (grid.nx.div_ceil(TILE), grid.ny.div_ceil(TILE));
    let mut bins: Vec<Vec<u32>> = vec![vec![]; tx * ty];
    let mut sweeps: Vec<Sweep> = Vec::with_capacity(segs.len());
    let mut cutting = 0;
    for (k, s) in segs.iter().enumerate() {
        let sw = Sweep::new(bit, s.from, s.to);
        sweeps.push(sw);
        if sw.z_min() >= top {
            continue;
        }
        let [x_lo, y_lo, x_hi, y_hi] = sw.footprint();
        let cell = |v: f64, o: f64, n: usize| -> Option<usize> {
            let c = ((v - o) / grid.pitch).floor();
            (c >= 0.0).then(|| (c as usize).min(n - 1))
        };
        // tile range touched (clamped); skip footprints entirely off the stock
        if x_hi < grid.x0 || y_hi < grid.y0 {
            continue;
        }
        let (xe, ye) = (
            grid.x0 + grid.nx as f64 * grid.pitch,
            grid.y0 + grid.ny as f64 * grid.pitch,
        );
        if x_lo > xe || y_lo > ye {
            continue;
        }
        cutting += 1;
        let i0 = cell(x_lo, grid.x0, grid.nx).unwrap_or(0) / TILE;
        let j0 = cell(y_lo, grid.y0, grid.ny).unwrap_or(0) / TILE;
        let i1 = cell(x_hi, grid.x0, grid.nx).unwrap_or(0) / TILE;
        let j1 = cell(y_hi, grid.y0, grid.ny).unwrap_or(0) / TILE;
        for tj in j0..=j1 {
            for ti in i0..=i1 {
                bins[tj * tx + ti].push(k as u32);
            }
        }
    }
    if order == Order::DeepestFirst {
        // stable: segments at one depth keep their program order
        bins.par_iter_mut()
            .for_each(|bin| bin.sort_by(|x, y| sweeps[*x as usize].z_min().total_cmp(&sweeps[*y as usize].z_min())));
    }
    let stock: &[f64] = z;
    let results: Vec<(usize, TileOutput)> = bins
        .par_iter()
        .enumerate()
        .filter(|(_, bin)| !bin.is_empty())
        .map(|(t, bin)| {
            let (ti, tj) = (t % tx, t / tx);
            let out = pulp::Arch::new().dispatch(TileSweep {
                grid,
                stock,
                corner: (ti * TILE, tj * TILE),
                bin,
                sweeps: &sweeps,
                segs,
            });
            (t, out)
        })
        .collect();
    let mut report = SweepReport {
        cutting_segments: cutting,
        ..Default::default()
    };
    for (t, (cells, swept, rapid, cuts)) in results {
        let (ti, tj) = (t % tx, t / tx);
        let (ci0, cj0) = (ti * TILE, tj * TILE);
        let w = TILE.min(grid.nx - ci0);
        for (j, src) in cells.chunks(w).enumerate() {
            let dst = (cj0 + j) * grid.nx + ci0;
            for (i, (d, s)) in z[dst..dst + w].iter_mut().zip(src).enumerate() {
                if *s < *d {
                    *d = *s;
                    lowered(ci0 + i, cj0 + j);
                }
            }
        }
        report.swept_cells += swept;
        report.rapid_cuts.extend(rapid);
        report.cut_segments.extend(cuts);
    }
    report.rapid_cuts.sort_unstable();
    report.rapid_cuts.dedup();
    report.cut_segments.sort_unstable();
    report.cut_segments.dedup();
    report
}

/// A tile's cells, the cells swept, the rapids that lowered one, and the segments that cut.
type TileOutput = (Vec<f64>, u64, Vec<usize>, Vec<usize>);

/// One tile's sweep, run by `pulp` with the widest vector instructions this CPU has, so that the
/// per-cell closed forms of [`Sweep::row`] (inlined here) take four or eight cells at a time.
struct TileSweep<'a> {
    grid: &'a Grid,
    /// The stock as it stands, row-major over the whole grid.
    stock: &'a [f64],
    /// The tile's first cell, `(i, j)`.
    corner: (usize, usize),
    /// The tile's segments, in the sweep's [`Order`].
    bin: &'a [u32],
    sweeps: &'a [Sweep],
    segs: &'a [Segment],
}

impl pulp::WithSimd for TileSweep<'_> {
    type Output = TileOutput;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
        let Self {
            grid,
            stock,
            corner: (ci0, cj0),
            bin,
            sweeps,
            segs,
        } = self;
        let w = TILE.min(grid.nx - ci0);
        let h = TILE.min(grid.ny - cj0);
        let mut cells = Vec::with_capacity(w * h);
        for j in 0..h {
            let k = (cj0 + j) * grid.nx + ci0;
            cells.extend_from_slice(&stock[k..k + w]);
        }
        // each chunk's highest cell, kept as the sweep lowers them, and each row's: a row or chunk whose
        // highest cell is no higher than the lowest the segment reaches there is skipped after one compare
        let chunks = w.div_ceil(CHUNK);
        let highest = |c: &[f64]| c.iter().fold(f64::NEG_INFINITY, |m, v| if *v > m { *v } else { m });
        let mut chunk_top: Vec<f64> = (0..h)
            .flat_map(|j| cells[j * w..(j + 1) * w].chunks(CHUNK).map(highest))
            .collect();
        let mut row_top: Vec<f64> = chunk_top.chunks(chunks).map(highest).collect();
        let mut swept = 0u64;
        let mut rapid = vec![];
        let mut cuts = vec![];
        let x_first = grid.x0 + (ci0 as f64 + 0.5) * grid.pitch;
        for &k in bin {
            let sw = &sweeps[k as usize];
            let is_rapid = segs[k as usize].kind == SegmentKind::Rapid;
            let mut drop = 0.0f64;
            for j in 0..h {
                let y = grid.y0 + ((cj0 + j) as f64 + 0.5) * grid.pitch;
                let Some((lo, hi)) = sw.row_span(y) else { continue };
                // cells whose centre may lie in [lo, hi]
                let a = ((lo - x_first) / grid.pitch).ceil().max(0.0);
                let b = ((hi - x_first) / grid.pitch).floor().min(w as f64 - 1.0);
                if a > b {
                    continue;
                }
                let (a, b) = (a as usize, b as usize);
                swept += (b + 1 - a) as u64;
                let x_at = |i: usize| x_first + i as f64 * grid.pitch;
                if row_top[j] <= sw.floor(x_at(a), x_at(b), y) {
                    continue;
                }
                let (row, tops) = (
                    &mut cells[j * w..(j + 1) * w],
                    &mut chunk_top[j * chunks..(j + 1) * chunks],
                );
                let mut row_lowered = false;
                // chunk by chunk: skip those where nothing stands above the lowest the segment can reach
                for (c, top) in tops.iter_mut().enumerate().take(b / CHUNK + 1).skip(a / CHUNK) {
                    let (first, last) = ((c * CHUNK).max(a), (c * CHUNK + CHUNK - 1).min(b));
                    let (xa, xb) = (x_at(first), x_at(last));
                    if *top <= sw.floor(xa, xb, y) {
                        continue;
                    }
                    let (_, d) = sw.row(y, xa, grid.pitch, &mut row[first..=last]);
                    *top = highest(&row[c * CHUNK..((c + 1) * CHUNK).min(w)]);
                    drop = drop.max(d);
                    row_lowered = true;
                }
                if row_lowered {
                    row_top[j] = highest(tops);
                }
            }
            if drop > LOWERED_MM && is_rapid {
                rapid.push(k as usize);
            }
            if drop > CUT_MM {
                cuts.push(k as usize);
            }
        }
        (cells, swept, rapid, cuts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Tiled and parallel equals the plain serial minimum over every segment and cell.
    #[test]
    fn tiled_sweep_equals_serial_reference() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let grid = Grid {
            x0: -0.31,
            y0: 0.17,
            pitch: 0.01,
            nx: 300,
            ny: 270,
        };
        let segs: Vec<Segment> = (0..60)
            .map(|k| Segment {
                from: [
                    rng.gen_range(-1.0..3.5),
                    rng.gen_range(-0.5..3.5),
                    rng.gen_range(-0.4..0.2),
                ],
                to: [
                    rng.gen_range(-1.0..3.5),
                    rng.gen_range(-0.5..3.5),
                    rng.gen_range(-0.4..0.2),
                ],
                kind: if k % 7 == 0 {
                    SegmentKind::Rapid
                } else {
                    SegmentKind::Feed
                },
                line: k,
                tool: 0,
                feed_mm_min: 100.0,
            })
            .collect();
        for bit in [
            Shape::Ball { diameter_mm: 0.6 },
            Shape::Flat { diameter_mm: 0.4 },
            Shape::Bull {
                diameter_mm: 0.5,
                corner_radius_mm: 0.1,
            },
        ] {
            let (z, rep) = sweep(&grid, 0.0, bit, &segs);
            let sweeps: Vec<Sweep> = segs.iter().map(|s| Sweep::new(bit, s.from, s.to)).collect();
            for j in 0..grid.ny {
                for i in 0..grid.nx {
                    let (x, y) = (grid.x0 + (i as f64 + 0.5) * 0.01, grid.y0 + (j as f64 + 0.5) * 0.01);
                    let r = sweeps.iter().map(|s| s.lowest(x, y)).fold(0.0, f64::min);
                    // the bull's sweep is certified within BULL_TOLERANCE_MM (Newton's path, and so its last
                    // digits, moves with the last bits of the cell's coordinates)
                    let tol = if matches!(bit, Shape::Bull { .. }) {
                        crate::cut::sweep::BULL_TOLERANCE_MM
                    } else {
                        1e-12
                    };
                    assert!(
                        (z[j * grid.nx + i] - r).abs() < tol,
                        "{bit:?} ({i},{j}): {} vs {r}",
                        z[j * grid.nx + i]
                    );
                }
            }
            assert!(rep.swept_cells > 0 && rep.cutting_segments > 0);
            // in two halves, the second lowering the stock the first left: the same stock, and the cells the
            // second reports lowered are exactly those it took below the first's
            let (mut two, _) = sweep(&grid, 0.0, bit, &segs[..30]);
            let first = two.clone();
            let mut marked = vec![false; two.len()];
            sweep_into(&grid, &mut two, 0.0, bit, &segs[30..], Order::Program, |i, j| {
                marked[j * grid.nx + i] = true
            });
            assert_eq!(two, z);
            // deepest first: the same stock
            let mut deep = vec![0.0; z.len()];
            sweep_into(&grid, &mut deep, 0.0, bit, &segs, Order::DeepestFirst, |_, _| {});
            assert_eq!(deep, z);
            for k in 0..z.len() {
                assert_eq!(marked[k], two[k] < first[k], "cell {k}");
            }
            // a rapid counts as cutting only if it lowered something when it ran
            for &k in &rep.rapid_cuts {
                assert_eq!(segs[k].kind, SegmentKind::Rapid);
            }
        }
    }
}
