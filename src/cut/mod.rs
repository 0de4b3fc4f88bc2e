//! The machining layer, below every stage that cuts or models a cut: the cutter's shape, machine profiles
//! and their tools, the drop-cutter (cutter-location surface), grey-scale morphology by the tool's
//! underside (dilation, opening), the chords a controller cuts along a pass, the closed-form sweep of a
//! tool along a segment, the tiled stock it lowers, and the run-time planner. `toolpath`, `design`,
//! `simulate` and `verify` share it, so no stage reaches into a later one for these.

pub mod accuracy;
pub mod chords;
pub mod dropcutter;
pub(crate) mod estimate;
pub mod feeds;
pub mod machine;
pub mod morphology;
pub(crate) mod stock;
pub mod sweep;
pub mod tool;
