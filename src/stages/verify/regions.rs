//! Verification of a spatially varying target (DESIGN.md §6.2): each region of the label image measured on
//! the simulated cut against its own target, away from the borders; how wide the borders are; and the part
//! rendered under a moving light.
//!
//! - **Where a region is measured.** A cell of the simulated surface belongs to the region its label says,
//!   at a Euclidean distance `d` from the nearest cell of another region. The *border* of a region is the
//!   band in which the cut departs from the composed design more than in the region's interior: the mean
//!   `|sim − design|` in 10 µm bands of `d`, against its mean over the interior (`d` ≥ 4 tool radii, at
//!   least 1 mm); the border width is the smallest `d` beyond which no band exceeds [`BORDER_FACTOR`] times the
//!   interior's. The region's milled NDF is measured over its cells at least the border width plus the slope
//!   mean's reach from every other region and the usual edge band from the stock's edge, with the slopes of
//!   the single-target measurement (mean over one stepover across the passes, scallop lobe put back).
//! - **Every point of the tile alike.** A region's shape holds parts of its tiles unequally (a strip of
//!   the field above a logo holds some facet rows and not others), which weights facets unequally just as
//!   a window of part of a tile would (`super::milled`): on the example's field the unweighted y variance
//!   ratio came out 0.85 where the balanced one is 0.97. So each measured cell is weighted by one over the
//!   number of measured cells at its tile phase (its position modulo the period); a region that holds one
//!   whole period clear of its border (the load checks one on the label image) holds every phase. The
//!   unweighted figure, the region as seen, is kept beside it (`as_seen_cov_ratio`).
//! - **The moving light.** A collimated light at `θ` from the normal in the x–z plane, seen from straight
//!   above: a cell with normal `n` reflects `L = D(n·h) / (4 n·v)` (the Beckmann polish lobe `D` about its
//!   own normal, `h` the half vector, masking and Fresnel taken as 1), averaged over the picture's pixels.

use super::metrics::{self, SurfaceMetrics, Tolerances};
use super::report::Figure;
use super::{VerifyConfig, VerifyError};
use crate::base::heightfield::Heightfield;
use crate::base::plot::Canvas;
use crate::base::surface;
use crate::stages::brdf::Brdf;
use crate::stages::facets::Tile;
use crate::stages::ndf::{Kernel, Ndf};
use crate::stages::simulate::{Deviation, Simulation};
use crate::stages::svbrdf::{distance_to_outside, hex, Labels};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A band of the border profile is part of the border while its mean `|sim − design|` exceeds this many
/// times the region interior's.
pub const BORDER_FACTOR: f64 = 1.5;

/// The label of simulated cells beyond the work area (where the toolpath cut the part's opposite edge).
const OUTSIDE: u8 = u8::MAX;

/// Width of the border profile's bands, mm.
pub const BAND_MM: f64 = 0.01;

/// The light's angles from the normal for the moving-light strip, degrees (toward +x).
pub const LIGHT_DEG: [f64; 6] = [0.0, 8.0, 16.0, 24.0, 32.0, 40.0];

/// One region to verify.
pub struct RegionInput<'a> {
    /// Name.
    pub name: &'a str,
    /// Its target spec.
    pub spec: &'a str,
    /// Its target.
    pub target: &'a Brdf,
    /// Its NDF stage's result.
    pub ndf: &'a Ndf,
    /// Its tile.
    pub tile: &'a Tile,
}

/// What verifying the regions compares.
pub struct RegionsInput<'a> {
    /// The regions, in label order.
    pub regions: Vec<RegionInput<'a>>,
    /// The label image.
    pub labels: &'a Labels,
    /// The base lobe the NDF stages deconvolved (the design tiles are convolved with it).
    pub base: Option<&'a Kernel>,
    /// The finishing raster's scallop lobe with the polish (the milled NDFs are convolved with it).
    pub scallop: &'a Kernel,
    /// The polish lobe's Beckmann α for the moving-light pictures.
    pub polish_alpha: f64,
    /// The simulated cut.
    pub sim: &'a Simulation,
    /// Its deviation from the composed part.
    pub deviation: &'a Deviation,
    /// The composed part (its pitch sets the edge band).
    pub part: &'a Heightfield,
    /// Finishing tool radius, mm.
    pub tool_radius_mm: f64,
    /// Finishing stepover, mm.
    pub stepover_mm: f64,
    /// Angle of the finishing passes from x, degrees.
    pub raster_angle_deg: f64,
    /// The machinable cone, degrees.
    pub cone_deg: f64,
}

