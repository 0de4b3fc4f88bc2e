//! Grey-scale morphology of a heightfield by a tool's underside (DESIGN.md §4): the drop-cutter dilation
//! (the CL surface) and the opening (the surface an infinitely fine raster of the bit leaves). Shared by the
//! simulator's reach check and the design loop's as-milled model, so both see one model of what a bit can
//! reach.

use crate::tool::Shape;
use rayon::prelude::*;

/// Height of the opening above the design beyond which a sample counts as unreachable, µm (covers the
/// sampling of the opening itself, see `simulate::deviation`).
pub const REACH_TOLERANCE_UM: f64 = 0.25;

/// `out[i] = max(out[i], src[i] + b)`: the inner loop of every dilation here and in the drop-cutter. Written
/// as a select (`if v > o { v } else { o }`), which compiles to packed `max` instructions; a conditional
/// store compiled to a compare and branch per element and ran at half the speed.
#[inline]
pub fn max_add(out: &mut [f64], src: &[f64], b: f64) {
    for (o, s) in out.iter_mut().zip(src) {
        let v = s + b;
        *o = if v > *o { v } else { *o };
    }
}

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
                    max_add(orow, &buf[(mi + di) as usize..(mi + di) as usize + nx], b);
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

/// Samples per tool radius below which [`opening_periodic`] takes the opening on a decimated grid.
pub const OPENING_SAMPLES_PER_RADIUS: f64 = 24.0;

/// The opening of a periodic `nx × ny` grid, taken on every `k`-th sample when the grid is finer than
/// `r / 24` (`k = ⌊r / (24·pitch)⌋`, when it divides both sides) and brought back by periodic bilinear
/// interpolation, never below the grid itself (an opening never is: convex edges, where interpolation
/// would cut the corner, keep the surface). Cost falls by `k⁴` (cells by `k²`, the bit's footprint by
/// `k²`). The sampling bound of the opening becomes `(k·p)²(1 + s²)^{3/2}/(8r)` (0.15 µm for a 0.5 mm
/// ball at slope 1, under [`REACH_TOLERANCE_UM`]). Where the opening is steep — the bit's fillet falling
/// from the top of a step between facets, near vertical — a chord of `k·p` misses the sphere by up to
/// about `0.2·√(2r·k·p)` (14 µm for that ball at 10 µm), and across a kink where two fillets meet by
/// `Δslope·k·p/4`: both only where the opening stands above the grid, in cells that are unreachable
/// either way, so the reach classification barely moves (on the default job 12.41% unreachable against
/// 12.43% from the full opening).
pub fn opening_periodic(h: &[f64], nx: usize, ny: usize, pitch: f64, tool: &Shape) -> Vec<f64> {
    let k = (tool.radius_mm() / (OPENING_SAMPLES_PER_RADIUS * pitch)).floor() as usize;
    if k < 2 || nx % k != 0 || ny % k != 0 || nx / k < 4 || ny / k < 4 {
        return opening(h, nx, ny, pitch, true, tool);
    }
    let (cx, cy) = (nx / k, ny / k);
    let coarse: Vec<f64> = (0..cx * cy).map(|c| h[(c / cx) * k * nx + (c % cx) * k]).collect();
    let open = opening(&coarse, cx, cy, pitch * k as f64, true, tool);
    let mut out = vec![0.0; nx * ny];
    out.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        let (j0, fy) = (j / k, (j % k) as f64 / k as f64);
        let j1 = (j0 + 1) % cy;
        for (i, v) in row.iter_mut().enumerate() {
            let (i0, fx) = (i / k, (i % k) as f64 / k as f64);
            let i1 = (i0 + 1) % cx;
            let a = open[j0 * cx + i0] * (1.0 - fx) + open[j0 * cx + i1] * fx;
            let b = open[j1 * cx + i0] * (1.0 - fx) + open[j1 * cx + i1] * fx;
            *v = (a * (1.0 - fy) + b * fy).max(h[j * nx + i]);
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::Brdf;
    use crate::{facets, ndf};

    #[test]
    fn the_decimated_opening_stays_within_its_sampling_bound_of_the_full_one() {
        let n = ndf::run(
            &ndf::NdfConfig {
                res: 64,
                ..Default::default()
            },
            &Brdf::parse("beckmann:alpha=0.2").unwrap(),
            None,
        )
        .unwrap();
        let cfg = facets::FacetsConfig {
            facets_x: 4,
            facets_y: 4,
            facet_mm: 1.0,
            pitch_um: 5.0,
            ..Default::default()
        };
        let tile = facets::run(&cfg, &n.target).unwrap();
        let hf = &tile.heightfield;
        let tool = Shape::Ball { diameter_mm: 0.5 };
        let full = opening(&hf.z_mm, hf.nx, hf.ny, hf.pitch_mm, true, &tool);
        let fast = opening_periodic(&hf.z_mm, hf.nx, hf.ny, hf.pitch_mm, &tool);
        // k = 2 here. The bound: a chord of k·p across the steepest part of a fillet (module notes) plus the
        // coarse grid's sampling bound; and the reach classification agrees almost everywhere
        let (kp, r) = (2.0 * hf.pitch_mm, 0.25);
        let bound = 0.2 * (2.0 * r * kp).sqrt() + kp * kp * 2f64.powf(1.5) / (8.0 * r);
        let tol = REACH_TOLERANCE_UM * 1e-3;
        let (mut worst, mut differ) = (0.0f64, 0usize);
        for (k, (a, b)) in fast.iter().zip(&full).enumerate() {
            assert!(*a >= hf.z_mm[k] - 1e-15, "below the surface at {k}");
            worst = worst.max((a - b).abs());
            differ += ((a - hf.z_mm[k] > tol) != (b - hf.z_mm[k] > tol)) as usize;
        }
        assert!(worst <= bound, "decimated opening off by {worst} mm, bound {bound} mm");
        let frac = differ as f64 / fast.len() as f64;
        assert!(
            frac < 0.01,
            "reach classification differs on {:.3}% of the cells",
            frac * 100.0
        );
    }
}
