//! The as-milled model of a tile: what the finishing ball leaves of the periodic design (DESIGN.md §4.3).
//!
//! The best any raster of a ball can leave on a surface `h` is its opening `O = erode(dilate(h))`
//! ([`crate::cut::morphology::opening`]): planes and convex edges survive, concave corners and the foot of every
//! step between facets are filled with the ball's own sphere. The raster's grooves come on top, and their
//! slopes are modelled by the scallop lobe (as the verification measures them), so the model's NDF is
//! `NDF(O) ⊛ K_scallop`, its slopes taken as the milled surface's are: the mean over one stepover across the
//! passes (`base::surface::stepover_slopes`), so the model smooths the fillets as the measurement does. The opening is taken on the tile rasterised at about a 24th of the ball radius,
//! periodic, so a round costs a fraction of a second instead of a simulation of the program. Where the
//! controller cuts arcs as chords, the slopes are measured on the cut along those chords instead
//! ([`crate::cut::chords`], DESIGN.md §4.3: each pass of the CL surface as chords, then eroded), which takes
//! a few percent of the variance along the passes; the reach is the opening's.

use crate::base::heightfield::Heightfield;
use crate::cut::chords::PassChords;
use crate::cut::tool::Shape;
use crate::stages::facets::{self, Tile};

/// Samples per ball radius of the model's grid (its pitch is the facet side over a whole number of
/// samples no coarser than `r / MODEL_SAMPLES_PER_RADIUS`).
pub const MODEL_SAMPLES_PER_RADIUS: f64 = 24.0;

/// The model's pitch for a tile and a ball, mm: the facet side split into whole samples of at most
/// `r / 24`, and never finer than the design's own pitch.
pub fn model_pitch_mm(tile: &Tile, tool: &Shape) -> f64 {
    let a = tile.config.facet_mm;
    let design = tile.heightfield.pitch_mm;
    let want = (tool.radius_mm() / MODEL_SAMPLES_PER_RADIUS).max(design);
    a / (a / want - 1e-9).ceil()
}

/// What the ball leaves of a tile: the opening (what it can reach) and, on a controller that cuts arcs as
/// chords, the cut along those chords; beside them the tile rasterised on the same grid.
pub struct AsMilled {
    /// The tile's facets rasterised on the model's grid (what the opening is taken of).
    pub design: Heightfield,
    /// The periodic opening of the tile by the ball.
    pub opened: Heightfield,
    /// The bit's centre on the chords of each pass of the CL surface ([`crate::cut::chords`]); `None` for a
    /// controller that follows arcs.
    pub chorded: Option<Heightfield>,
}

impl AsMilled {
    /// The surface the model measures: the chords' cut where there is one, else the opening.
    #[must_use]
    pub fn cut(&self) -> &Heightfield {
        self.chorded.as_ref().unwrap_or(&self.opened)
    }
}

/// The periodic opening of `tile` by `tool` on a grid of `pitch_mm` (which must divide the facet side), in
/// single precision ([`crate::cut::morphology::opening_f32`]: within a nanometre of the double-precision one, at
/// twice its speed; the model's slopes are differences over a stepover of tens of micrometres), and with
/// `chords` the cut along the chords of each pass.
pub fn as_milled(tile: &Tile, tool: &Shape, pitch_mm: f64, chords: Option<PassChords>) -> AsMilled {
    let mut cfg = tile.config;
    cfg.pitch_um = pitch_mm * 1000.0;
    let hf = facets::rasterise(&tile.arrangement, &tile.z_mm, &cfg);
    let (opened, chorded) =
        crate::cut::morphology::opening_f32_chorded(&hf.z_mm, hf.nx, hf.ny, hf.pitch_mm, tool, chords);
    AsMilled {
        chorded: chorded.map(|z_mm| hf.with_heights(z_mm)),
        opened: hf.with_heights(opened),
        design: hf,
    }
}

