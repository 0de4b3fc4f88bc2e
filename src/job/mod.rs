//! `JOB.toml`: every stage of the pipeline in one documented, versioned file, and the runner behind
//! `brdfmill run`.
//!
//! ```toml
//! version = 1
//! name = "GGX samples"                     # optional: without it the job is named after its target
//!
//! [target]
//! brdf = "ggx:alpha=0.3,material=aluminium"  # any BRDF spec (see docs/CLI.md)
//! base = "scallop"                           # the base lobe deconvolved: "scallop" (the finishing raster's
//!                                            # own lobe, computed from the bit and stepover), "none", or a spec
//! polish = "beckmann:alpha=0.05"             # optional: the material's own polish lobe (with base = "scallop"
//!                                            # it is convolved into the base; the milled NDF is blurred by it)
//!
//! [machine]
//! profile = "../machines/grbl-3018.toml"     # relative to this file
//!
//! [ndf]        # NdfConfig: res, max_angle_deg, iterations, tolerance, [ndf.half_angle]
//! [facets]     # FacetsConfig: facets_x, facets_y, facet_mm, pitch_um, seed, max_slope_deg, ... [facets.anneal]
//! [toolpath]   # ToolpathConfig: tool, rough_tool, stock, area_mm, scallop_um, angle_deg, strategy, ...
//! [simulate]   # pitch_um, arc_tolerance_um
//! [verify]     # VerifyConfig: incident_deg, prefilter_um, wavelength_um, coherence_sigma_um, wave_patch_mm, [verify.tolerances]
//! ```
//!
//! Unknown keys are refused with their line. Loading ([`Job::load`]) only parses the file, applies the
//! overrides and composes the stages' checked plans — each stage checks its own section once, and its
//! refusal names the job's key; it writes nothing. [`run`] sequences the stages and writes the artifacts.

use crate::cut::machine::Machine;
use crate::stages::brdf::Brdf;
use crate::stages::design::DesignConfig;
use crate::stages::facets::FacetsConfig;
use crate::stages::ndf::NdfConfig;
use crate::stages::simulate::SimulateConfig;
use crate::stages::svbrdf::{Labels, SvbrdfSection};
use crate::stages::toolpath::{ToolpathConfig, ToolpathPlan};
use crate::stages::verify::VerifyConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The job format version this build reads.
pub const VERSION: u32 = 1;

/// `[target]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSection {
    /// The target BRDF spec (empty when `highlight` is given instead).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub brdf: String,
    /// A drawn highlight (PNG, relative to the job file) as the target instead of a BRDF
    /// ([`crate::stages::brdf::highlight`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight: Option<String>,
    /// The angle of reflection at the ends of the highlight image's longer axis, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight_extent_deg: Option<f64>,
    /// The part's material with a `highlight` or a `surface` (a preset name, as in a BRDF spec's
    /// `material=`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
    /// A measured surface (an X3P scan, or a `.npy` heightfield in mm with `surface_pitch_um`; relative to
    /// the job file) whose NDF is the target ([`crate::stages::brdf::surface`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<String>,
    /// The sample pitch of a `.npy` `surface`, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_pitch_um: Option<f64>,
    /// σ of the Gaussian pre-filter of the `surface` before its slopes are taken, µm (default 0: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_filter_um: Option<f64>,
    /// How the `surface`'s NDF is estimated: `"geometric"` (its slopes' histogram, the default) or `"wave"`
    /// (the Kirchhoff BRDF at normal incidence, with `surface_wavelength_um` and `surface_sigma_um`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_method: Option<crate::stages::brdf::surface::Method>,
    /// The wavelength of the `"wave"` estimate, µm (default 0.55).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_wavelength_um: Option<f64>,
    /// The coherence σ of the `"wave"` estimate, µm (default 10, the seed's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_sigma_um: Option<f64>,
    /// `"scallop"`, `"none"` or a BRDF spec.
    #[serde(default = "default_base")]
    pub base: String,
    /// The material's own polish lobe (a BRDF spec), optional.
    #[serde(default)]
    pub polish: Option<String>,
    /// When `brdf` names a `merl:` file that does not exist, a BRDF spec to write that file from first (so
    /// an example can exercise the MERL reader without shipping 35 MB), optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub merl_from: Option<String>,
}

fn default_base() -> String {
    "scallop".into()
}

