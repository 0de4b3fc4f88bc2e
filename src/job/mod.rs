//! `JOB.toml`: every stage of the pipeline in one documented, versioned file, and the runner behind
//! `brdfmill run`.
//!
//! ```toml
//! version = 1
//! name = "isotropic GGX, aluminium"
//!
//! [target]
//! brdf = "ggx:alpha=0.3,material=aluminium"  # any BRDF spec (see README)
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
//! Unknown keys are refused with their line; the machine profile, the tool and the combination of
//! parameters are checked before any work starts ([`Job::load`]).

use crate::cut::machine::Machine;
use crate::cut::tool::Shape;
use crate::stages::brdf::Brdf;
use crate::stages::design::DesignConfig;
use crate::stages::facets::FacetsConfig;
use crate::stages::ndf::NdfConfig;
use crate::stages::svbrdf::{Labels, SvbrdfSection};
use crate::stages::toolpath::ToolpathConfig;
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
    /// The part's material with a `highlight` (a preset name, as in a BRDF spec's `material=`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
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
    /// Arc linearisation tolerance, µm.
    pub arc_tolerance_um: f64,
}

impl Default for SimulateSection {
    fn default() -> Self {
        Self {
            pitch_um: 5.0,
            arc_tolerance_um: 0.1,
        }
    }
}

/// A job file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Job {
    /// [`VERSION`].
    pub version: u32,
    /// A name for the report.
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
    /// A stage failed.
    #[error("{stage}: {message}")]
    Stage {
        /// Which stage.
        stage: &'static str,
        /// Its error.
        message: String,
    },
    /// An output could not be written.
    #[error(transparent)]
    Write(#[from] crate::base::io::WriteError),
}

/// One region of a spatially varying target, ready to run.
#[derive(Clone, Debug)]
pub struct RegionTarget {
    /// Its name (files `ndf-NAME.json`, `tile-NAME.*`).
    pub name: String,
    /// Its label colour.
    pub color: [u8; 3],
    /// The target spec as resolved.
    pub spec: String,
    /// The target.
    pub target: Brdf,
}

/// A job checked and ready to run: the parsed inputs it needs.
pub struct Ready {
    /// The job.
    pub job: Job,
    /// The job file's folder.
    pub dir: PathBuf,
    /// The target BRDF (with `[svbrdf]`, the first region's).
    pub target: Brdf,
    /// With `[svbrdf]`: each region's target, in the order of `[[svbrdf.region]]`.
    pub regions: Vec<RegionTarget>,
    /// With `[svbrdf]`: the label image, read and checked against the regions.
    pub labels: Option<Labels>,
    /// The machine.
    pub machine: Machine,
    /// Path of the machine profile.
    pub machine_path: PathBuf,
    /// Where the steepest facet (`facets.max_slope_deg`) came from: `"job"` or the finishing tool.
    pub slope_cap_from: String,
    /// Inputs the load prepared (a MERL file written from `target.merl_from`), for the user to be told.
    pub prepared: Vec<String>,
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

