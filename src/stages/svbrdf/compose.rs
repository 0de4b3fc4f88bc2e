//! The part heightfield of a spatially varying target: at each cell, the height of the tile of the
//! cell's region, every tile laid from the work origin with the same period, each shifted by its own
//! offset so that the regions meet at a common level (DESIGN.md §3.3).

use super::{Labels, SvbrdfError};
use crate::base::heightfield::Heightfield;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The most cells a part heightfield may have (8 bytes each: 1 GB).
pub const MAX_PART_CELLS: usize = 128 << 20;

/// How the tiles' heights were brought to a common level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Alignment {
    /// Each tile's mean height at one level: the smallest steps at the borders on average.
    Mean,
    /// Each tile's top at the stock top: used when mean alignment would need more relief than the budget.
    Top,
}

/// The composed part.
#[derive(Clone, Debug)]
pub struct Part {
    /// The part's design heightfield over the work area, periodic with the area as its period (the toolpath
    /// repeats it only in the margin outside the area, where no region is judged).
    pub heightfield: Heightfield,
    /// Each region's tile offset, mm (added to the tile's heights).
    pub offsets_mm: Vec<f64>,
    /// How the offsets were chosen.
    pub alignment: Alignment,
    /// Highest minus lowest point of the part, mm (at most the alignment's bound).
    pub relief_mm: f64,
}

/// Compose the part: `tiles[k]` (periodic, one per region, all of one size and pitch) where `labels` says
/// region `k`, over `labels.area_mm`. The offsets put every tile's mean height at one level and the highest
/// tile top at z = 0 — unless that needs more than `budget_mm` of relief (a shallow tile's mean sits high, a
/// deep one's low; 0: no budget), when every tile's top goes to z = 0 instead, which never needs more than
/// the deepest tile. Either relief is a bound: a tile's highest or lowest cell may fall outside its region.
pub fn compose(tiles: &[&Heightfield], labels: &Labels, budget_mm: f64) -> Result<Part, SvbrdfError> {
    let bad = |s: String| Err(SvbrdfError::Config(s));
    let Some(t0) = tiles.first() else {
        return bad("no region tiles to compose".into());
    };
    if tiles.len() != labels.colors.len() {
        return bad(format!("{} tiles for {} regions", tiles.len(), labels.colors.len()));
    }
    if let Some(t) = tiles
        .iter()
        .find(|t| (t.nx, t.ny) != (t0.nx, t0.ny) || (t.pitch_mm - t0.pitch_mm).abs() > 1e-12 || !t.periodic)
    {
        return bad(format!(
            "the region tiles differ ({}×{} at {} mm against {}×{} at {} mm, periodic {}): every region needs the job's one tile period",
            t.nx, t.ny, t.pitch_mm, t0.nx, t0.ny, t0.pitch_mm, t.periodic
        ));
    }
    let p = t0.pitch_mm;
    let [ax, ay] = labels.area_mm;
    let (nx, ny) = ((ax / p).round() as usize, (ay / p).round() as usize);
    let cells = nx.checked_mul(ny).filter(|&c| c > 0 && c <= MAX_PART_CELLS);
    let Some(cells) = cells else {
        return bad(format!(
            "the part would be {nx} × {ny} cells at `facets.pitch_um` = {} µm over `toolpath.area_mm` = [{ax}, {ay}]; at most {MAX_PART_CELLS} cells",
            p * 1e3
        ));
    };
    let stats: Vec<(f64, f64, f64)> = tiles
        .iter()
        .map(|t| {
            let (lo, hi) = t.range();
            (t.z_mm.iter().sum::<f64>() / t.z_mm.len() as f64, lo, hi)
        })
        .collect();
    let above = stats.iter().map(|s| s.2 - s.0).fold(0.0, f64::max);
    let below = stats.iter().map(|s| s.0 - s.1).fold(0.0, f64::max);
    // a budget of 0 is no budget (as `facets.max_relief_mm`)
    let (alignment, offsets_mm): (Alignment, Vec<f64>) = if budget_mm <= 0.0 || above + below <= budget_mm + 1e-12 {
        (Alignment::Mean, stats.iter().map(|s| -s.0 - above).collect())
    } else {
        (Alignment::Top, stats.iter().map(|s| -s.2).collect())
    };
    let mut z = vec![0.0; cells];
    z.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        let y = (j as f64 + 0.5) * p;
        let tj = j % t0.ny;
        for (i, v) in row.iter_mut().enumerate() {
            let k = labels.at((i as f64 + 0.5) * p, y);
            *v = tiles[k].z_mm[tj * t0.nx + i % t0.nx] + offsets_mm[k];
        }
    });
    let heightfield = Heightfield {
        nx,
        ny,
        pitch_mm: p,
        periodic: true,
        z_mm: z,
    };
    let (lo, hi) = heightfield.range();
    Ok(Part {
        heightfield,
        offsets_mm,
        alignment,
        relief_mm: hi - lo,
    })
}
