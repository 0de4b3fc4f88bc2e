//! Grey-scale morphology of a heightfield by a tool's underside (DESIGN.md §4): the drop-cutter dilation
//! (the CL surface) and the opening (the surface an infinitely fine raster of the bit leaves). Shared by the
//! simulator's reach check and the design loop's as-milled model, so both see one model of what a bit can
//! reach.

use crate::tool::Shape;
use rayon::prelude::*;

/// Height of the opening above the design beyond which a sample counts as unreachable, µm (covers the
/// sampling of the opening itself, see `simulate::deviation`).
pub const REACH_TOLERANCE_UM: f64 = 0.25;

/// `out(x) = max_{|u| ≤ R} z(x + u) − prof(|u|)` over a grid (the drop-cutter dilation, DESIGN.md §4), rows
/// in parallel; with `periodic` the grid wraps, otherwise samples beyond it are absent.
///
/// The same samples and rim tolerance as `toolpath::dropcutter::DropCutter::surface`, but not the same
/// rounding: that forms the row offset as `(j′ + ½)·p − y` and the profile from `ρ²`, this one as `dj·p` and
/// from `ρ`, so the two agree only to a few ulp (≤ 6e-17 mm on ball and bull tests, exact for a flat), which
/// would move the last digits of the reported opening statistics.
pub fn dilate(z: &[f64], nx: usize, ny: usize, pitch: f64, periodic: bool, tool: &Shape) -> Vec<f64> {
    let bit = tool.normalized();
    let r = bit.radius_mm();
    let m = (r / pitch).ceil() as usize + 1;
    let mi = m as i64;
    // offsets (dj, [(di, -prof)])
    let rows: Vec<(i64, Vec<(i64, f64)>)> = (-mi..=mi)
        .map(|dj| {
            let dy = dj as f64 * pitch;
            let offs = (-mi..=mi)
                .filter_map(|di| {
                    let dx = di as f64 * pitch;
                    let d2 = dx * dx + dy * dy;
                    (d2 <= r * r * (1.0 + 1e-12)).then(|| (di, -bit.profile(d2.sqrt().min(r))))
                })
                .collect::<Vec<_>>();
            (dj, offs)
        })
        .filter(|(_, o)| !o.is_empty())
        .collect();
    let mut out = vec![f64::NEG_INFINITY; nx * ny];
    out.par_chunks_mut(nx).enumerate().for_each_init(
        || vec![0.0; nx + 2 * m],
        |buf, (j, orow)| {
            for (dj, offs) in &rows {
                let jj = j as i64 + dj;
                let jj = if periodic {
                    jj.rem_euclid(ny as i64) as usize
                } else if jj < 0 || jj >= ny as i64 {
                    continue;
                } else {
                    jj as usize
                };
                let src = &z[jj * nx..(jj + 1) * nx];
                for (k, v) in buf.iter_mut().enumerate() {
                    let i = k as i64 - mi;
                    *v = if periodic {
                        src[i.rem_euclid(nx as i64) as usize]
                    } else if i < 0 || i >= nx as i64 {
                        f64::NEG_INFINITY
                    } else {
                        src[i as usize]
                    };
                }
                for &(di, b) in offs {
                    let s = &buf[(mi + di) as usize..(mi + di) as usize + nx];
                    for (o, v) in orow.iter_mut().zip(s) {
                        let c = v + b;
                        if c > *o {
                            *o = c;
                        }
                    }
                }
            }
        },
    );
    out
}

/// The opening of a grid by the bit, `O = erode(dilate(h))`: the highest surface the bit can leave on `h`
/// from above, however fine its raster (the erosion of the drop-cutter CL surface, DESIGN.md §4).
pub fn opening(h: &[f64], nx: usize, ny: usize, pitch: f64, periodic: bool, tool: &Shape) -> Vec<f64> {
    let cl = dilate(h, nx, ny, pitch, periodic, tool);
    let neg: Vec<f64> = cl.iter().map(|v| -v).collect();
    dilate(&neg, nx, ny, pitch, periodic, tool)
        .into_iter()
        .map(|v| -v)
        .collect()
}