    /// Read a job file and check everything that can be checked before work starts.
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
        let text = std::fs::read_to_string(path).map_err(|e| invalid(format!("cannot read the job file: {e}")))?;
        let mut raw: toml::Value = toml::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        for o in overrides {
            apply_override(&mut raw, o).map_err(|e| invalid(format!("--set {o}: {e}")))?;
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
        let cap_given = raw.get("facets").and_then(|f| f.get("max_slope_deg")).is_some();
        let relief_given = raw.get("facets").and_then(|f| f.get("max_relief_mm")).is_some();
        let mut job: Job = if overrides.is_empty() {
            // from the text, so an error names its line and column
            toml::from_str(&text).map_err(|e| invalid(e.to_string()))?
        } else {
            raw.try_into().map_err(|e: toml::de::Error| invalid(e.to_string()))?
        };
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let prepared: Vec<String> = make_missing_merl(&job.target, &dir)
            .map_err(|e| invalid(format!("`target.merl_from`: {e}")))?
            .into_iter()
            .collect();
        let regions = match &job.svbrdf {
            Some(sv) => region_targets(&job.target, sv, &dir).map_err(&invalid)?,
            None => vec![],
        };
        let target = match regions.first() {
            Some(r) => r.target.clone(),
            None => {
                let t = &job.target;
                let (key, spec) = target_spec(
                    "target",
                    (&t.brdf, &t.highlight, t.highlight_extent_deg, &t.material),
                    &dir,
                )
                .map_err(&invalid)?;
                Brdf::parse(&spec).map_err(|e| invalid(format!("`{key}`: {e}")))?
            }
        };
        if !matches!(job.target.base.as_str(), "scallop" | "none") {
            Brdf::parse(&resolve_spec(&job.target.base, &dir)).map_err(|e| invalid(format!("`target.base`: {e}")))?;
        }
        if let Some(p) = &job.target.polish {
            Brdf::parse(&resolve_spec(p, &dir)).map_err(|e| invalid(format!("`target.polish`: {e}")))?;
        }
        let (machine_path, machine) =
            load_profile(&job.machine.profile, &dir).map_err(|e| invalid(format!("`machine.profile`: {e}")))?;
        let tool = machine
            .tool(&job.toolpath.tool)
            .map_err(|e| invalid(format!("`toolpath.tool`: {e}")))?;
        if !matches!(tool.shape, Shape::Ball { .. }) {
            return Err(invalid(format!(
                "`toolpath.tool` = `{}` is {:?}: finishing needs a ball-nose",
                tool.id,
                tool.shape.kind()
            )));
        }
        job.ndf.validate().map_err(|e| invalid(e.to_string()))?;
        if !relief_given {
            job.facets.max_relief_mm = tool_relief_budget(tool, &machine);
        }
        let slope_cap_from = if cap_given {
            "job (`facets.max_slope_deg`)".to_string()
        } else {
            let budget = if job.facets.max_relief_mm > 0.0 {
                job.facets.max_relief_mm
            } else {
                tool_relief_budget(tool, &machine)
            };
            let (deg, why) = tool_slope_cap(tool, budget, job.facets.facet_mm, job.ndf.max_angle_deg);
            job.facets.max_slope_deg = deg;
            why
        };
        job.design.validate().map_err(|e| invalid(e.to_string()))?;
        job.facets.validate().map_err(|e| invalid(e.to_string()))?;
        if tool.diameter_mm() > job.facets.facet_mm + 1e-9 {
            return Err(invalid(format!(
                "impossible combination: `toolpath.tool` `{}` is {} mm across, larger than a facet (`facets.facet_mm` = {} mm); the bit could not cut one facet's plane",
                tool.id, tool.diameter_mm(), job.facets.facet_mm
            )));
        }
        let [ax, ay] = job.toolpath.area_mm;
        if ax > machine.travel.x_mm || ay > machine.travel.y_mm {
            return Err(invalid(format!(
                "impossible combination: `toolpath.area_mm` = [{ax}, {ay}] is larger than the machine's travel {}×{} mm ({})",
                machine.travel.x_mm,
                machine.travel.y_mm,
                machine_path.display()
            )));
        }
        if !(ax > 0.0 && ay > 0.0) {
            return Err(invalid(format!(
                "`toolpath.area_mm` must be positive, got [{ax}, {ay}]"
            )));
        }
        check_work(&job, tool.radius_mm()).map_err(invalid)?;
        // everything the toolpath stage checks without the tile, now rather than after the design
        crate::cut::machine::program_text("name", &job.name).map_err(|e| invalid(e.to_string()))?;
        crate::stages::toolpath::check_config(&job.toolpath_config(), &machine, job.facets.pitch_um * 1e-3)
            .map_err(|e| invalid(e.to_string()))?;
        job.verify.validate().map_err(|e| invalid(e.to_string()))?;
        let labels = match &job.svbrdf {
            Some(sv) => Some(read_labels(&job, sv, &regions, &dir).map_err(|e| invalid(e.to_string()))?),
            None => None,
        };
        Ok(Ready {
            job,
            dir,
            target,
            regions,
            labels,
            machine,
            machine_path,
            slope_cap_from,
            prepared,
        })
    }
}