/// One region's figures (`metrics.json` `regions[k]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegionMetrics {
    /// Name.
    pub name: String,
    /// Label colour, `#rrggbb`.
    pub color: String,
    /// Target spec.
    pub target: String,
    /// Its share of the label image.
    pub area_fraction: f64,
    /// Border width: the band along other regions where the cut departs from the design, mm.
    pub border_mm: f64,
    /// Distance from other regions inside which the milled NDF is not measured, mm.
    pub excluded_mm: f64,
    /// Cells measured.
    pub measured_cells: usize,
    /// … and their area, mm².
    pub measured_mm2: f64,
    /// Mean `|sim − design|` over the region's interior, µm (the border's reference).
    pub interior_deviation_um: f64,
    /// The border profile: `[d_mm, mean |sim − design| µm]` per band.
    pub border_profile: Vec<[f64; 2]>,
    /// Share of its tile's points (phases) among its measured cells (1: the region holds every point).
    pub phase_coverage: f64,
    /// The slope variance ratio of its measured cells unweighted (the region as seen), x and y.
    pub as_seen_cov_ratio: [f64; 2],
    /// Mean reflected radiance of its measured cells under each light of `light_deg` (relative units).
    pub light_radiance: Vec<f64>,
    /// Its design tile (facets ⊛ base lobe) against its target.
    pub design: SurfaceMetrics,
    /// Its milled cells against its target.
    pub milled: SurfaceMetrics,
    /// Every milled check passes.
    pub pass: bool,
}

/// `metrics.json` of a job with `[svbrdf]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegionsMetrics {
    /// Format version.
    pub version: u32,
    /// `"svbrdf"`: the file holds regions (a single-target job's `metrics.json` has `design` and `milled`).
    pub kind: String,
    /// Every region passes.
    pub pass: bool,
    /// The tolerances used (each region's own checks).
    pub tolerances: Tolerances,
    /// The regions.
    pub regions: Vec<RegionMetrics>,
    /// The moving light's angles from the normal, degrees.
    pub light_deg: Vec<f64>,
    /// Reasons for every failing check, and what else the user should know.
    pub notes: Vec<String>,
}

