//! Machine profiles: `machines/*.toml`, versioned (`version = 1`). Every length in mm, every feed in
//! mm/min, accelerations in mm/s², spindle speeds in rev/min, times in s — the unit is in each field's name.
//!
//! A profile names the controller dialect, the travel, the feed/rapid/acceleration limits, the spindle range,
//! the program conventions (safe z, spindle dwell) and the tools the machine has, each with cutting data for
//! aluminium and for wax/plastics. Unknown keys are refused (with the line), so a typo never silently falls
//! back to a default.

pub use crate::cut::accuracy::Accuracy;
use crate::cut::tool::Shape;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The profile format version this build reads.
pub const VERSION: u32 = 1;

pub use crate::gcode::moves::Coolant;
pub use crate::gcode::Dialect;

/// Machine travel, mm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Travel {
    /// X travel, mm.
    pub x_mm: f64,
    /// Y travel, mm.
    pub y_mm: f64,
    /// Z travel, mm.
    pub z_mm: f64,
}

/// Motion limits.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Highest cutting feed in X/Y, mm/min.
    pub max_feed_mm_min: f64,
    /// Highest feed in Z, mm/min.
    pub max_feed_z_mm_min: f64,
    /// Rapid (G0) rate in X/Y, mm/min.
    pub rapid_mm_min: f64,
    /// Rapid rate in Z, mm/min.
    pub rapid_z_mm_min: f64,
    /// Acceleration in X/Y, mm/s².
    pub acceleration_mm_s2: f64,
    /// Acceleration in Z, mm/s².
    pub acceleration_z_mm_s2: f64,
    /// Cornering tolerance: GRBL's junction deviation `$11`, LinuxCNC's `G64 P`, mm.
    pub path_tolerance_mm: f64,
    /// The smallest step the machine resolves, mm (one motor step, or the DRO's last digit): coordinates
    /// are written rounded to it (Z rounded up, so the path never goes below the CL surface) with as many
    /// decimals as it needs. Default 0.0001 mm (4 decimals).
    #[serde(default = "default_resolution_mm")]
    pub resolution_mm: f64,
    /// Motion blocks per second the controller's planner sustains; a program faster than that starves the
    /// planner and the machine slows down (GRBL 1.1 on an AVR: about 300). Absent: 300 for GRBL, no limit for
    /// LinuxCNC (its trajectory planner runs at the servo rate and blends within `G64 P`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_blocks_s: Option<f64>,
    /// The largest sagitta of the chords the controller draws an arc with, mm: GRBL cuts every `G2`/`G3`
    /// into straight segments whose endpoints lie on the arc and whose sagitta is at most its `$12` (0.002
    /// mm by default). Absent: 0.002 for GRBL; LinuxCNC's planner follows the arc itself. The simulation of
    /// a job cuts the arcs as these chords: it is the path the machine follows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arc_tolerance_mm: Option<f64>,
    /// The axes have backlash (lead screws, no compensation): finishing is then one-way climb by default, so
    /// every pass is cut with the same axis load direction. Default false.
    #[serde(default)]
    pub backlash: bool,
}

fn default_resolution_mm() -> f64 {
    1e-4
}

impl Limits {
    /// The block-rate limit in force, blocks/s (None: unlimited).
    pub fn block_rate_limit(&self, dialect: Dialect) -> Option<f64> {
        match (self.max_blocks_s, dialect) {
            (Some(r), _) => Some(r),
            (None, Dialect::Grbl) => Some(300.0),
            (None, Dialect::Linuxcnc) => None,
        }
    }

    /// The sagitta of the chords the controller draws arcs with, mm (None: it follows arcs exactly):
    /// [`Self::arc_tolerance_mm`], else GRBL's default `$12`.
    pub fn arc_chord_mm(&self, dialect: Dialect) -> Option<f64> {
        match (self.arc_tolerance_mm, dialect) {
            (Some(t), _) => Some(t),
            (None, Dialect::Grbl) => Some(GRBL_ARC_TOLERANCE_MM),
            (None, Dialect::Linuxcnc) => None,
        }
    }
}

/// GRBL 1.1's default arc tolerance `$12`, mm (`DEFAULT_ARC_TOLERANCE` in its `defaults.h`).
pub const GRBL_ARC_TOLERANCE_MM: f64 = 0.002;