/// Fraction of the model's samples the ball cannot reach: the opening above the design by more than
/// [`crate::cut::morphology::REACH_TOLERANCE_UM`].
pub fn unreachable_fraction(milled: &AsMilled) -> f64 {
    let (design, opened) = (&milled.design, &milled.opened);
    let tol = crate::cut::morphology::REACH_TOLERANCE_UM * 1e-3;
    let n = design
        .z_mm
        .iter()
        .zip(&opened.z_mm)
        .filter(|(d, o)| **o > **d + tol)
        .count();
    n as f64 / design.z_mm.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cut::morphology::{opening, opening_f32, opening_periodic, REACH_TOLERANCE_UM};
    use crate::stages::brdf::Brdf;
    use crate::stages::ndf::{self, NdfConfig};

    #[test]
    fn the_opening_keeps_planes_and_fills_concave_corners_only() {
        let n = ndf::run(
            &NdfConfig {
                res: 64,
                ..Default::default()
            },
            &Brdf::parse("beckmann:alpha=0.2").unwrap(),
            None,
        )
        .unwrap();
        let cfg = facets::FacetsConfig {
            facets_x: 6,
            facets_y: 6,
            facet_mm: 1.0,
            pitch_um: 10.0,
            ..Default::default()
        };
        let tile = facets::run(&cfg, &n.target).unwrap();
        let tool = Shape::Ball { diameter_mm: 0.5 };
        let p = model_pitch_mm(&tile, &tool);
        assert!((p - 1.0 / 96.0).abs() < 1e-12, "{p}");
        let milled = as_milled(&tile, &tool, p, None);
        let o = &milled.opened;
        let mut c = tile.config;
        c.pitch_um = p * 1000.0;
        let d = facets::rasterise(&tile.arrangement, &tile.z_mm, &c);
        // an opening never cuts below the surface, and leaves facet centres (a ball fits on a plane) alone, to
        // the single-precision model's nanometre
        assert!(o.z_mm.iter().zip(&d.z_mm).all(|(o, d)| *o >= *d));
        let m = 96;
        for fy in 0..6 {
            for fx in 0..6 {
                let (i, j) = (fx * m + m / 2, fy * m + m / 2);
                assert!((o.at(i, j) - d.at(i, j)).abs() < 1e-6, "facet ({fx},{fy}) centre moved");
            }
        }
        let u = unreachable_fraction(&milled);
        assert!(u > 0.0 && u < 0.5, "{u}");
    }

    // The morphology's own accuracy on a real faceted tile (the machining layer's tests use no stage).
    /// A 4 × 4 tile of 1 mm facets for the target `spec`, rasterised at `pitch_um`.
    fn tile_4x4(spec: &str, pitch_um: f64) -> facets::Tile {
        let n = ndf::run(
            &ndf::NdfConfig {
                res: 64,
                ..Default::default()
            },
            &Brdf::parse(spec).unwrap(),
            None,
        )
        .unwrap();
        let cfg = facets::FacetsConfig {
            facets_x: 4,
            facets_y: 4,
            facet_mm: 1.0,
            pitch_um,
            ..Default::default()
        };
        facets::run(&cfg, &n.target).unwrap()
    }

    /// The single-precision opening is the double-precision one to within its rounding (relative heights,
    /// a few f32 steps of 0.12 nm at 1 mm), on a faceted tile with a millimetre of relief.
    #[test]
    fn the_single_precision_opening_is_the_double_one_to_a_nanometre() {
        let tile = tile_4x4("beckmann:alpha=0.3", 10.0);
        let hf = &tile.heightfield;
        let (lo, hi) = hf.range();
        assert!(hi - lo > 0.3, "relief {}", hi - lo);
        let tool = Shape::Ball { diameter_mm: 0.5 };
        for periodic in [true, false] {
            let full = opening(&hf.z_mm, hf.nx, hf.ny, hf.pitch_mm, periodic, &tool);
            let single = opening_f32(&hf.z_mm, hf.nx, hf.ny, hf.pitch_mm, periodic, &tool);
            let worst = full.iter().zip(&single).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst < 1e-6, "periodic {periodic}: {worst} mm apart");
        }
    }

    #[test]
    fn the_decimated_opening_stays_within_its_sampling_bound_of_the_full_one() {
        let tile = tile_4x4("beckmann:alpha=0.2", 5.0);
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
