//! # brdfmill
//!
//! Turn a target reflectance (a BRDF) into microgeometry that a 3-axis mill with a ball-nose bit can cut,
//! then check the result. The method is Weyrich, Peers, Matusik & Rusinkiewicz 2009, "Fabricating
//! Microgeometry for Custom Surface Reflectance" (ACM TOG 28(3), DOI 10.1145/1531326.1531338). Equation
//! numbers (Eq. N) follow the restatement the project reads it in; `docs/DESIGN.md` says which equation is
//! which and holds every derivation the code cites (`DESIGN.md §N`).
//!
//! The pipeline, one module per stage, data flowing one way:
//!
//! 1. [`brdf`]: analytic and measured BRDFs behind one type, conductor Fresnel from complex IOR.
//! 2. [`ndf`]: BRDF → half-angle distribution in slope space → Lucy–Richardson deconvolution of the base
//!    material's own lobe → target NDF (`ndf.json`).
//!
//! Shared foundations: [`geometry`] (directions, slopes, half/difference angles), [`slope`] (a slope-space
//! density grid and its statistics), [`plot`] (false-colour PNG figures) and [`io`] (atomic file output).
//!
//! Conventions: right-handed frame, `z` the mean surface normal pointing out of the material; machine lengths
//! in mm, optical lengths in µm, angles in radians internally. A microfacet normal `wm = (mx, my, mz)` is the
//! slope `(p, q) = (-mx/mz, -my/mz)`; the slope density `P22(p, q)` integrates to 1 over the slope plane and
//! relates to the NDF by `D(wm) = P22(p, q) / cos⁴θm`.
#![warn(missing_docs)]
#![forbid(unsafe_code)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod analyze;
pub mod brdf;
pub mod de;
pub mod design;
pub mod distance;
pub mod facets;
pub(crate) mod fft2;
pub mod gcode;
pub mod geometry;
pub mod heightfield;
pub mod image;
pub mod io;
pub mod job;
pub mod morphology;
pub mod ndf;
pub mod npy;
pub mod optics;
pub mod plot;
pub mod simulate;
pub mod slope;
pub mod stl;
pub mod stream;
pub mod svbrdf;
pub mod tool;
pub mod toolpath;
pub mod verify;
pub mod x3p;
