//! Helpers shared by the integration tests that run the `brdfmill` binary (`mod common;` in each; a test file
//! uses what it needs).
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The repository (the binary runs here, so `examples/…` paths resolve).
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Run the binary with `args` from the repository.
pub fn brdfmill(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("run brdfmill")
}

/// Run the binary and require it to succeed; its stderr is the failure message.
pub fn brdfmill_ok(args: &[&str]) -> Output {
    let o = brdfmill(args);
    assert!(
        o.status.success(),
        "brdfmill {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The default job on a 6 × 6 mm tile (a smaller part: the same target, machine and tool; about 10 s in
/// release) into `out`, with further `--set` overrides.
pub fn run_small_job(out: &Path, sets: &[&str]) {
    let mut args = vec![
        "run",
        "examples/default.toml",
        "--out",
        out.to_str().unwrap(),
        "--set",
        "facets.facets_x=6",
        "--set",
        "facets.facets_y=6",
        "--set",
        "toolpath.area_mm=[7.2,7.2]",
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    brdfmill_ok(&args);
}

/// A BRDF `f(wi, wo)` in RGB, without the cosine.
pub type BrdfBox<'a> = Box<dyn Fn(&brdfmill::base::geometry::Vec3, &brdfmill::base::geometry::Vec3) -> [f64; 3] + 'a>;

/// The BRDFs `brdfmill export` writes for a job's output folder: the target, and the report's design and
/// milled BRDFs (the microfacet BRDFs of `ndf-design.json` and `ndf-milled.json` with the target's material).
pub struct JobBrdfs {
    pub target: brdfmill::stages::brdf::Brdf,
    pub design: brdfmill::stages::optics::geometric::MicrofacetBrdf,
    pub milled: brdfmill::stages::optics::geometric::MicrofacetBrdf,
}

impl JobBrdfs {
    /// Read from the output folder `job` of a job whose target is `spec`.
    pub fn read(job: &Path, spec: &str) -> Self {
        use brdfmill::stages::ndf::NdfFile;
        use brdfmill::stages::optics::geometric::MicrofacetBrdf;
        let target = brdfmill::stages::brdf::Brdf::parse(spec).unwrap();
        let surface =
            |name: &str| MicrofacetBrdf::new(NdfFile::read(&job.join(name)).unwrap().target(), target.material);
        let (design, milled) = (surface("ndf-design.json"), surface("ndf-milled.json"));
        Self { target, design, milled }
    }

    /// Each with the stem of its exported files: `target`, `design`, `milled`.
    pub fn each(&self) -> [(&'static str, BrdfBox<'_>); 3] {
        [
            ("target", Box::new(|a, b| self.target.eval(a, b))),
            ("design", Box::new(|a, b| self.design.eval(a, b))),
            ("milled", Box::new(|a, b| self.milled.eval(a, b))),
        ]
    }
}
