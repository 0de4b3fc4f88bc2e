//! `brdfmill export OUTDIR`: the BRDFs of a job's output folder in a file other tools read. Written: the
//! target's, the design tile's and the simulated milled surface's BRDFs as MERL `.binary` tables
//! (`target.binary`, `design.binary`, `milled.binary`; Matusik et al. 2003: 90 θh × 90 θd × 180 φd bins,
//! θh on a square-root scale, f per channel over the scales 1/1500, 1.15/1500, 1.66/1500).
//!
//! The design's and the milled surface's BRDFs are the report's: the microfacet BRDF (Eq. 5) of the NDF the
//! verdict measured (`ndf-design.json`, `ndf-milled.json`), its Smith masking from the same grid, with the
//! target's material. The job is read back from the folder's `job.toml`, as `compare` reads it.

use super::{JobError, StageError};
use crate::stages::brdf::merl::Merl;
use crate::stages::ndf::NdfFile;
use crate::stages::optics::geometric::MicrofacetBrdf;
use std::path::{Path, PathBuf};

/// A BRDF to tabulate: `f(wi, wo)` in RGB.
type BrdfFn<'a> =
    dyn Fn(&crate::base::geometry::Vec3, &crate::base::geometry::Vec3) -> crate::stages::brdf::Rgb + Sync + 'a;

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
    let mut written = vec![];
    let tables: [(&str, &BrdfFn, String); 3] = [
        (
            "target.binary",
            &|a, b| target.eval(a, b),
            format!("the target `{}`", target.spec),
        ),
        (
            "design.binary",
            &|a, b| design.eval(a, b),
            "the design tile's BRDF (its NDF in ndf-design.json)".into(),
        ),
        (
            "milled.binary",
            &|a, b| milled.eval(a, b),
            "the simulated milled surface's BRDF (its NDF in ndf-milled.json)".into(),
        ),
    ];
    for (name, f, what) in tables {
        let path = out.join(name);
        Merl::from_fn(f).write(&path)?;
        written.push((path, what));
    }
    Ok(written)
}
