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