/// The fields that name a target: a BRDF spec, or a highlight with its extent and material.
type TargetFields<'a> = (&'a String, &'a Option<String>, Option<f64>, &'a Option<String>);

/// A target's BRDF spec, from `SECTION.brdf` or from `SECTION.highlight` (with its extent and material), and
/// the key it came from. Exactly one of the two must be given; the highlight's keys only go with it.
fn target_spec(
    section: &str,
    (brdf, highlight, extent, material): TargetFields,
    dir: &Path,
) -> Result<(String, String), String> {
    match (highlight, brdf.trim().is_empty()) {
        (Some(_), false) => Err(format!("give `{section}.brdf` or `{section}.highlight`, not both")),
        (None, true) => Err(format!(
            "missing `{section}.brdf` (a BRDF spec) or `{section}.highlight` (a PNG)"
        )),
        (None, false) => {
            for (key, given) in [
                ("highlight_extent_deg", extent.is_some()),
                ("material", material.is_some()),
            ] {
                if given {
                    return Err(format!(
                        "`{section}.{key}` goes with `{section}.highlight`; with `{section}.brdf` give the material in the spec (`…,material=NAME`)"
                    ));
                }
            }
            Ok((format!("{section}.brdf"), resolve_spec(brdf, dir)))
        }
        (Some(path), true) => {
            let spec = crate::stages::brdf::highlight::spec(path, extent, material.as_deref())
                .map_err(|e| format!("`{section}.highlight`: {e}"))?;
            Ok((format!("{section}.highlight"), resolve_spec(&spec, dir)))
        }
    }
}

/// `[[svbrdf.region]]` → each region's target, with names and colours checked (valid, distinct). With
/// regions, `[target]` gives no target of its own (only `base` and `polish`).
fn region_targets(t: &TargetSection, sv: &SvbrdfSection, dir: &Path) -> Result<Vec<RegionTarget>, String> {
    if !t.brdf.trim().is_empty() || t.highlight.is_some() || t.material.is_some() || t.highlight_extent_deg.is_some() {
        return Err(
            "with `[svbrdf]` each `[[svbrdf.region]]` names its own target: leave `target.brdf`, `target.highlight` and their keys out (`[target]` keeps `base` and `polish`)".into(),
        );
    }
    if t.merl_from.is_some() {
        return Err("`target.merl_from` does not go with `[svbrdf]`".into());
    }
    if sv.region.len() < 2 {
        return Err(format!(
            "`[svbrdf]` needs at least two `[[svbrdf.region]]` (got {}); a single target goes in `[target]`",
            sv.region.len()
        ));
    }
    if sv.region.len() > crate::stages::svbrdf::MAX_REGIONS {
        return Err(format!(
            "`[svbrdf]` has {} regions; at most {}",
            sv.region.len(),
            crate::stages::svbrdf::MAX_REGIONS
        ));
    }
    let mut out: Vec<RegionTarget> = vec![];
    for (k, r) in sv.region.iter().enumerate() {
        let section = format!("svbrdf.region[{}]", k + 1);
        crate::stages::svbrdf::check_name(&r.name).map_err(|e| format!("`{section}.name`: {e}"))?;
        let color = crate::stages::svbrdf::parse_color(&r.color).map_err(|e| format!("`{section}.color`: {e}"))?;
        if let Some(o) = out.iter().find(|o| o.name == r.name) {
            return Err(format!("`{section}.name`: `{}` is already a region's name", o.name));
        }
        if let Some(o) = out.iter().find(|o| o.color == color) {
            return Err(format!(
                "`{section}.color`: {} is already region `{}`'s colour",
                crate::stages::svbrdf::hex(color),
                o.name
            ));
        }
        let (key, spec) = target_spec(
            &section,
            (&r.brdf, &r.highlight, r.highlight_extent_deg, &r.material),
            dir,
        )?;
        let target = Brdf::parse(&spec).map_err(|e| format!("`{key}`: {e}"))?;
        out.push(RegionTarget {
            name: r.name.clone(),
            color,
            spec,
            target,
        });
    }
    Ok(out)
}

