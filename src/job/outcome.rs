//! The run's vocabulary: the stages in order, the progress events a run reports, what it produced, and the
//! name of its state file.

use super::Ready;
use crate::stages::design::Round;
use crate::stages::toolpath;
use crate::stages::verify::{self, Metrics};
use std::path::PathBuf;

/// Pipeline stages, in order (for progress reporting and `--until`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    /// BRDF → NDF.
    Ndf,
    /// NDF → tile.
    Facets,
    /// Tile → G-code.
    Toolpath,
    /// G-code → milled surface.
    Simulate,
    /// Metrics, figures, report.
    Verify,
}

impl Stage {
    /// Display name.
    pub fn name(&self) -> &'static str {
        match self {
            Stage::Ndf => "ndf",
            Stage::Facets => "facets",
            Stage::Toolpath => "toolpath",
            Stage::Simulate => "simulate",
            Stage::Verify => "verify",
        }
    }

    /// The stage of a name (`ndf`, `facets`, `toolpath`, `simulate`, `verify`).
    pub fn parse(s: &str) -> Option<Stage> {
        [
            Stage::Ndf,
            Stage::Facets,
            Stage::Toolpath,
            Stage::Simulate,
            Stage::Verify,
        ]
        .into_iter()
        .find(|st| st.name() == s)
    }
}

/// The name of the run-state file in the output folder: `"state": "running"` from the first stage until the
/// last one asked for has written its artifacts, then `"complete"`. A run that was interrupted (Ctrl-C, a
/// crash, a full disk) leaves `"running"` behind, so its folder never passes for a finished run.
pub const RUN_STATE: &str = "run.json";

/// What `run` reports as it goes.
pub enum Progress<'a> {
    /// A stage starts.
    Started(Stage),
    /// A stage has written its artifacts.
    Finished(Stage),
    /// The design loop modelled a candidate arrangement (before the first round).
    Arrangement(&'a Round),
    /// The design loop finished a round.
    Round(&'a Round),
    /// A job with `[svbrdf]`: the design rounds that follow are this region's.
    Region(&'a str),
    /// An input the run prepared before the first stage (a MERL file written from `target.merl_from`).
    Prepared(&'a str),
}

/// What the run produced.
pub struct Outcome {
    /// The metrics (`None` when the run stopped before verification, or for a job with `[svbrdf]`).
    pub metrics: Option<Metrics>,
    /// A job with `[svbrdf]`: the regions' metrics (`None` before verification).
    pub regions: Option<verify::RegionsMetrics>,
    /// The program's numbers (`None` when the run stopped before the toolpath).
    pub program: Option<toolpath::Summary>,
    /// The tile's relief (highest minus lowest point), mm (`None` before the facets).
    pub relief_mm: Option<f64>,
    /// The setup sheet's rows (the report's "To mill this"), empty before verification.
    pub setup: Vec<(String, String)>,
    /// Files written, in order.
    pub artifacts: Vec<PathBuf>,
    /// Bytes written in all.
    pub bytes_written: u64,
    /// Per stage, seconds.
    pub timings: Vec<(Stage, f64)>,
    /// The report's path (`None` before verification).
    pub report: Option<PathBuf>,
    /// The design loop's rounds and the one chosen (index), empty before the facets.
    pub rounds: (Vec<Round>, usize),
    /// The candidate arrangements' first rounds (the best became round 1), empty before the facets.
    pub arrangements: Vec<Round>,
    /// The steepest facet, degrees, and where it came from.
    pub slope_cap: (f64, String),
    /// What the run noticed about its input that the user should know (e.g. target mass beyond the NDF
    /// grid), whatever the verdict.
    pub warnings: Vec<String>,
}

/// An outcome with nothing in it yet.
pub(super) fn empty_outcome(ready: &Ready) -> Outcome {
    Outcome {
        metrics: None,
        regions: None,
        program: None,
        relief_mm: None,
        setup: vec![],
        artifacts: vec![],
        bytes_written: 0,
        timings: vec![],
        report: None,
        rounds: (vec![], 0),
        arrangements: vec![],
        slope_cap: (ready.job.facets.max_slope_deg, ready.slope_cap_from.clone()),
        // what the plan raised or warns of on this machine (a tolerance below its step, zigzag with backlash)
        warnings: ready.toolpath.notes.clone(),
    }
}