/// Verify every region; the metrics and the figures (label map, moving light, border profiles, each
/// region's NDFs).
pub fn run(cfg: &VerifyConfig, input: &RegionsInput) -> Result<(RegionsMetrics, Vec<Figure>), VerifyError> {
    cfg.validate()?;
    let tol = cfg.tolerances;
    let hf = &input.sim.heightfield;
    let (nx, ny, p) = (hf.nx, hf.ny, hf.pitch_mm);
    let [ox, oy] = input.sim.origin_mm;
    let label: Vec<u8> = (0..nx * ny)
        .into_par_iter()
        .map(|c| {
            let (i, j) = (c % nx, c / nx);
            let (x, y) = (ox + (i as f64 + 0.5) * p, oy + (j as f64 + 0.5) * p);
            let [ax, ay] = input.labels.area_mm;
            if (0.0..=ax).contains(&x) && (0.0..=ay).contains(&y) {
                input.labels.at(x, y) as u8
            } else {
                // beyond the work area the toolpath's margin holds the part's opposite edge: no region's
                OUTSIDE
            }
        })
        .collect();
    let edge = ((2.0 * input.tool_radius_mm + 2.0 * input.part.pitch_mm) / p).ceil() as usize
        + super::milled::reach_cells(p, input.stepover_mm);
    if nx <= 2 * edge + 2 || ny <= 2 * edge + 2 {
        return Err(VerifyError::Region(format!(
            "the simulated surface ({nx} × {ny} cells) is too small for its {edge}-cell edge band"
        )));
    }
    let cells = [edge, edge, nx - 2 * edge, ny - 2 * edge];
    let slopes = surface::stepover_slopes(hf, cells, input.raster_angle_deg, input.stepover_mm);
    let reach_mm = super::milled::reach_cells(p, input.stepover_mm) as f64 * p;
    let reference_mm = (4.0 * input.tool_radius_mm).max(1.0);
    let cone_tan = input.cone_deg.to_radians().tan();
    // distance to the work area's edge, beyond which the toolpath cut the part's opposite edge (DESIGN.md
    // §3.3): a ball centred within r of that seam can be lifted by it, so cells within 2r of the edge are
    // neither in the border profile nor measured
    let edge_mm: Vec<f64> = distance_to_outside(&label.iter().map(|&l| l == OUTSIDE).collect::<Vec<_>>(), nx, ny)
        .into_iter()
        .map(|d| d * p)
        .collect();
    let seam_mm = 2.0 * input.tool_radius_mm + reach_mm;
    let ctx = Shared {
        cfg,
        input,
        label: &label,
        edge_mm: &edge_mm,
        cells,
        slopes: &slopes,
        reach_mm,
        reference_mm,
        cone_tan,
        seam_mm,
        light: light_dirs(),
        fractions: input.labels.fractions(),
    };
    let mut out = vec![];
    let mut notes = vec![];
    let mut figures = vec![];
    for (k, r) in input.regions.iter().enumerate() {
        out.push(region(&ctx, k, r, &mut notes, &mut figures)?);
    }
    let light = ctx.light;
    let strip = light_strip(hf, cells, &light, input.polish_alpha);
    let mut all = vec![
        Figure::new(
            "Label map",
            format!(
                "The label image `{}` over the work area ({} × {} mm; right = +x, up = +y), each region in its label colour: {}.",
                input.labels.path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default(),
                input.labels.area_mm[0],
                input.labels.area_mm[1],
                out.iter().map(|r| format!("`{}` {} ({:.0}%)", r.name, r.color, r.area_fraction * 100.0)).collect::<Vec<_>>().join(", ")
            ),
            &input.labels.figure(480),
        ),
        Figure::new(
            "The milled part under a moving light",
            format!(
                "The simulated cut (inside the edge band) seen from straight above, lit by a collimated light at {} degrees from the normal toward +x; each cell reflects its polish lobe (Beckmann α = {}) about its own normal, averaged over each pixel; one brightness scale for all frames (gamma 2.2). Mean radiance per region and frame: {}.",
                LIGHT_DEG.map(|d| format!("{d:.0}")).join(", "),
                input.polish_alpha,
                out.iter()
                    .map(|r| format!("`{}` {}", r.name, r.light_radiance.iter().map(|v| format!("{v:.2}")).collect::<Vec<_>>().join(" / ")))
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
            &strip,
        ),
        border_figure(&out),
    ];
    all.extend(figures);
    Ok((
        RegionsMetrics {
            version: 1,
            kind: "svbrdf".into(),
            pass: out.iter().all(|r| r.pass),
            tolerances: tol,
            light_deg: LIGHT_DEG.to_vec(),
            regions: out,
            notes,
        },
        all,
    ))
}

/// What every region's measurement shares: the label of each simulated cell, the distance to the work
/// area's edge, the measured window and its stepover slopes, and the bands and light of the figures.
struct Shared<'a> {
    cfg: &'a VerifyConfig,
    input: &'a RegionsInput<'a>,
    label: &'a [u8],
    edge_mm: &'a [f64],
    cells: [usize; 4],
    slopes: &'a [(f64, f64)],
    reach_mm: f64,
    reference_mm: f64,
    cone_tan: f64,
    seam_mm: f64,
    light: Vec<[f64; 3]>,
    fractions: Vec<f64>,
}