/// Read the label image of `[svbrdf]` against its regions and the work area, and refuse a region too small
/// to hold one tile period.
fn read_labels(job: &Job, sv: &SvbrdfSection, regions: &[RegionTarget], dir: &Path) -> Result<Labels, String> {
    let f = &job.facets;
    let [ax, ay] = job.toolpath.area_mm;
    let pitch_mm = f.pitch_um * 1e-3;
    let cells = (ax / pitch_mm).round() * (ay / pitch_mm).round();
    if cells > crate::stages::svbrdf::MAX_PART_CELLS as f64 {
        return Err(format!(
            "`[svbrdf]`: the composed part would be {cells:.0} cells (`toolpath.area_mm` = [{ax}, {ay}] at `facets.pitch_um` = {}); at most {}",
            f.pitch_um,
            crate::stages::svbrdf::MAX_PART_CELLS
        ));
    }
    let path = dir.join(&sv.labels);
    let names: Vec<String> = regions.iter().map(|r| r.name.clone()).collect();
    let colors: Vec<[u8; 3]> = regions.iter().map(|r| r.color).collect();
    let labels =
        Labels::read(&path, &names, &colors, job.toolpath.area_mm).map_err(|e| format!("`svbrdf.labels`: {e}"))?;
    labels
        .check_period([f.facets_x as f64 * f.facet_mm, f.facets_y as f64 * f.facet_mm])
        .map_err(|e| format!("`svbrdf.region`: {e}"))?;
    Ok(labels)
}