/// Spindle speed range.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spindle {
    /// Lowest speed, rev/min.
    pub min_rpm: f64,
    /// Highest speed, rev/min.
    pub max_rpm: f64,
}

/// Program conventions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProgramDefaults {
    /// Height above the stock top (z = 0) for rapid moves, mm.
    pub safe_z_mm: f64,
    /// Dwell after the spindle starts, s.
    pub spindle_dwell_s: f64,
    /// Height the program retracts to at its end and for a tool change, mm above the stock top; default
    /// `safe_z_mm`. Must be ≥ `safe_z_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance_z_mm: Option<f64>,
    /// Where the tool is parked (at the clearance height) at the end and for a tool change, work X/Y mm;
    /// default: no park move (the tool stays over the last point).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub park_xy_mm: Option<[f64; 2]>,
    /// Coolant while cutting: `off` (default), `mist` (`M7`) or `flood` (`M8`).
    #[serde(default = "coolant_off")]
    pub coolant: Coolant,
    /// LinuxCNC: the machine-coordinate Z every tool change retracts to first (`G53 G0 Z…`), mm; default 0,
    /// the top of travel on a machine homed there (LinuxCNC homes before it runs a program). GRBL programs
    /// change no tool (one program per tool).
    #[serde(default)]
    pub tool_change_machine_z_mm: f64,
    /// The tool a job roughs with when it names none (`toolpath.rough_tool`): used when it is larger than
    /// the finishing tool and the relief is deeper than the finishing tool's depth of cut. Absent: the
    /// finishing tool roughs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roughing_tool: Option<String>,
}

fn coolant_off() -> Coolant {
    Coolant::Off
}

impl ProgramDefaults {
    /// The end and tool-change retract height, mm.
    pub fn clearance_z(&self) -> f64 {
        self.clearance_z_mm.unwrap_or(self.safe_z_mm)
    }
}

/// Cutting data for one stock material.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CuttingData {
    /// Cutting feed, mm/min.
    pub feed_mm_min: f64,
    /// Plunge feed, mm/min.
    pub plunge_mm_min: f64,
    /// Spindle speed, rev/min.
    pub spindle_rpm: f64,
    /// Largest depth of cut per pass, mm.
    pub max_depth_of_cut_mm: f64,
}

/// A tool in the machine's library: its geometry (the crate's one tool model, [`Shape`]), reach, number and
/// cutting data. In the profile the geometry is written as `kind`, `diameter_mm` and `corner_radius_mm`
/// (bull-nose only; a ball's may be given and must then be its radius), checked when the profile loads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ToolRecord", into = "ToolRecord")]
pub struct Tool {
    /// Identifier used on the command line (`--tool ID`).
    pub id: String,
    /// Geometry.
    pub shape: Shape,
    /// Flute (cutting) length, mm: the deepest the tool can reach below the stock top.
    pub flute_length_mm: f64,
    /// Tool number in the tool changer / table (the `T` and `H` words of a LinuxCNC tool change).
    pub number: u32,
    /// Number of flutes (for the chip load `feed / (rpm · flutes)` in the header); default 2.
    pub flutes: u32,
    /// Steepest entry into material, degrees from the horizontal: every entry ramps down along its pass at
    /// this angle at most (90: a straight plunge at the plunge feed is allowed). Default
    /// [`default_ramp_deg`] by kind.
    pub max_ramp_deg: f64,
    /// Cutting data in aluminium: the profile's (it may spell the key `aluminum`), or when it gives none the
    /// table's for this tool on this machine ([`crate::cut::feeds::derive`]).
    pub aluminium: CuttingData,
    /// Cutting data in machining wax and plastics, the profile's or the table's.
    pub wax: CuttingData,
    /// Which stocks' data the profile gave (`[aluminium, wax]`); the others come from the table.
    pub given: [bool; 2],
}

/// A tool as written in a profile.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolRecord {
    id: String,
    kind: String,
    diameter_mm: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    corner_radius_mm: Option<f64>,
    flute_length_mm: f64,
    #[serde(default)]
    number: u32,
    #[serde(default = "two")]
    flutes: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    max_ramp_deg: Option<f64>,
    #[serde(default, alias = "aluminum", skip_serializing_if = "Option::is_none")]
    aluminium: Option<CuttingData>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    wax: Option<CuttingData>,
}

fn two() -> u32 {
    2
}

