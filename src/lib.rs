//! # brdfmill
//!
//! Turn a target reflectance (a BRDF) into microgeometry that a 3-axis mill with a ball-nose bit can cut,
//! then check the result. The method is Weyrich, Peers, Matusik & Rusinkiewicz 2009, "Fabricating
//! Microgeometry for Custom Surface Reflectance" (ACM TOG 28(3), DOI 10.1145/1531326.1531338). Equation
//! numbers (Eq. N) follow the restatement the project reads it in; `docs/DESIGN.md` says which equation is
//! which and holds every derivation the code cites (`DESIGN.md §N`).
//!
//! The crate in layers; each imports only the layers below it and, among the stages, only earlier ones:
//!
//! | layer | modules | holds |
//! | --- | --- | --- |
//! | foundation | [`base`], [`gcode`] | directions and slopes, slope-space densities, heightfields, distances, FFTs, file formats and atomic output, figures; the one G-code model (tokenizer, modal state, move list, writer, program model) |
//! | machining | [`cut`] | tool shapes, machine profiles and their accuracy (backlash, runout, step grid), drop-cutter, morphology by the tool, the chords a controller cuts, the swept stock, the run-time planner |
//! | stages | [`stages`]: [`brdf`](stages::brdf) → [`ndf`](stages::ndf) → [`facets`](stages::facets) → [`design`](stages::design) → [`svbrdf`](stages::svbrdf) → [`toolpath`](stages::toolpath) → [`simulate`](stages::simulate) → [`optics`](stages::optics) → [`verify`](stages::verify) | target BRDF → NDF → facet tile → the loop around it → G-code → simulated cut → its BRDF and the verdict |
//! | applications | [`apps`]: [`stream`](apps::stream), [`analyze`](apps::analyze), [`calibrate`](apps::calibrate) | GRBL streaming and the virtual controller; a measured surface's NDF and BRDF; the coupon that measures a machine's accuracy |
//! | the job | [`job`] | `JOB.toml`, the runner that sequences the stages and writes their artifacts |
//!
//! The binary (`src/main.rs`, `src/cli/`) only parses arguments, reads and writes files and prints.
//!
//! Conventions: right-handed frame, `z` the mean surface normal pointing out of the material; machine lengths
//! in mm, optical lengths in µm, angles in radians internally. A microfacet normal `wm = (mx, my, mz)` is the
//! slope `(p, q) = (-mx/mz, -my/mz)`; the slope density `P22(p, q)` integrates to 1 over the slope plane and
//! relates to the NDF by `D(wm) = P22(p, q) / cos⁴θm`.
#![warn(missing_docs)]
#![forbid(unsafe_code)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod apps;
pub mod base;
pub mod cut;
pub mod gcode;
pub mod job;
pub mod stages;
