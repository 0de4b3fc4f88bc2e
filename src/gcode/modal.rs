//! The modal state a controller keeps between blocks: units, distance modes, plane, motion mode, feed,
//! spindle and coolant. One type for every reader of G-code in the crate: the streamer re-sends it on a
//! resume, the simulator reads programs against it, the virtual controller runs on it.

use serde::{Deserialize, Serialize};

/// mm per inch.
pub const MM_PER_INCH: f64 = 25.4;

/// Length units (G20/G21).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// G21, millimetres (GRBL's default).
    Mm,
    /// G20, inches.
    Inch,
}

impl Units {
    /// mm per program unit.
    #[must_use]
    pub fn mm(self) -> f64 {
        match self {
            Units::Mm => 1.0,
            Units::Inch => MM_PER_INCH,
        }
    }
}

/// Distance mode (G90/G91), also used for arc centres (G90.1/G91.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Distance {
    /// G90 (G90.1 for arc centres), absolute.
    Absolute,
    /// G91 (G91.1 for arc centres), incremental.
    Incremental,
}

/// Motion mode (modal group 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MotionMode {
    /// G0 rapid.
    Rapid,
    /// G1 linear feed.
    Linear,
    /// G2 clockwise arc.
    ArcCw,
    /// G3 counter-clockwise arc.
    ArcCcw,
    /// G80 motion cancelled.
    Cancel,
    /// G38.2–G38.5: a straight probing move that stops when the probe touches (`away`: loses contact),
    /// with an alarm if it never does (unless `no_error`: G38.3, G38.5).
    Probe {
        /// G38.4/G38.5: until contact is lost.
        away: bool,
        /// G38.3/G38.5: no alarm without a change of contact.
        no_error: bool,
    },
}

impl MotionMode {
    /// The motion mode of a group-1 G code in tenths (`0`, `10`, `20`, `30`, `800`, `382`–`385`).
    #[must_use]
    pub fn from_tenths(t: i64) -> Option<MotionMode> {
        Some(match t {
            0 => MotionMode::Rapid,
            10 => MotionMode::Linear,
            20 => MotionMode::ArcCw,
            30 => MotionMode::ArcCcw,
            800 => MotionMode::Cancel,
            382..=385 => MotionMode::Probe {
                away: t >= 384,
                no_error: t % 2 == 1,
            },
            _ => return None,
        })
    }

    /// Its G code (`G0` … `G80`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            MotionMode::Rapid => "G0",
            MotionMode::Linear => "G1",
            MotionMode::ArcCw => "G2",
            MotionMode::ArcCcw => "G3",
            MotionMode::Cancel => "G80",
            MotionMode::Probe {
                away: false,
                no_error: false,
            } => "G38.2",
            MotionMode::Probe {
                away: false,
                no_error: true,
            } => "G38.3",
            MotionMode::Probe {
                away: true,
                no_error: false,
            } => "G38.4",
            MotionMode::Probe {
                away: true,
                no_error: true,
            } => "G38.5",
        }
    }

    /// An arc (G2/G3).
    #[must_use]
    pub fn is_arc(self) -> bool {
        matches!(self, MotionMode::ArcCw | MotionMode::ArcCcw)
    }
}

/// Spindle state (M3/M4/M5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Spindle {
    /// M5.
    Off,
    /// M3, clockwise.
    Cw,
    /// M4, counter-clockwise.
    Ccw,
}

/// The modal state between blocks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Modal {
    /// G20/G21.
    pub units: Units,
    /// G90/G91.
    pub distance: Distance,
    /// G90.1/G91.1: arc centres `I J K` absolute or relative to the start (the default).
    #[serde(default = "arc_default")]
    pub arc_distance: Distance,
    /// G17/G18/G19 as 17, 18, 19.
    pub plane: u8,
    /// Group 1 motion mode.
    pub motion: MotionMode,
    /// Programmed feed in mm/min (`None` until an F word).
    pub feed_mm_min: Option<f64>,
    /// Spindle speed S (rpm).
    pub spindle_rpm: f64,
    /// M3/M4/M5.
    pub spindle: Spindle,
    /// M7 mist coolant on.
    pub mist: bool,
    /// M8 flood coolant on.
    pub flood: bool,
}

fn arc_default() -> Distance {
    Distance::Incremental
}

impl Default for Modal {
    /// GRBL's state after reset: `G0 G54 G17 G21 G90 G91.1 G94 M5 M9 T0 F0 S0`.
    fn default() -> Self {
        Modal {
            units: Units::Mm,
            distance: Distance::Absolute,
            arc_distance: Distance::Incremental,
            plane: 17,
            motion: MotionMode::Rapid,
            feed_mm_min: None,
            spindle_rpm: 0.0,
            spindle: Spindle::Off,
            mist: false,
            flood: false,
        }
    }
}