/// The entry ramp angle a tool gets when its profile gives none, degrees: 3° for a flat or bull-nose end
/// mill (its centre barely cuts, so it must not plunge; 2–5° is the usual range), 10° for a ball-nose, whose
/// centre cuts but at zero surface speed.
pub fn default_ramp_deg(shape: Shape) -> f64 {
    match shape.normalized() {
        Shape::Ball { .. } => 10.0,
        Shape::Flat { .. } | Shape::Bull { .. } => 3.0,
    }
}

impl TryFrom<ToolRecord> for Tool {
    type Error = String;
    fn try_from(r: ToolRecord) -> Result<Tool, String> {
        let shape = Shape::from_parts(&r.kind, r.diameter_mm, r.corner_radius_mm)
            .map_err(|e| format!("tool `{}`: {e}", r.id))?;
        Ok(Tool {
            id: r.id,
            shape,
            flute_length_mm: r.flute_length_mm,
            number: r.number,
            flutes: r.flutes,
            max_ramp_deg: r.max_ramp_deg.unwrap_or_else(|| default_ramp_deg(shape)),
            // the table's data need the machine: filled in by `Machine::parse`
            aluminium: r.aluminium.unwrap_or_default(),
            wax: r.wax.unwrap_or_default(),
            given: [r.aluminium.is_some(), r.wax.is_some()],
        })
    }
}

impl From<Tool> for ToolRecord {
    fn from(t: Tool) -> ToolRecord {
        ToolRecord {
            id: t.id,
            kind: t.shape.kind().into(),
            diameter_mm: t.shape.diameter_mm(),
            corner_radius_mm: matches!(t.shape, Shape::Bull { .. }).then(|| t.shape.corner_radius_mm()),
            flute_length_mm: t.flute_length_mm,
            number: t.number,
            flutes: t.flutes,
            max_ramp_deg: Some(t.max_ramp_deg),
            aluminium: t.given[0].then_some(t.aluminium),
            wax: t.given[1].then_some(t.wax),
        }
    }
}

/// Stock material (selects the cutting data).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Stock {
    /// Aluminium (`"aluminum"`, the US spelling, is read as the same).
    #[serde(alias = "aluminum")]
    Aluminium,
    /// Machining wax and plastics.
    Wax,
}

impl Stock {
    /// The material's name for people: "aluminium", "machining wax".
    pub fn name(self) -> &'static str {
        match self {
            Stock::Aluminium => "aluminium",
            Stock::Wax => "machining wax",
        }
    }
}

impl Tool {
    /// Chip load at `feed_mm_min` and `spindle_rpm`, µm per tooth: `1000·F / (n·z)`.
    pub fn chip_load_um(&self, feed_mm_min: f64, spindle_rpm: f64) -> f64 {
        1000.0 * feed_mm_min / (spindle_rpm * self.flutes.max(1) as f64)
    }

    /// Surface speed at the full diameter at `spindle_rpm`, m/min: `π·D·n / 1000`.
    pub fn surface_speed_m_min(&self, spindle_rpm: f64) -> f64 {
        std::f64::consts::PI * self.diameter_mm() * spindle_rpm / 1000.0
    }

    /// The profile gave this stock's cutting data (else they come from the table, `cut::feeds`).
    pub fn data_given(&self, stock: Stock) -> bool {
        self.given[stock as usize]
    }

    /// A tool of this shape with the table's data on a 24,000 rpm spindle (for tests).
    #[cfg(test)]
    pub(crate) fn for_test(id: &str, shape: Shape) -> Tool {
        let lim = crate::cut::feeds::Limits {
            rpm: [0.0, 24_000.0],
            max_feed_mm_min: 5000.0,
            runout_um: 0.0,
            coolant_on: true,
        };
        let d = shape.diameter_mm();
        Tool {
            id: id.into(),
            shape,
            flute_length_mm: 3.0 * d,
            number: 1,
            flutes: 2,
            max_ramp_deg: default_ramp_deg(shape),
            aluminium: crate::cut::feeds::derive(d, 2, Stock::Aluminium, &lim),
            wax: crate::cut::feeds::derive(d, 2, Stock::Wax, &lim),
            given: [false; 2],
        }
    }

    /// Cutting data for a stock.
    pub fn cutting(&self, stock: Stock) -> &CuttingData {
        match stock {
            Stock::Aluminium => &self.aluminium,
            Stock::Wax => &self.wax,
        }
    }