impl Default for TargetSection {
    /// No target (a job with `[svbrdf]` regions gives theirs), the scallop lobe as the base.
    fn default() -> Self {
        Self {
            brdf: String::new(),
            highlight: None,
            highlight_extent_deg: None,
            material: None,
            surface: None,
            surface_pitch_um: None,
            surface_filter_um: None,
            surface_method: None,
            surface_wavelength_um: None,
            surface_sigma_um: None,
            base: default_base(),
            polish: None,
            merl_from: None,
        }
    }
}

/// `[machine]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSection {
    /// Machine profile path, relative to the job file.
    pub profile: String,
}

/// `[simulate]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateSection {
    /// Stock grid pitch, µm.
    pub pitch_um: f64,
    /// Arc linearisation tolerance, µm. Absent: the chords the job's controller draws arcs with (GRBL's
    /// `$12`, [`crate::cut::machine::Limits::arc_chord_mm`]), or 0.1 µm for a controller that follows arcs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arc_tolerance_um: Option<f64>,
}

/// Arc linearisation of a simulation when neither the job nor the controller gives one, µm: well under
/// the one-sided simplification tolerance, so the arcs are cut as written.
pub const EXACT_ARC_TOLERANCE_UM: f64 = 0.1;

impl Default for SimulateSection {
    fn default() -> Self {
        Self {
            pitch_um: 5.0,
            arc_tolerance_um: None,
        }
    }
}

impl SimulateSection {
    /// The simulation of the program `plan` makes: its finishing ball (and every tool of the machine swept with
    /// its own shape), on this section's grid and arc tolerance, with the machine's limits and dialect.
    #[must_use]
    pub fn config(&self, plan: &ToolpathPlan) -> SimulateConfig {
        SimulateConfig {
            tool: crate::cut::tool::Shape::Ball {
                diameter_mm: plan.tool.diameter_mm(),
            },
            tools: crate::stages::simulate::tool_table(&plan.machine),
            pitch_um: self.pitch_um,
            arc_tolerance_um: self.arc_tolerance_um.unwrap_or_else(|| {
                plan.machine
                    .limits
                    .arc_chord_mm(plan.machine.dialect)
                    .map_or(EXACT_ARC_TOLERANCE_UM, |mm| mm * 1e3)
            }),
            machine: Some(plan.machine.clone()),
            ..Default::default()
        }
    }
}

/// A job file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Job {
    /// [`VERSION`].
    pub version: u32,
    /// A name for the report and the program's header; when the file gives none (or an empty one), loading
    /// names the job after its target ([`Job::load`]), so a `--set` of the target renames it too.
    #[serde(default)]
    pub name: String,
    /// The target (with `[svbrdf]`, only its `base` and `polish`: the regions give the targets).
    #[serde(default)]
    pub target: TargetSection,
    /// The machine.
    pub machine: MachineSection,
    /// NDF stage.
    #[serde(default)]
    pub ndf: NdfConfig,
    /// Facets stage.
    #[serde(default)]
    pub facets: FacetsConfig,
    /// The design loop around the facets stage.
    #[serde(default)]
    pub design: DesignConfig,
    /// Toolpath stage.
    #[serde(default)]
    pub toolpath: ToolpathConfig,
    /// Simulation.
    #[serde(default)]
    pub simulate: SimulateSection,
    /// Verification.
    #[serde(default)]
    pub verify: VerifyConfig,
    /// A spatially varying target: a label image and a target per label colour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub svbrdf: Option<SvbrdfSection>,
}