/// Region `k` against its own target away from its border (phase-weighted), its border profile and
/// radiance under the moving light; a failing check's reason goes to `notes`, its figures to `figures`.
fn region(
    ctx: &Shared,
    k: usize,
    r: &RegionInput,
    notes: &mut Vec<String>,
    figures: &mut Vec<Figure>,
) -> Result<RegionMetrics, VerifyError> {
    let Shared {
        cfg,
        input,
        label,
        edge_mm,
        cells,
        slopes,
        reach_mm,
        reference_mm,
        cone_tan,
        seam_mm,
        ..
    } = *ctx;
    let (light, fractions) = (&ctx.light, &ctx.fractions);
    let tol = cfg.tolerances;
    let hf = &input.sim.heightfield;
    let (nx, ny, p) = (hf.nx, hf.ny, hf.pitch_mm);
    let [ox, oy] = input.sim.origin_mm;
    // distance to the other regions (not the area's edge: the border is where two regions meet)
    let dist: Vec<f64> = distance_to_outside(
        &label
            .iter()
            .map(|&l| l as usize != k && l != OUTSIDE)
            .collect::<Vec<_>>(),
        nx,
        ny,
    )
    .into_iter()
    .map(|d| d * p)
    .collect();
    let (profile, interior) = border_profile(&dist, edge_mm, seam_mm, label, k, input.deviation, reference_mm);
    let border_mm = border_width(&profile, interior);
    let excluded_mm = border_mm + reach_mm;
    let inside = |i: usize, j: usize| {
        let c = (j + cells[1]) * nx + i + cells[0];
        label[c] as usize == k && dist[c] >= excluded_mm && edge_mm[c] >= seam_mm
    };
    // the region's measured cells, each weighted by 1 / (cells of its tile phase), so every point of the
    // tile counts alike whatever part of the tiles the region's shape holds (module notes)
    let t = &r.tile.heightfield;
    let (mut mine, mut phase) = (vec![], vec![]);
    for (c, s) in slopes.iter().enumerate() {
        let (i, j) = (c % cells[2], c / cells[2]);
        if inside(i, j) {
            let x = ox + (i + cells[0]) as f64 * p + 0.5 * p;
            let y = oy + (j + cells[1]) as f64 * p + 0.5 * p;
            let u = ((x / t.pitch_mm).floor() as i64).rem_euclid(t.nx as i64) as usize;
            let v = ((y / t.pitch_mm).floor() as i64).rem_euclid(t.ny as i64) as usize;
            mine.push(*s);
            phase.push(v * t.nx + u);
        }
    }
    if mine.is_empty() {
        return Err(VerifyError::Region(format!(
            "region `{}` has no cell {excluded_mm:.2} mm from the other regions and inside the stock's edge band: nothing of it can be measured",
            r.name
        )));
    }
    let mut count = vec![0u32; t.nx * t.ny];
    for &ph in &phase {
        count[ph] += 1;
    }
    let phase_coverage = count.iter().filter(|&&c| c > 0).count() as f64 / count.len() as f64;
    let weights: Vec<f64> = phase.iter().map(|&ph| 1.0 / count[ph] as f64).collect();
    let domain = r.ndf.config.domain();
    let convolved = |w: Option<&[f64]>| {
        let (raw, _) = surface::ndf_of_weighted_slopes(&mine, w, domain);
        let mut g = input.scallop.convolve(&raw);
        g.normalise();
        g
    };
    let milled = convolved(Some(&weights));
    let as_seen = metrics::measure(&r.ndf.observed, &convolved(None), r.target, &[], &tol, cone_tan);
    let [lo, hi] = tol.cov_ratio;
    if as_seen.cov_ratio.iter().any(|v| *v < lo || *v > hi) {
        notes.push(format!(
            "Region `{}` as seen (its cells unweighted) has slope variance ratio [{:.3}, {:.3}], outside [{lo}, {hi}]: its shape holds some parts of its tiles more than others; a region several tile periods across averages this out.",
            r.name, as_seen.cov_ratio[0], as_seen.cov_ratio[1]
        ));
    }
    let (design, _) = crate::stages::design::design_ndf(r.tile, input.base, domain);
    let mut design_m = metrics::measure(&r.ndf.observed, &design, r.target, &cfg.incident_deg, &tol, cone_tan);
    let mut milled_m = metrics::measure(&r.ndf.observed, &milled, r.target, &cfg.incident_deg, &tol, cone_tan);
    if let Some(h) = r.target.highlight() {
        let c = super::highlight::compare(
            h,
            r.ndf,
            input.base,
            &design,
            &milled,
            &mut design_m,
            &mut milled_m,
            &tol,
        );
        figures.push(Figure {
            title: format!("Region `{}`: highlight", r.name),
            ..c.figure
        });
    }
    // a region whose measured cells miss some points of its tile cannot show the tile's distribution
    // (the design tile holds every point of itself: its row reads 1, so both columns line up)
    for (m, v) in [(&mut design_m, 1.0), (&mut milled_m, phase_coverage)] {
        m.checks.push(metrics::Check {
            name: "tile points measured (phase coverage)".into(),
            value: v,
            tolerance: "= 1 (every point of the tile clear of the border)".into(),
            pass: v >= 1.0,
        });
        m.pass = m.checks.iter().all(|c| c.pass);
    }
    for c in milled_m.checks.iter().filter(|c| !c.pass) {
        notes.push(format!(
            "Region `{}`: {} = {:.4} (needs {}).",
            r.name, c.name, c.value, c.tolerance
        ));
    }
    let radiance = region_radiance(hf, cells, light, input.polish_alpha, inside);
    let measured_cells = mine.len();
    let as_seen_cov_ratio = as_seen.cov_ratio;
    figures.push(region_ndfs(r, &r.ndf.observed, &milled));
    Ok(RegionMetrics {
        name: r.name.to_string(),
        color: hex(input.labels.colors[k]),
        target: r.spec.to_string(),
        area_fraction: fractions[k],
        border_mm,
        excluded_mm,
        measured_cells,
        measured_mm2: measured_cells as f64 * p * p,
        interior_deviation_um: interior,
        border_profile: profile,
        light_radiance: radiance,
        phase_coverage,
        as_seen_cov_ratio,
        pass: milled_m.pass,
        design: design_m,
        milled: milled_m,
    })
}