    /// Radius, mm.
    pub fn radius_mm(&self) -> f64 {
        self.shape.radius_mm()
    }

    /// Diameter, mm.
    pub fn diameter_mm(&self) -> f64 {
        self.shape.diameter_mm()
    }
}

/// A machine profile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Machine {
    /// Profile format version ([`VERSION`]).
    pub version: u32,
    /// Human-readable name.
    pub name: String,
    /// Controller dialect.
    pub dialect: Dialect,
    /// Travel.
    pub travel: Travel,
    /// Motion limits.
    pub limits: Limits,
    /// Spindle range.
    pub spindle: Spindle,
    /// Program conventions.
    pub program: ProgramDefaults,
    /// What the machine does to a program: backlash, runout, the step grid (`[accuracy]`; absent: a perfect
    /// machine is assumed, and the report says so).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<Accuracy>,
    /// Tools.
    pub tools: Vec<Tool>,
}

/// What is wrong with a machine profile's text.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// Not TOML, or not this format (the message has the line and column).
    #[error("{0}")]
    Syntax(String),
    /// A profile of another format version.
    #[error("`version` = {found}: this build reads machine profiles of version {VERSION}")]
    Version {
        /// The version the profile declares.
        found: i64,
    },
    /// No `version` key.
    #[error("missing `version` (expected version = {VERSION})")]
    NoVersion,
    /// A field out of range.
    #[error("`{field}` must be {expected}, got {value}")]
    Field {
        /// The field, as a TOML path (`tools[1] (ball1).flute_length_mm`).
        field: String,
        /// What it must be.
        expected: String,
        /// What it is.
        value: String,
    },
    /// Two tools with one id.
    #[error("tool id `{0}` is used twice")]
    DuplicateTool(String),
    /// The tool asked for is not in the profile.
    #[error("machine `{machine}` has no tool `{id}`; its tools: {tools}")]
    NoTool {
        /// The profile's name.
        machine: String,
        /// The id asked for.
        id: String,
        /// The ids there are.
        tools: String,
    },
}

/// A machine profile that cannot be used: the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum MachineError {
    /// The file could not be read.
    #[error(transparent)]
    Read(#[from] crate::base::io::ReadError),
    /// The file's content is wrong (the message is the field's own, so it is not also a `source`: a
    /// chain printed with `{:#}` gave it twice).
    #[error("{path}: {error}")]
    Profile {
        /// The profile file.
        path: String,
        /// What is wrong, naming the field.
        error: ProfileError,
    },
    /// Neither a file nor the name of a shipped profile.
    #[error("{path}: no such file, and not a shipped profile ({names})")]
    Unknown {
        /// The path tried.
        path: String,
        /// The shipped profiles' names.
        names: String,
    },
}

/// The machine profiles shipped in `machines/`, by name (compiled in, so they are found from any folder).
pub const SHIPPED_PROFILES: [(&str, &str); 3] = [
    ("grbl-3018", include_str!("../../machines/grbl-3018.toml")),
    ("grbl-router-6040", include_str!("../../machines/grbl-router-6040.toml")),
    ("linuxcnc-mill", include_str!("../../machines/linuxcnc-mill.toml")),
];

fn field(field: impl Into<String>, expected: &str, value: impl std::fmt::Display) -> ProfileError {
    ProfileError::Field {
        field: field.into(),
        expected: expected.into(),
        value: value.to_string(),
    }
}

/// Refuse text that reaches a program's comments and holds a control character: a newline would start new
/// G-code blocks (issue 13's `name = "evil\nG0 Z-40"`), a carriage return or a NUL confuses controllers.
/// Refused rather than cleaned, because such a name is a typo or an attack and the user should see which
/// field. Comment delimiters `( ) ;` are legitimate in a name ("router (GRBL 1.1)") and are made safe where
/// comments are written (`crate::gcode::emit::comment_text`: `(` → `[`, `)` → `]`, `;` → `,`).
pub fn program_text(name: &str, s: &str) -> Result<(), ProfileError> {
    if let Some(c) = s.chars().find(|c| c.is_control()) {
        return Err(field(
            name,
            "text without control characters (it is written into the program's comments)",
            format!("{s:?} (holds {c:?})"),
        ));
    }
    if s.chars().count() > 60 {
        return Err(field(name, "at most 60 characters", s.chars().count()));
    }
    Ok(())
}