/// A job that cannot run, or a stage that failed.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// The job file is wrong: the message names the key and the reason.
    #[error("{path}: {reason}")]
    Invalid {
        /// The job file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A `--set SECTION.KEY=VALUE` override is wrong: the message names the option as typed and the reason.
    #[error("--set {option}: {reason}")]
    Override {
        /// The override as the user typed it.
        option: String,
        /// What is wrong.
        reason: String,
    },
    /// A stage failed. Its error is in the message and not chained as a source, so that a reader of the
    /// whole chain (`{:#}`) sees it once.
    #[error("{stage}: {error}")]
    Stage {
        /// Which stage.
        stage: &'static str,
        /// Its error.
        error: StageError,
    },
    /// An output could not be written.
    #[error(transparent)]
    Write(#[from] crate::base::io::WriteError),
}

/// The error of a stage, kept in [`JobError::Stage`].
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// A target or base BRDF.
    #[error(transparent)]
    Brdf(#[from] crate::stages::brdf::BrdfError),
    /// The NDF stage.
    #[error(transparent)]
    Ndf(#[from] crate::stages::ndf::NdfError),
    /// The design loop.
    #[error(transparent)]
    Design(#[from] crate::stages::design::DesignError),
    /// Composing a spatially varying part.
    #[error(transparent)]
    Svbrdf(#[from] crate::stages::svbrdf::SvbrdfError),
    /// The toolpath stage.
    #[error(transparent)]
    Toolpath(#[from] crate::stages::toolpath::ToolpathError),
    /// The simulation.
    #[error(transparent)]
    Simulate(#[from] crate::stages::simulate::SimulateError),
    /// The verification.
    #[error(transparent)]
    Verify(#[from] crate::stages::verify::VerifyError),
    /// An input the run prepares (a MERL file written from `target.merl_from`, a scan's figures).
    #[error("{0}")]
    Input(String),
    /// An artifact that could not be serialised.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

pub use targets::{MerlFrom, RegionTarget};

/// A job checked and ready to run: the parsed job and the stages' plans composed from it.
pub struct Ready {
    /// The job.
    pub job: Job,
    /// The job file's folder.
    pub dir: PathBuf,
    /// The targets: the job's one target (named `""`) or, with `[svbrdf]`, each region's in the order of
    /// `[[svbrdf.region]]`.
    pub targets: Vec<RegionTarget>,
    /// With `[svbrdf]`: the label image, read and checked against the regions.
    pub labels: Option<Labels>,
    /// The machine.
    pub machine: Machine,
    /// Path of the machine profile.
    pub machine_path: PathBuf,
    /// The toolpath stage's plan: the tools, the stepover, the feed and the strategy, checked.
    pub toolpath: ToolpathPlan,
    /// Where the steepest facet (`facets.max_slope_deg`) came from: `"job"` or the finishing tool.
    pub slope_cap_from: String,
    /// A MERL file the run writes first (`target.merl_from` naming a file that does not exist); until then
    /// the target is the model it is written from.
    pub merl: Option<MerlFrom>,
}

impl Ready {
    /// The target (with `[svbrdf]`, the first region's).
    #[must_use]
    pub fn target(&self) -> &Brdf {
        &self.targets[0].target
    }
}

impl Job {
    /// The toolpath stage's configuration: `[toolpath]`, with the job's `name` in the program's header
    /// unless `toolpath.job` names it.
    pub fn toolpath_config(&self) -> ToolpathConfig {
        let mut t = self.toolpath.clone();
        if t.job == ToolpathConfig::default().job {
            t.job = self.name.clone();
        }
        t
    }

    /// The job as TOML (`job.toml` in the output folder): reading it back composes the same job.
    pub fn to_toml(&self) -> Result<String, StageError> {
        let fail = |e: String| StageError::Input(format!("the job cannot be written as TOML: {e}"));
        // through JSON, where a derived seed above TOML's largest integer (2⁶³ − 1) becomes the text the job
        // format reads seeds from (`base::de::seed`), and an absent option (null) is left out
        fn fit(v: serde_json::Value) -> Option<serde_json::Value> {
            use serde_json::Value;
            match v {
                Value::Null => None,
                Value::Number(n) if n.as_u64().is_some_and(|u| u > i64::MAX as u64) => {
                    Some(Value::String(n.to_string()))
                }
                Value::Array(a) => Some(Value::Array(a.into_iter().filter_map(fit).collect())),
                Value::Object(o) => Some(Value::Object(
                    o.into_iter().filter_map(|(k, v)| fit(v).map(|v| (k, v))).collect(),
                )),
                other => Some(other),
            }
        }
        let json = serde_json::to_value(self).map_err(|e| fail(e.to_string()))?;
        let value = toml::Value::try_from(fit(json).unwrap_or_default()).map_err(|e| fail(e.to_string()))?;
        toml::to_string(&value).map_err(|e| fail(e.to_string()))
    }

    /// Read a job file written by [`Job::to_toml`] (an output folder's `job.toml`), its paths read from
    /// `dir`, the folder of the job file it was written from.
    pub fn load_in(path: &Path, dir: &Path) -> Result<Ready, JobError> {
        let (job, given) = Job::parse(path, &[])?;
        job.compose(dir.to_path_buf(), given)
            .map_err(|reason| JobError::Invalid {
                path: path.display().to_string(),
                reason,
            })
    }

    /// Read a job file and compose the stages' plans: everything that can be checked before work starts.
    pub fn load(path: &Path) -> Result<Ready, JobError> {
        Job::load_with(path, &[])
    }

    /// [`Job::load`] with `section.key=value` overrides applied to the file first (the value is TOML: a
    /// number, `true`, `"text"` or `[1, 2]`; a bare word is taken as a string). Each override must name a key
    /// of the job's format, so a typo is refused like one in the file.
    pub fn load_with(path: &Path, overrides: &[String]) -> Result<Ready, JobError> {
        let invalid = |reason: String| JobError::Invalid {
            path: path.display().to_string(),
            reason,
        };
        let (job, given) = Job::parse(path, overrides)?;
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        job.compose(dir, given)
            .map_err(|reason| invalid(with_overrides_named(reason, overrides)))
    }

    /// The job file with the overrides applied, its version checked, and which of the facets' budget keys it
    /// gives itself (the others are derived from the finishing tool). An error is the file's (with its line)
    /// or the override's that brought it in ([`JobError::Override`]).
    fn parse(path: &Path, overrides: &[String]) -> Result<(Job, Given), JobError> {
        let invalid = |reason: String| JobError::Invalid {
            path: path.display().to_string(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| invalid(format!("cannot read the job file: {e}")))?;
        let file: toml::Value = toml::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        // the file alone, then after each override in turn: which one brought an error in
        let mut stages = vec![file.clone()];
        let mut raw = file;
        for o in overrides {
            apply_override(&mut raw, o).map_err(|reason| JobError::Override {
                option: o.clone(),
                reason,
            })?;
            stages.push(raw.clone());
        }
        match raw.get("version").and_then(|v| v.as_integer()) {
            Some(v) if v == VERSION as i64 => {}
            Some(v) => {
                return Err(invalid(format!(
                    "`version` = {v}: this build reads job files of version {VERSION}"
                )))
            }
            None => return Err(invalid(format!("missing `version` (expected version = {VERSION})"))),
        }
        let facets_key = |k: &str| raw.get("facets").and_then(|f| f.get(k)).is_some();
        let given = Given {
            slope_cap: facets_key("max_slope_deg"),
            relief: facets_key("max_relief_mm"),
        };
        let job: Job = if overrides.is_empty() {
            // from the text, so an error names its line and column
            toml::from_str(&text).map_err(|e: toml::de::Error| invalid(e.to_string()))?
        } else {
            raw.try_into()
                .map_err(|e: toml::de::Error| match override_at_fault(&stages, overrides) {
                    Some((k, reason)) => JobError::Override {
                        option: overrides[k].clone(),
                        reason,
                    },
                    // the file's own error: from its text, with the line
                    None => invalid(toml::from_str::<Job>(&text).err().unwrap_or(e).to_string()),
                })?
        };
        Ok((job, given))
    }

    /// Compose the stages' plans: the targets, the machine, the toolpath plan, the facets' budgets derived
    /// from its finishing tool, then each remaining section's own check. A refusal names the job's key.
    fn compose(mut self, dir: PathBuf, given: Given) -> Result<Ready, String> {
        if self.name.trim().is_empty() {
            self.name = targets::derived_name(&self.target, self.svbrdf.as_ref());
        }
        crate::cut::machine::program_text("name", &self.name).map_err(|e| e.to_string())?;
        let (targets, merl) = match &self.svbrdf {
            Some(sv) => (targets::region_targets(&self.target, sv, &dir)?, None),
            None => {
                let (single, merl) = targets::single_target(&self.target, &dir)?;
                (vec![single], merl)
            }
        };
        if !matches!(self.target.base.as_str(), "scallop" | "none") {
            Brdf::parse(&resolve_spec(&self.target.base, &dir)).map_err(|e| format!("`target.base`: {e}"))?;
        }
        if let Some(p) = &self.target.polish {
            Brdf::parse(&resolve_spec(p, &dir)).map_err(|e| format!("`target.polish`: {e}"))?;
        }
        let (machine_path, machine) =
            Machine::find(&self.machine.profile, &dir).map_err(|e| format!("`machine.profile`: {e}"))?;
        let toolpath = self
            .toolpath_config()
            .check(&machine, self.facets.pitch_um * 1e-3)
            .map_err(|e| keyed::<ToolpathConfig>("toolpath", &e.to_string()))?;
        self.ndf
            .validate()
            .map_err(|e| keyed::<NdfConfig>("ndf", &e.to_string()))?;
        let slope_cap_from = self.derive_budgets(&toolpath.tool, &machine, given);
        self.design
            .validate()
            .map_err(|e| keyed::<DesignConfig>("design", &e.to_string()))?;
        self.facets
            .validate()
            .map_err(|e| keyed::<FacetsConfig>("facets", &e.to_string()))?;
        let tool = &toolpath.tool;
        if tool.diameter_mm() > self.facets.facet_mm + 1e-9 {
            return Err(format!(
                "impossible combination: `toolpath.tool` `{}` is {} mm across, larger than a facet (`facets.facet_mm` = {} mm); the bit could not cut one facet's plane",
                tool.id, tool.diameter_mm(), self.facets.facet_mm
            ));
        }
        self.simulate
            .config(&toolpath)
            .check_area(self.toolpath.area_mm)
            .map_err(|e| keyed::<SimulateSection>("simulate", &e.to_string()))?;
        self.verify
            .validate()
            .map_err(|e| keyed::<VerifyConfig>("verify", &e.to_string()))?;
        let labels = match &self.svbrdf {
            Some(sv) => Some(targets::read_labels(&self, sv, &targets, &dir)?),
            None => None,
        };
        Ok(Ready {
            job: self,
            dir,
            targets,
            labels,
            machine,
            machine_path,
            toolpath,
            slope_cap_from,
            merl,
        })
    }

    /// The facets' relief budget and steepest facet from the finishing tool, where the job does not give them
    /// (DESIGN.md §4.4); says where the steepest facet came from.
    fn derive_budgets(&mut self, tool: &crate::cut::machine::Tool, machine: &Machine, given: Given) -> String {
        if !given.relief {
            self.facets.max_relief_mm = tool_relief_budget(tool, machine);
        }
        if given.slope_cap {
            return "job (`facets.max_slope_deg`)".to_string();
        }
        let budget = if self.facets.max_relief_mm > 0.0 {
            self.facets.max_relief_mm
        } else {
            tool_relief_budget(tool, machine)
        };
        let (deg, why) = tool_slope_cap(tool, budget, self.facets.facet_mm, self.ndf.max_angle_deg);
        self.facets.max_slope_deg = deg;
        why
    }
}

/// Which of the facets' budget keys the job gives itself.
#[derive(Clone, Copy)]
struct Given {
    slope_cap: bool,
    relief: bool,
}

/// A stage's refusal in the job's words: each `` `key` `` (or `` `key.sub` ``) of the section's configuration
/// `C` that the message names becomes `` `section.key` `` (`` `section.key.sub` ``).
fn keyed<C: Serialize + Default>(section: &str, message: &str) -> String {
    let keys: Vec<String> = match toml::Value::try_from(C::default()) {
        Ok(toml::Value::Table(t)) => t.keys().cloned().collect(),
        _ => vec![],
    };
    let mut out = message.to_string();
    for k in keys {
        out = out
            .replace(&format!("`{k}`"), &format!("`{section}.{k}`"))
            .replace(&format!("`{k}."), &format!("`{section}.{k}."));
    }
    out
}

/// Margin kept between a tile's relief and the finishing tool's flute length, fraction of the flutes.
pub const FLUTE_MARGIN: f64 = 0.1;

/// The relief budget from the finishing tool and the machine, mm: the flutes less [`FLUTE_MARGIN`], never
/// more than the machine's Z travel less its clearance height (DESIGN.md §4.4).
pub fn tool_relief_budget(tool: &crate::cut::machine::Tool, machine: &Machine) -> f64 {
    let flutes = tool.flute_length_mm * (1.0 - FLUTE_MARGIN);
    flutes.min(machine.travel.z_mm - machine.program.clearance_z())
}

/// The steepest facet the finishing ball can cut within a relief budget, degrees, and why (DESIGN.md §4.4).
/// A ball cuts any slope below 90° with its side, so its geometry alone sets no limit short of the equator;
/// what limits a facet is its own height: a square facet of side `a` with slopes `(p, q)` rises
/// `a(|p| + |q|)` corner to corner, at most `√2·a·tan θ`, and no facet may be taller than the relief the
/// flutes can cut, so `tan θ ≤ B/(√2·a)`. Never steeper than the NDF grid reaches (`ndf.max_angle_deg`).
pub fn tool_slope_cap(tool: &crate::cut::machine::Tool, budget_mm: f64, facet_mm: f64, grid_deg: f64) -> (f64, String) {
    let deg = (budget_mm / (std::f64::consts::SQRT_2 * facet_mm)).atan().to_degrees();
    if deg <= grid_deg {
        (
            deg,
            format!(
                "the tool: a {facet_mm} mm facet at most {budget_mm:.3} mm tall corner to corner (the relief budget: `{}`'s {} mm flutes less {:.0}%), atan({budget_mm:.3}/(√2·{facet_mm})) = {deg:.1}°",
                tool.id,
                tool.flute_length_mm,
                FLUTE_MARGIN * 100.0,
            ),
        )
    } else {
        (
            grid_deg,
            format!(
                "the NDF grid (`ndf.max_angle_deg` = {grid_deg}°; `{}`'s flutes would allow {deg:.1}°)",
                tool.id
            ),
        )
    }
}

/// Which override brought in the error the job has once every override is applied, and that error;
/// `None` when it is the file's own. `stages` is the file alone, then the file after each override in turn
/// (the last one does not read as a job). The override is the last one whose key is where the error is
/// (the key itself, a table it replaced, or an unknown key it made up); failing that, when the file alone
/// reads, the override after the last stage that reads.
fn override_at_fault(stages: &[toml::Value], overrides: &[String]) -> Option<(usize, String)> {
    let error = |v: &toml::Value| v.clone().try_into::<Job>().err().map(|e| e.to_string());
    let last = error(stages.last()?)?;
    let at = error_key(&last);
    let keyed = overrides.iter().rposition(|o| {
        let key = o.split_once('=').map_or(o.as_str(), |(k, _)| k).trim();
        let key: String = key.split('.').map(str::trim).collect::<Vec<_>>().join(".");
        key == at.key
            || at.key.starts_with(&format!("{key}."))
            || (at.unknown && key.starts_with(&format!("{}.", at.key)))
    });
    if let Some(k) = keyed {
        return Some((k, one_line(&last)));
    }
    let errors: Vec<Option<String>> = stages.iter().map(error).collect();
    errors[0].as_ref()?;
    let k = errors.iter().rposition(Option::is_none)?;
    Some((k, one_line(errors[k + 1].as_ref()?)))
}

/// Where a `toml` error (read from a value, so without a line) is: the dotted key it names and whether that
/// key is unknown (made up, so an override of a key below it made it).
struct ErrorKey {
    key: String,
    unknown: bool,
}

fn error_key(message: &str) -> ErrorKey {
    let table = message
        .rsplit_once("\nin `")
        .and_then(|(_, rest)| rest.split_once('`'))
        .map(|(k, _)| k.to_string());
    let unknown = message
        .strip_prefix("unknown field `")
        .and_then(|rest| rest.split_once('`'))
        .map(|(k, _)| k.to_string());
    let key = match (table, &unknown) {
        (Some(t), Some(u)) => format!("{t}.{u}"),
        (Some(t), None) => t,
        (None, Some(u)) => u.clone(),
        (None, None) => String::new(),
    };
    ErrorKey {
        key,
        unknown: unknown.is_some(),
    }
}

/// A message of the `toml` reader on one line (it puts the key path on a line of its own).
fn one_line(message: &str) -> String {
    message.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A refusal that names a key an override set says so: `(`key` from `--set key=value`)`.
fn with_overrides_named(reason: String, overrides: &[String]) -> String {
    let named: Vec<String> = overrides
        .iter()
        .filter_map(|o| {
            let key = o.split_once('=')?.0.trim();
            reason
                .contains(&format!("`{key}`"))
                .then(|| format!("`{key}` from `--set {o}`"))
        })
        .collect();
    if named.is_empty() {
        reason
    } else {
        format!("{reason} ({})", named.join("; "))
    }
}

/// Set `section.key=value` (dotted path, TOML value) in a parsed job.
fn apply_override(raw: &mut toml::Value, o: &str) -> Result<(), String> {
    let (key, value) = o.split_once('=').ok_or("expected SECTION.KEY=VALUE")?;
    let path: Vec<&str> = key.trim().split('.').map(str::trim).collect();
    if path.iter().any(|p| p.is_empty()) {
        return Err(format!("`{key}` is not a dotted key"));
    }
    let value = value.trim();
    let parsed: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value.to_string()));
    let mut node = raw;
    for part in &path[..path.len() - 1] {
        let table = node
            .as_table_mut()
            .ok_or_else(|| format!("`{part}` is not a section"))?;
        node = table
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    }
    let table = node
        .as_table_mut()
        .ok_or_else(|| format!("`{key}` is not inside a section"))?;
    table.insert(path[path.len() - 1].to_string(), parsed);
    Ok(())
}

/// Paths in `merl:`, `rgl:` and `csv:` specs are relative to the job file.
pub(crate) fn resolve_spec(spec: &str, dir: &Path) -> String {
    for kind in ["merl:", "rgl:", "csv:", "highlight:", "surface:"] {
        if let Some(rest) = spec.strip_prefix(kind) {
            let (path, tail) = rest
                .split_once(',')
                .map(|(a, b)| (a, format!(",{b}")))
                .unwrap_or((rest, String::new()));
            let p = Path::new(path.trim());
            let full = if p.is_absolute() { p.to_path_buf() } else { dir.join(p) };
            return format!("{kind}{}{tail}", full.display());
        }
    }
    spec.to_string()
}

mod artifacts;
pub mod compare;
pub mod export;
mod outcome;
mod runner;
mod scan_target;
mod setup;
mod stages;
mod summary;
mod targets;

pub use outcome::{Outcome, Progress, Stage, RUN_STATE};
pub use runner::run;

#[cfg(test)]
mod tests {
    use super::*;

    /// `target.merl_from` has the run write the missing file into its output folder, never beside the job
    /// (loading writes nothing), and what it wrote reads back as the model it came from; a file that is beside
    /// the job is read instead; it refuses a target that is not a `merl:` file.
    #[test]
    fn a_missing_merl_file_is_written_from_its_spec_into_the_output_folder() {
        let dir = tempfile::tempdir().unwrap();
        let out = tempfile::tempdir().unwrap();
        let job = |brdf: &str| {
            let p = dir.path().join("job.toml");
            std::fs::write(
                &p,
                format!(
                    "version = 1\nname = \"m\"\n[target]\nbrdf = \"{brdf}\"\nmerl_from = \"beckmann:alpha=0.3\"\n[machine]\nprofile = \"grbl-3018\"\n[toolpath]\ntool = \"ball05\"\n"
                ),
            )
            .unwrap();
            p
        };
        let ready = Job::load(&job("merl:data/m.binary")).unwrap();
        let merl = ready.merl.as_ref().expect("the run is to write the file");
        let (target, spec, file, _) = merl.write(out.path(), &ready.targets[0].spec).unwrap();
        assert_eq!(file, out.path().join("m.binary"));
        assert!(file.exists());
        assert_eq!(spec, format!("merl:{}", file.display()));
        assert!(!dir.path().join("data").exists(), "nothing beside the job");
        let model = Brdf::parse("beckmann:alpha=0.3").unwrap();
        let (wi, wo) = (
            crate::base::geometry::spherical(0.4, 0.3),
            crate::base::geometry::spherical(0.3, 2.9),
        );
        let (a, b) = (target.eval(&wi, &wo)[1], model.eval(&wi, &wo)[1]);
        assert!((a / b - 1.0).abs() < 0.05, "{a} against {b}");
        // a file beside the job is read, not written
        std::fs::create_dir(dir.path().join("data")).unwrap();
        std::fs::copy(&file, dir.path().join("data/m.binary")).unwrap();
        let again = Job::load(&job("merl:data/m.binary")).unwrap();
        assert!(again.merl.is_none());
        let e = Job::load(&job("beckmann:alpha=0.2"))
            .err()
            .expect("refused")
            .to_string();
        assert!(
            e.contains("target.merl_from") && e.contains("only a `merl:` target"),
            "{e}"
        );
    }

    #[test]
    fn shipped_profiles_are_found_by_name_and_a_wrong_name_lists_them() {
        let dir = tempfile::tempdir().unwrap();
        let (p, m) = Machine::find("grbl-3018", dir.path()).unwrap();
        assert!(p.display().to_string().contains("shipped"));
        let on_disk = Machine::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/machines/grbl-3018.toml"
        )))
        .unwrap();
        assert_eq!(m, on_disk);
        let e = Machine::find("grbl-9999", dir.path()).unwrap_err().to_string();
        assert!(e.contains("grbl-router-6040") && e.contains("linuxcnc-mill"), "{e}");
    }
}
