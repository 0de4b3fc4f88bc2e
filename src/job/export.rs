//! `brdfmill export OUTDIR`: the BRDFs of a job's output folder in files other tools read. Written: the
//! target's, the design tile's and the simulated milled surface's BRDFs
//! - as RGL `.bsdf` files (`target.bsdf`, `design.bsdf`, `milled.bsdf`; Dupuy & Jakob 2018, RGB form, the
//!   layout in [`crate::stages::brdf::rgl_write`]), which Mitsuba 3's `measured` plugin renders;
//! - as MERL `.binary` tables (`target.binary`, `design.binary`, `milled.binary`; Matusik et al. 2003:
//!   90 θh × 90 θd × 180 φd bins, θh on a square-root scale, f per channel over the scales 1/1500,
//!   1.15/1500, 1.66/1500).
//!
//! An RGL file is parameterised by an NDF: the design's and the milled surface's are theirs; the target's is
//! its own where the model has one (analytic models, RGL, drawn highlights, scans) and otherwise (MERL) the
//! half-angle distribution the job derived from its reflectance (`ndf.json`'s `observed`) with a uniform floor
//! ([`crate::stages::brdf::rgl_write::with_floor`]), so that reflection beyond its slope grid's cone is kept.
//!
//! The design's and the milled surface's BRDFs are the report's: the microfacet BRDF (Eq. 5) of the NDF the
//! verdict measured (`ndf-design.json`, `ndf-milled.json`), its Smith masking from the same grid, with the
//! target's material. The job is read back from the folder's `job.toml`, as `compare` reads it.

use super::{JobError, StageError};
use crate::base::geometry::Vec3;
use crate::stages::brdf::merl::Merl;
use crate::stages::brdf::rgl_write::{with_floor, write_rgl, RglSource};
use crate::stages::ndf::NdfFile;
use crate::stages::optics::geometric::MicrofacetBrdf;
use std::path::{Path, PathBuf};

/// A BRDF to tabulate: `f(wi, wo)` in RGB.
type BrdfFn<'a> = dyn Fn(&Vec3, &Vec3) -> crate::stages::brdf::Rgb + Sync + 'a;

/// An NDF `D(wm)`.
type NdfFn<'a> = dyn Fn(&Vec3) -> f64 + Sync + 'a;

/// Write the job's BRDFs from its output folder `job_out` into `out`; returns each file and what it holds.
pub fn export(job_out: &Path, out: &Path) -> Result<Vec<(PathBuf, String)>, JobError> {
    let input = |e: String| JobError::Stage {
        stage: "export",
        error: StageError::Input(e),
    };
    let ready = super::compare::reload(job_out)?;
    if ready.labels.is_some() {
        return Err(input(
            "the job has `[svbrdf]` regions: export writes the BRDFs of a job with one target".into(),
        ));
    }
    let target = ready.target();
    let surface = |name: &str| -> Result<MicrofacetBrdf, JobError> {
        let path = job_out.join(name);
        let f = NdfFile::read(&path).map_err(|e| input(e.to_string()))?;
        Ok(MicrofacetBrdf::new(f.target(), target.material))
    };
    let (design, milled) = (surface("ndf-design.json")?, surface("ndf-milled.json")?);
    // the target's own NDF, or the half-angle distribution of its reflectance
    let observed = if target.known_ndf(&Vec3::new(0.0, 0.0, 1.0)).is_some() {
        None
    } else {
        let f = NdfFile::read(&job_out.join("ndf.json")).map_err(|e| input(e.to_string()))?;
        Some(MicrofacetBrdf::new(f.observed(), None))
    };
    let own = |m: &Vec3| target.known_ndf(m).unwrap_or(0.0);
    let floored = observed.as_ref().map(|o| with_floor(move |m: &Vec3| o.d(m)));
    let target_d: &NdfFn = match &floored {
        Some(d) => d,
        None => &own,
    };
    let mut written = vec![];
    let tables: [(&str, &BrdfFn, &NdfFn, String); 3] = [
        (
            "target",
            &|a, b| target.eval(a, b),
            target_d,
            format!("the target `{}`", target.spec),
        ),
        (
            "design",
            &|a, b| design.eval(a, b),
            &|m| design.d(m),
            "the design tile's BRDF (its NDF in ndf-design.json)".into(),
        ),
        (
            "milled",
            &|a, b| milled.eval(a, b),
            &|m| milled.d(m),
            "the simulated milled surface's BRDF (its NDF in ndf-milled.json)".into(),
        ),
    ];
    for (name, f, d, what) in tables {
        let path = out.join(format!("{name}.bsdf"));
        let src = RglSource {
            description: format!("brdfmill: {what}"),
            ndf: d,
            brdf: f,
        };
        write_rgl(&path, &src)?;
        written.push((path, format!("{what}, RGL .bsdf (Mitsuba 3 `measured`, RGB variants)")));
        let path = out.join(format!("{name}.binary"));
        Merl::from_fn(f).write(&path)?;
        written.push((path, format!("{what}, MERL .binary")));
    }
    Ok(written)
}