impl Machine {
    /// Read and validate a profile.
    pub fn load(path: &Path) -> Result<Self, MachineError> {
        let text = crate::base::io::read_to_string(path)?;
        Self::parse(&text).map_err(|error| MachineError::Profile {
            path: path.display().to_string(),
            error,
        })
    }

    /// A profile by path (relative to `dir`) or, when no such file exists, by the name of a shipped profile
    /// (`grbl-3018`, `grbl-router-6040`, `linuxcnc-mill`, with or without `.toml`). Returns where it came
    /// from (`machines/NAME.toml (shipped)` for a shipped one) and the profile.
    pub fn find(profile: &str, dir: &Path) -> Result<(std::path::PathBuf, Self), MachineError> {
        let path = dir.join(profile);
        if path.exists() {
            return Self::load(&path).map(|m| (path, m));
        }
        let name = profile.trim_end_matches(".toml");
        let name = name.strip_prefix("machines/").unwrap_or(name);
        match SHIPPED_PROFILES.iter().find(|(n, _)| *n == name) {
            Some((n, text)) => {
                let shown = format!("machines/{n}.toml (shipped)");
                Self::parse(text)
                    .map(|m| (shown.clone().into(), m))
                    .map_err(|error| MachineError::Profile { path: shown, error })
            }
            None => Err(MachineError::Unknown {
                path: path.display().to_string(),
                names: SHIPPED_PROFILES.map(|(n, _)| n).join(", "),
            }),
        }
    }

    /// Parse and validate profile text.
    pub fn parse(text: &str) -> Result<Self, ProfileError> {
        // Check the version first so an old or new profile gets that message, not a field error.
        let raw: toml::Value = toml::from_str(text).map_err(|e| ProfileError::Syntax(e.to_string()))?;
        match raw.get("version").and_then(|v| v.as_integer()) {
            Some(v) if v == VERSION as i64 => {}
            Some(found) => return Err(ProfileError::Version { found }),
            None => return Err(ProfileError::NoVersion),
        }
        let mut m: Machine = toml::from_str(text).map_err(|e| ProfileError::Syntax(e.to_string()))?;
        m.validate()?;
        m.fill_cutting_data();
        Ok(m)
    }