/// Mean `|sim − design|` per [`BAND_MM`] band of distance from the other regions, over region `k`'s assessed
/// cells (at least `seam_mm` from the work area's edge) out to `reference_mm`, and the mean beyond (the interior; the farthest quarter of the bands when
/// the region reaches no farther).
fn border_profile(
    dist: &[f64],
    edge_mm: &[f64],
    seam_mm: f64,
    label: &[u8],
    k: usize,
    dev: &Deviation,
    reference_mm: f64,
) -> (Vec<[f64; 2]>, f64) {
    let bands = (reference_mm / BAND_MM).ceil() as usize;
    let mut sum = vec![0.0; bands + 1];
    let mut n = vec![0usize; bands + 1];
    for (((d, e), l), v) in dist.iter().zip(edge_mm).zip(label).zip(&dev.map_um) {
        if *l as usize != k || !v.is_finite() || *e < seam_mm {
            continue;
        }
        let b = ((d / BAND_MM) as usize).min(bands);
        sum[b] += (*v as f64).abs();
        n[b] += 1;
    }
    let profile: Vec<[f64; 2]> = (0..bands)
        .filter(|&b| n[b] > 0)
        .map(|b| [(b as f64 + 0.5) * BAND_MM, sum[b] / n[b] as f64])
        .collect();
    let interior = if n[bands] > 0 {
        sum[bands] / n[bands] as f64
    } else {
        let far = &profile[profile.len() * 3 / 4..];
        far.iter().map(|v| v[1]).sum::<f64>() / far.len().max(1) as f64
    };
    (profile, interior)
}

/// The smallest distance beyond which no band of `profile` exceeds [`BORDER_FACTOR`] × `interior`, mm.
fn border_width(profile: &[[f64; 2]], interior: f64) -> f64 {
    profile
        .iter()
        .rev()
        .find(|v| v[1] > BORDER_FACTOR * interior)
        .map_or(0.0, |v| v[0] + 0.5 * BAND_MM)
}

/// The light directions of [`LIGHT_DEG`].
fn light_dirs() -> Vec<[f64; 3]> {
    LIGHT_DEG
        .iter()
        .map(|d| {
            let (s, c) = d.to_radians().sin_cos();
            [s, 0.0, c]
        })
        .collect()
}

/// Radiance toward the viewer above of a cell with slopes `(p, q)` under light `l`: `D(n·h)/(4 n·v)`,
/// Beckmann `D` of roughness `alpha` (module notes).
#[inline]
pub fn radiance(p: f64, q: f64, l: &[f64; 3], alpha: f64) -> f64 {
    let k = 1.0 / (1.0 + p * p + q * q).sqrt();
    let n = [-p * k, -q * k, k];
    let nl = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
    if nl <= 0.0 {
        return 0.0;
    }
    let h = [l[0], l[1], l[2] + 1.0];
    let hn = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    let c = (n[0] * h[0] + n[1] * h[1] + n[2] * h[2]) / hn;
    if c <= 0.0 {
        return 0.0;
    }
    let c2 = c * c;
    let t2 = (1.0 - c2) / c2;
    (-t2 / (alpha * alpha)).exp() / (std::f64::consts::PI * alpha * alpha * c2 * c2) / (4.0 * n[2])
}