/// `target.merl_from`: write the `merl:` file `target.brdf` names from that spec when the file is missing.
/// Returns what was written, if anything.
fn make_missing_merl(t: &TargetSection, dir: &Path) -> Result<Option<String>, String> {
    let Some(from) = &t.merl_from else {
        return Ok(None);
    };
    let spec = resolve_spec(&t.brdf, dir);
    let Some(rest) = spec.strip_prefix("merl:") else {
        return Err(format!(
            "only a `merl:` target can be written from a spec; `target.brdf` is `{}`",
            t.brdf
        ));
    };
    let path = PathBuf::from(rest.split(',').next().unwrap_or(rest).trim());
    if path.exists() {
        return Ok(None);
    }
    let source = Brdf::parse(from).map_err(|e| e.to_string())?;
    if matches!(source.model, crate::stages::brdf::Model::Merl(_)) {
        return Err(format!(
            "`{from}` is itself a MERL file: name an analytic or measured model"
        ));
    }
    crate::stages::brdf::Merl::from_fn(|wi, wo| source.eval(wi, wo))
        .write(&path)
        .map_err(|e| e.to_string())?;
    Ok(Some(format!(
        "wrote {} from `{from}` (`target.merl_from`)",
        path.display()
    )))
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

/// A machine profile by path (relative to the job's folder) or by a shipped profile's name
/// ([`Machine::find`]).
fn load_profile(profile: &str, dir: &Path) -> Result<(PathBuf, Machine), String> {
    Machine::find(profile, dir).map_err(|e| e.to_string())
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

/// The most finishing passes a job may ask for (a 1 µm scallop with a 0.5 mm ball is 45 µm apart: 2,700
/// passes over 120 mm).
pub const MAX_PASSES: f64 = 200_000.0;

/// The most simulated stock cells (8 bytes each: 4 GB).
pub const MAX_SIM_CELLS: f64 = 5e8;

/// Bound the work of the toolpath and simulate stages before anything runs: the stepover (from the scallop
/// or given) and the pass count it implies, the simulation's cell count and arc tolerance. The message
/// names the key and gives the estimate.
fn check_work(job: &Job, r_mm: f64) -> Result<(), String> {
    let t = &job.toolpath;
    let [ax, ay] = t.area_mm;
    let stepover = if t.stepover_mm != 0.0 {
        if !(t.stepover_mm.is_finite() && t.stepover_mm > 0.0) {
            return Err(format!(
                "`toolpath.stepover_mm` must be a positive length (or 0: from the scallop), got {}",
                t.stepover_mm
            ));
        }
        t.stepover_mm
    } else {
        let h = t.scallop_um * 1e-3;
        if !(h.is_finite() && h > 0.0 && h < r_mm) {
            return Err(format!(
                "`toolpath.scallop_um` must be in (0, {}) µm for the {} mm ball, got {}",
                r_mm * 1e3,
                2.0 * r_mm,
                t.scallop_um
            ));
        }
        crate::stages::toolpath::raster::stepover_for_scallop(r_mm, h)
    };
    let passes = ax.hypot(ay) / stepover;
    if passes > MAX_PASSES {
        return Err(format!(
            "the stepover {stepover:.3e} mm (`toolpath.scallop_um` = {} / `toolpath.stepover_mm` = {}) needs about {passes:.3e} passes over {ax}×{ay} mm, more than {MAX_PASSES:e}",
            t.scallop_um, t.stepover_mm
        ));
    }
    let p = job.simulate.pitch_um;
    if !(p.is_finite() && p > 0.0) {
        return Err(format!("`simulate.pitch_um` must be positive, got {p}"));
    }
    let margin_mm = 2.0 * r_mm + 1.0;
    let cells = ((ax + margin_mm) / (p * 1e-3)) * ((ay + margin_mm) / (p * 1e-3));
    if cells > MAX_SIM_CELLS {
        return Err(format!(
            "`simulate.pitch_um` = {p} over {ax}×{ay} mm is about {cells:.3e} stock cells, more than {MAX_SIM_CELLS:e} (8 bytes each)"
        ));
    }
    let a = job.simulate.arc_tolerance_um;
    if !(a.is_finite() && (1e-3..=100.0).contains(&a)) {
        return Err(format!(
            "`simulate.arc_tolerance_um` must be in [0.001, 100] µm, got {a}"
        ));
    }
    Ok(())
}

/// Paths in `merl:`, `rgl:` and `csv:` specs are relative to the job file.
pub(crate) fn resolve_spec(spec: &str, dir: &Path) -> String {
    for kind in ["merl:", "rgl:", "csv:", "highlight:"] {
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

mod regions;
mod run;
mod summary;

pub use run::{run, Outcome, Progress, Stage};

#[cfg(test)]
mod tests {
    use super::*;

    /// `target.merl_from` writes the missing file once, and what it wrote reads back as the model it came
    /// from; it refuses a target that is not a `merl:` file.
    #[test]
    fn a_missing_merl_file_is_written_from_its_spec_once() {
        let dir = tempfile::tempdir().unwrap();
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
        let ready = Job::load(&job("merl:m.binary")).unwrap();
        assert_eq!(ready.prepared.len(), 1, "{:?}", ready.prepared);
        let written = std::fs::metadata(dir.path().join("m.binary"))
            .unwrap()
            .modified()
            .unwrap();
        let again = Job::load(&job("merl:m.binary")).unwrap();
        assert!(again.prepared.is_empty());
        assert_eq!(
            std::fs::metadata(dir.path().join("m.binary"))
                .unwrap()
                .modified()
                .unwrap(),
            written
        );
        let model = Brdf::parse("beckmann:alpha=0.3").unwrap();
        let (wi, wo) = (
            crate::base::geometry::spherical(0.4, 0.3),
            crate::base::geometry::spherical(0.3, 2.9),
        );
        let (a, b) = (again.target.eval(&wi, &wo)[1], model.eval(&wi, &wo)[1]);
        assert!((a / b - 1.0).abs() < 0.05, "{a} against {b}");
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
        let (p, m) = load_profile("grbl-3018", dir.path()).unwrap();
        assert!(p.display().to_string().contains("shipped"));
        let on_disk = Machine::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/machines/grbl-3018.toml"
        )))
        .unwrap();
        assert_eq!(m, on_disk);
        let e = load_profile("grbl-9999", dir.path()).unwrap_err();
        assert!(e.contains("grbl-router-6040") && e.contains("linuxcnc-mill"), "{e}");
    }
}