    fn validate(&self) -> Result<(), ProfileError> {
        let pos = |name: &str, v: f64| -> Result<(), ProfileError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(field(name, "a positive number", v))
            }
        };
        pos("travel.x_mm", self.travel.x_mm)?;
        pos("travel.y_mm", self.travel.y_mm)?;
        pos("travel.z_mm", self.travel.z_mm)?;
        let l = &self.limits;
        pos("limits.max_feed_mm_min", l.max_feed_mm_min)?;
        pos("limits.max_feed_z_mm_min", l.max_feed_z_mm_min)?;
        pos("limits.rapid_mm_min", l.rapid_mm_min)?;
        pos("limits.rapid_z_mm_min", l.rapid_z_mm_min)?;
        pos("limits.acceleration_mm_s2", l.acceleration_mm_s2)?;
        pos("limits.acceleration_z_mm_s2", l.acceleration_z_mm_s2)?;
        pos("limits.path_tolerance_mm", l.path_tolerance_mm)?;
        pos("spindle.max_rpm", self.spindle.max_rpm)?;
        if !(self.spindle.min_rpm >= 0.0 && self.spindle.min_rpm <= self.spindle.max_rpm) {
            return Err(field(
                "spindle.min_rpm",
                "in [0, spindle.max_rpm]",
                self.spindle.min_rpm,
            ));
        }
        pos("program.safe_z_mm", self.program.safe_z_mm)?;
        pos("limits.resolution_mm", l.resolution_mm)?;
        if l.resolution_mm > 0.01 {
            return Err(field("limits.resolution_mm", "at most 0.01 mm", l.resolution_mm));
        }
        if let Some(a) = &self.accuracy {
            a.check().map_err(|(k, e, v)| field(k, &e, v))?;
        }
        if let Some(r) = l.max_blocks_s {
            pos("limits.max_blocks_s", r)?;
        }
        if let Some(t) = l.arc_tolerance_mm {
            pos("limits.arc_tolerance_mm", t)?;
            if t > 0.1 {
                return Err(field("limits.arc_tolerance_mm", "at most 0.1 mm", t));
            }
        }
        let clear = self.program.clearance_z();
        if !(clear.is_finite() && clear >= self.program.safe_z_mm && clear <= self.travel.z_mm) {
            return Err(field(
                "program.clearance_z_mm",
                "finite, ≥ program.safe_z_mm and ≤ travel.z_mm",
                clear,
            ));
        }
        if let Some([x, y]) = self.program.park_xy_mm {
            if !(x.is_finite() && y.is_finite() && x.abs() <= self.travel.x_mm && y.abs() <= self.travel.y_mm) {
                return Err(field(
                    "program.park_xy_mm",
                    "finite and within the travel",
                    format!("[{x}, {y}]"),
                ));
            }
        }
        program_text("name", &self.name)?;
        if !(0.0..=600.0).contains(&self.program.spindle_dwell_s) {
            return Err(field(
                "program.spindle_dwell_s",
                "in [0, 600] s (a spindle is up to speed in seconds)",
                self.program.spindle_dwell_s,
            ));
        }
        if self.tools.is_empty() {
            return Err(field("tools", "at least one `[[tools]]` entry", "none"));
        }
        if let Some(id) = &self.program.roughing_tool {
            if !self.tools.iter().any(|t| &t.id == id) {
                let ids: Vec<&str> = self.tools.iter().map(|t| t.id.as_str()).collect();
                return Err(field(
                    "program.roughing_tool",
                    &format!("one of the profile's tools ({})", ids.join(", ")),
                    id,
                ));
            }
        }
        for (k, t) in self.tools.iter().enumerate() {
            let f = |name: &str| format!("tools[{k}] (`{}`).{name}", t.id);
            if self.tools[..k].iter().any(|o| o.id == t.id) {
                return Err(ProfileError::DuplicateTool(t.id.clone()));
            }
            program_text(&format!("tools[{k}].id"), &t.id)?;
            t.shape
                .validate()
                .map_err(|e| field(f(&e.field), &e.expected, &e.value))?;
            // a bit wider than the machine's travel is a typo (and would ask the raster for an endless grid)
            let widest = self.travel.x_mm.min(self.travel.y_mm);
            if t.shape.diameter_mm() > widest {
                return Err(field(
                    f("diameter_mm"),
                    &format!("at most the smaller travel, {widest} mm"),
                    t.shape.diameter_mm(),
                ));
            }
            if self.dialect == Dialect::Linuxcnc && t.number == 0 {
                return Err(field(f("number"), "≥ 1 (LinuxCNC's `T0 M6` unloads the spindle)", 0));
            }
            if !(t.max_ramp_deg > 0.0 && t.max_ramp_deg <= 90.0) {
                return Err(field(f("max_ramp_deg"), "an angle in (0, 90] degrees", t.max_ramp_deg));
            }
            if t.flutes == 0 || t.flutes > 16 {
                return Err(field(f("flutes"), "in 1..=16", t.flutes));
            }
            pos(&f("flute_length_mm"), t.flute_length_mm)?;
            let given = [("aluminium", &t.aluminium), ("wax", &t.wax)].into_iter().zip(t.given);
            for (name, c) in given.filter(|(_, g)| *g).map(|(c, _)| c) {
                pos(&f(&format!("{name}.feed_mm_min")), c.feed_mm_min)?;
                pos(&f(&format!("{name}.plunge_mm_min")), c.plunge_mm_min)?;
                pos(&f(&format!("{name}.spindle_rpm")), c.spindle_rpm)?;
                pos(&f(&format!("{name}.max_depth_of_cut_mm")), c.max_depth_of_cut_mm)?;
            }
        }
        Ok(())
    }

    /// Every tool's cutting data the profile does not give, from the table for this machine (after
    /// [`Machine::validate`], which checks the figures the table is limited by).
    fn fill_cutting_data(&mut self) {
        let lim = crate::cut::feeds::Limits::of(self);
        for t in &mut self.tools {
            let d = t.diameter_mm();
            for (given, stock, data) in [
                (t.given[0], Stock::Aluminium, &mut t.aluminium),
                (t.given[1], Stock::Wax, &mut t.wax),
            ] {
                if !given {
                    *data = crate::cut::feeds::derive(d, t.flutes, stock, &lim);
                }
            }
        }
    }

    /// The machine's errors (perfect when the profile declares none).
    pub fn accuracy(&self) -> Accuracy {
        self.accuracy.unwrap_or_default()
    }

    /// X or Y has backlash: `[accuracy] backlash_um` above 0, or the older `limits.backlash = true`.
    pub fn has_backlash(&self) -> bool {
        self.limits.backlash || self.accuracy().has_backlash_xy()
    }

    /// The grid coordinates are written on, mm: one motor step when all three axes have the same
    /// `accuracy.steps_per_mm` (so GRBL's rounding to steps moves nothing), else `limits.resolution_mm`.
    pub fn write_resolution_mm(&self) -> f64 {
        self.accuracy().common_step_mm().unwrap_or(self.limits.resolution_mm)
    }

    /// The block-rate limit of this machine, blocks/s (None: unlimited).
    pub fn block_rate_limit(&self) -> Option<f64> {
        self.limits.block_rate_limit(self.dialect)
    }

    /// The tool with this id; the error lists the ones there are.
    pub fn tool(&self, id: &str) -> Result<&Tool, ProfileError> {
        self.tools.iter().find(|t| t.id == id).ok_or_else(|| {
            let ids: Vec<&str> = self.tools.iter().map(|t| t.id.as_str()).collect();
            ProfileError::NoTool {
                machine: self.name.clone(),
                id: id.to_string(),
                tools: ids.join(", "),
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_us_spelling_of_aluminium_reads_as_the_same_stock_and_key() {
        #[derive(Deserialize)]
        struct S {
            stock: Stock,
        }
        let us: S = toml::from_str("stock = \"aluminum\"").unwrap();
        let uk: S = toml::from_str("stock = \"aluminium\"").unwrap();
        assert_eq!(us.stock, uk.stock);
        let text = include_str!("../../machines/grbl-3018.toml");
        let given = |key: &str| {
            text.replacen(
                "flute_length_mm = 3.0\n",
                &format!(
                    "flute_length_mm = 3.0\n{key} = {{ feed_mm_min = 150.0, plunge_mm_min = 50.0, spindle_rpm = 10000.0, \
                     max_depth_of_cut_mm = 0.1 }}\n"
                ),
                1,
            )
        };
        let uk = Machine::parse(&given("aluminium")).unwrap();
        let us = Machine::parse(&given("aluminum")).unwrap();
        assert_eq!(us, uk);
        assert!(uk.tools[0].data_given(Stock::Aluminium) && uk.tools[0].aluminium.feed_mm_min == 150.0);
        // the other tools' data come from the table
        assert!(!uk.tools[1].data_given(Stock::Aluminium) && uk.tools[1].aluminium.feed_mm_min > 0.0);
    }

    fn shipped() -> Vec<std::path::PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("machines");
        let mut v: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        v.sort();
        v
    }

    #[test]
    fn shipped_profiles_load() {
        let all = shipped();
        assert!(all.len() >= 3, "{all:?}");
        let mut dialects = vec![];
        for p in all {
            let m = Machine::load(&p).unwrap_or_else(|e| panic!("{e}"));
            assert!(
                m.tools.iter().any(|t| matches!(t.shape, Shape::Ball { .. })),
                "{}: no ball-nose",
                p.display()
            );
            dialects.push(m.dialect);
        }
        assert!(dialects.contains(&Dialect::Grbl) && dialects.contains(&Dialect::Linuxcnc));
    }

    #[test]
    fn bad_profiles_name_the_field() {
        let good = std::fs::read_to_string(&shipped()[0]).unwrap();
        let e = Machine::parse(&good.replace("version = 1", "version = 2")).unwrap_err();
        assert!(matches!(e, ProfileError::Version { found: 2 }), "{e}");
        let e = Machine::parse(&good.replace("x_mm =", "x_mmm ="))
            .unwrap_err()
            .to_string();
        assert!(e.contains("x_mmm"), "{e}");
        let e = Machine::parse(&good.replacen("diameter_mm = ", "diameter_mm = -", 1))
            .unwrap_err()
            .to_string();
        assert!(e.contains("diameter_mm"), "{e}");
        let e = Machine::parse(&good.replacen("flute_length_mm = ", "flute_length_mm = -", 1)).unwrap_err();
        assert!(
            matches!(&e, ProfileError::Field { field, .. } if field.ends_with(".flute_length_mm")),
            "{e}"
        );
    }
}