/// Central-difference slopes of cell `(i, j)` of `hf`.
#[inline]
fn cell_slopes(hf: &Heightfield, i: usize, j: usize) -> (f64, f64) {
    let p2 = 2.0 * hf.pitch_mm;
    (
        (hf.at(i + 1, j) - hf.at(i - 1, j)) / p2,
        (hf.at(i, j + 1) - hf.at(i, j - 1)) / p2,
    )
}

/// Mean radiance of the cells of `cells` (offsets within it) that `keep` accepts, per light.
fn region_radiance(
    hf: &Heightfield,
    cells: [usize; 4],
    light: &[[f64; 3]],
    alpha: f64,
    keep: impl Fn(usize, usize) -> bool + Sync,
) -> Vec<f64> {
    let [i0, j0, w, h] = cells;
    let (sum, n) = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut s = vec![0.0; light.len()];
            let mut n = 0usize;
            for i in (0..w).filter(|&i| keep(i, j)) {
                let (p, q) = cell_slopes(hf, i0 + i, j0 + j);
                for (acc, l) in s.iter_mut().zip(light) {
                    *acc += radiance(p, q, l, alpha);
                }
                n += 1;
            }
            (s, n)
        })
        // added in row order, whatever the schedule
        .collect::<Vec<_>>()
        .into_iter()
        .fold((vec![0.0; light.len()], 0), |a, b| {
            (a.0.iter().zip(&b.0).map(|(x, y)| x + y).collect(), a.1 + b.1)
        });
    sum.iter().map(|s| s / n.max(1) as f64).collect()
}

