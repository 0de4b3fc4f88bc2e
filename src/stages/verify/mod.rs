//! Stage 6 (verify) — the loop closes: the target against the design tile and the simulated milled surface.
//!
//! What is compared with what (DESIGN.md §6): the reference is the target's *observed* half-angle
//! distribution `O` (before deconvolution). The design tile's NDF (its facet slopes) is convolved with the
//! whole base lobe `K` before the comparison; the milled surface's NDF already carries the tool marks, so it
//! is convolved only with the part of `K` that the simulation does not model (the material's own polish).
//!
//! - [`run`]: the stage's entry point, `run(&VerifyConfig, &VerifyInput) -> VerifyOutput`,
//! - `metrics`: the figures and their tolerances (`metrics.json`),
//! - `explain`: plain-word reasons for every failing figure,
//! - `render`: sphere previews and BRDF slices,
//! - `report`: the single-page offline HTML report.

pub(crate) mod explain;
pub(crate) mod highlight;
pub(crate) mod metrics;
pub mod milled;
pub mod regions;
pub(crate) mod render;
pub(crate) mod report;
mod run;

pub use metrics::{SurfaceMetrics, Tolerances};
pub use regions::{RegionMetrics, RegionsMetrics};
pub use run::{measure_cut, measure_shape, run, Gauge, VerifyConfig, VerifyError, VerifyInput, VerifyOutput};

use serde::{Deserialize, Serialize};

/// `metrics.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Format version.
    pub version: u32,
    /// The design tile (facet slopes ⊛ base lobe) against the target.
    pub design: SurfaceMetrics,
    /// The simulated milled surface (⊛ polish lobe) against the target.
    pub milled: SurfaceMetrics,
    /// The same program cut by a perfect machine (the figures before the machine's backlash, runout and step
    /// grid); equal to `milled` when the profile declares no error. Absent in files written before it.
    #[serde(default)]
    pub milled_ideal: Option<SurfaceMetrics>,
    /// The machine's errors the milled cut followed; absent: a perfect machine.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<crate::cut::accuracy::Accuracy>,
    /// What each declared error moves (see [`MachineEffect`]); empty when the machine declares at most one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub machine_effects: Vec<MachineEffect>,
    /// The milled surface meets every tolerance.
    pub pass: bool,
    /// The tolerances used.
    pub tolerances: Tolerances,
    /// What the reference is and which lobes were applied.
    pub reference: String,
    /// Findings that explain shortfalls (bit radius, concavity, discretisation), in plain words.
    pub notes: Vec<String>,
    /// The diffraction warning of the scallop period (`optics::wave::diffraction_warning`), if any.
    pub diffraction: Option<String>,
    /// How the milled surface was measured (absent in files written before it was recorded).
    #[serde(default)]
    pub measurement: Option<milled::Measurement>,
    /// The design loop's rounds, in order: each tile's as-milled model against the target.
    #[serde(default)]
    pub rounds: Vec<crate::stages::design::Round>,
    /// The candidate arrangements the loop chose its first round from (their uncorrected models).
    #[serde(default)]
    pub arrangements: Vec<crate::stages::design::Round>,
    /// With a `highlight` target: the correlation of the milled surface's highlight, rendered in the image's
    /// configuration, with the image (the same as `highlight.milled_corr`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight_corr: Option<f64>,
    /// With a `highlight` target: the image, its configuration and the correlations.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight: Option<HighlightMetrics>,
    /// Gloss, haze and distinctness of image of the target and of the milled surface
    /// ([`crate::stages::optics::gloss`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub appearance: Option<AppearanceMetrics>,
}

/// The target's and the milled surface's appearance in a lab's units (`metrics.json` `appearance`), not
/// checked against a tolerance: the NDF metrics judge the cut, these say what a glossmeter would read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AppearanceMetrics {
    /// How the figures are defined: the standard, the geometries and the receptors.
    pub method: String,
    /// The target BRDF's.
    pub target: crate::stages::optics::gloss::Appearance,
    /// The milled surface's (its geometric BRDF with the part's material).
    pub milled: crate::stages::optics::gloss::Appearance,
}

/// One machine error and the milled figures of a cut with it alone, or with all but it
/// (`metrics.json` `machine_effects`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MachineEffect {
    /// The error: `backlash`, `runout` or `steps`.
    pub error: String,
    /// It, in words with its figure.
    pub what: String,
    /// True: the cut has this error alone (a perfect machine otherwise); false: the cut has every declared
    /// error but this one, so its effect is the difference from `milled`.
    #[serde(default = "yes")]
    pub alone: bool,
    /// Slope variance ratios x, y of that cut.
    pub cov_ratio: [f64; 2],
    /// NDF relative L1 distance.
    pub ndf_l1: f64,
    /// NDF correlation.
    pub ndf_corr: f64,
}

fn yes() -> bool {
    true
}

/// A `highlight` target against what was designed and milled (`metrics.json` `highlight`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HighlightMetrics {
    /// The image file.
    pub image: String,
    /// Its size, pixels.
    pub size_px: [usize; 2],
    /// The angle of reflection at the ends of its longer axis, degrees.
    pub extent_deg: f64,
    /// The configuration the image and the renderings are in.
    pub configuration: String,
    /// The size both are compared at, pixels (the image box-averaged).
    pub compared_px: [usize; 2],
    /// Correlation of the milled surface's highlight (its NDF, the scallop and polish lobe included) with
    /// the image.
    pub milled_corr: f64,
    /// … of the design tile's (⊛ the base lobe).
    pub design_corr: f64,
    /// … of the target's observed distribution as the NDF grid holds it: the most any design could reach
    /// on this grid.
    pub grid_corr: f64,
    /// … of the NDF stage's deconvolved target blurred again by the base lobe (the scallop and polish lobe):
    /// the most any slopes could reach under that lobe, up to the deconvolution's own error.
    #[serde(default)]
    pub lobe_corr: f64,
}