/// The moving-light strip: one frame per light, each at most 300 px wide, one brightness scale.
fn light_strip(hf: &Heightfield, cells: [usize; 4], light: &[[f64; 3]], alpha: f64) -> Canvas {
    let [i0, j0, w, h] = cells;
    let f = w.max(h).div_ceil(300).max(1);
    let (fw, fh) = ((w / f).max(1), (h / f).max(1));
    let frames: Vec<Vec<f64>> = light
        .iter()
        .map(|l| {
            (0..fw * fh)
                .into_par_iter()
                .map(|c| {
                    let (x, y) = (c % fw, c / fw);
                    let mut s = 0.0;
                    for dj in 0..f {
                        for di in 0..f {
                            // picture rows top first: +y up
                            let i = i0 + (x * f + di).min(w - 1);
                            let j = j0 + ((fh - 1 - y) * f + dj).min(h - 1);
                            let (p, q) = cell_slopes(hf, i, j);
                            s += radiance(p, q, l, alpha);
                        }
                    }
                    s / (f * f) as f64
                })
                .collect()
        })
        .collect();
    let mut all: Vec<f64> = frames.iter().flatten().copied().collect();
    all.sort_by(f64::total_cmp);
    let top = all[((all.len() as f64 * 0.995) as usize).min(all.len() - 1)].max(1e-12);
    let gap = 6u32;
    let mut c = Canvas::new((fw as u32 + gap) * frames.len() as u32 + gap, fh as u32 + 2 * gap + 16);
    for (k, fr) in frames.iter().enumerate() {
        let x0 = gap as i64 + k as i64 * (fw as i64 + gap as i64);
        for (idx, v) in fr.iter().enumerate() {
            let g = ((v / top).clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8;
            c.put(x0 + (idx % fw) as i64, gap as i64 + (idx / fw) as i64, [g, g, g]);
        }
        c.text(
            (x0 + fw as i64 / 2) as i32,
            (fh as u32 + gap + 12) as i32,
            &format!("light {:.0}°", LIGHT_DEG[k]),
            embedded_graphics::text::Alignment::Center,
        );
    }
    c
}

/// The border profiles of every region.
fn border_figure(regions: &[RegionMetrics]) -> Figure {
    use crate::base::plot::{LinePlot, Series, PALETTE};
    let series: Vec<Series> = regions
        .iter()
        .enumerate()
        .flat_map(|(k, r)| {
            let color = PALETTE[k % PALETTE.len()];
            let x1 = r.border_profile.last().map_or(1.0, |v| v[0]);
            [
                Series {
                    label: format!("{} |sim - design|", r.name),
                    points: r.border_profile.iter().map(|v| (v[0], v[1])).collect(),
                    color,
                    dashed: false,
                },
                // the border (a distance, mm) and the band it is measured against (a departure, µm) are
                // two marks with a legend entry each
                Series {
                    label: format!("{}: border {:.2} mm", r.name, r.border_mm),
                    points: vec![
                        (r.border_mm, 0.0),
                        (r.border_mm, BORDER_FACTOR * r.interior_deviation_um),
                    ],
                    color,
                    dashed: true,
                },
                Series {
                    label: format!(
                        "{}: {BORDER_FACTOR}× the interior's {:.2} µm",
                        r.name, r.interior_deviation_um
                    ),
                    points: vec![
                        (r.border_mm, BORDER_FACTOR * r.interior_deviation_um),
                        (x1, BORDER_FACTOR * r.interior_deviation_um),
                    ],
                    color: color.map(|c| ((u16::from(c) + 255) / 2) as u8),
                    dashed: true,
                },
            ]
        })
        .collect();
    let plot = LinePlot {
        title: "departure from the design by distance from the other regions".into(),
        x_label: "distance from the border (mm)".into(),
        y_label: "mean |sim - design| (µm)".into(),
        series,
        size_px: (560, 300),
        log_y: false,
        whole_x: false,
    };
    Figure::new(
        "Region borders",
        format!(
            "Each region's mean departure of the simulated cut from the composed design in {} µm bands of distance from the nearest other region. The dashed upright line marks the border width, the paler dashed line {BORDER_FACTOR} times the interior's departure: beyond the border no band departs more than that. {}",
            BAND_MM * 1e3,
            regions
                .iter()
                .map(|r| format!("`{}`: border {:.2} mm, interior {:.3} µm; its NDF measured over {:.1} mm² at least {:.2} mm from the other regions.", r.name, r.border_mm, r.interior_deviation_um, r.measured_mm2, r.excluded_mm))
                .collect::<Vec<_>>()
                .join(" ")
        ),
        &plot.render(),
    )
}

/// A region's observed target distribution beside its milled NDF.
fn region_ndfs(
    r: &RegionInput,
    observed: &crate::base::slope::SlopeGrid,
    milled: &crate::base::slope::SlopeGrid,
) -> Figure {
    let c = Canvas::hstack(&[
        crate::stages::ndf::render_png(observed, "target: observed distribution O"),
        crate::stages::ndf::render_png(milled, "milled cells' NDF"),
    ]);
    Figure::new(
        format!("Region `{}`", r.name),
        format!(
            "Left, the observed half-angle distribution of `{}`; right, the NDF of the region's milled cells away from its border (slopes over one stepover, the scallop lobe put back).",
            r.spec
        ),
        &c,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radiance_peaks_where_the_normal_is_the_half_vector() {
        // a light at 24° toward +x, seen from above, has its half vector at 12° toward +x: the normal of
        // slope p = −tan 12° (z falling toward +x)
        let l = light_dirs()[3]; // 24°
        let best = (-400..=400)
            .map(|k| k as f64 * 0.001)
            .max_by(|a, b| radiance(*a, 0.0, &l, 0.1).total_cmp(&radiance(*b, 0.0, &l, 0.1)))
            .unwrap();
        assert!((best + 12f64.to_radians().tan()).abs() < 2e-3, "brightest slope {best}");
        // at normal light and view a flat cell reflects the lobe's peak, D(1)/4 = 1/(4πα²)
        let flat = radiance(0.0, 0.0, &[0.0, 0.0, 1.0], 0.1);
        assert!((flat - 1.0 / (4.0 * std::f64::consts::PI * 0.01)).abs() < 1e-9);
    }

    #[test]
    fn the_border_is_where_the_profile_leaves_the_band() {
        let profile: Vec<[f64; 2]> = (0..100)
            .map(|b| [(b as f64 + 0.5) * BAND_MM, if b < 23 { 5.0 } else { 1.0 }])
            .collect();
        assert!((border_width(&profile, 1.0) - 0.23).abs() < 1e-12);
        assert_eq!(border_width(&profile[30..], 1.0), 0.0);
    }
}
