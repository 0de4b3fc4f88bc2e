//! `brdfmill toolpath` through the binary: a program and its figures, and refusals that write nothing.

use std::path::{Path, PathBuf};
use std::process::Command;

fn brdfmill(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

fn machine(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("machines")
        .join(name)
        .display()
        .to_string()
}

fn small_tile(dir: &Path) -> PathBuf {
    let ndf = dir.join("ndf.json");
    assert!(brdfmill(&[
        "ndf",
        "--brdf",
        "beckmann:alpha=0.2",
        "--res",
        "64",
        "--out",
        ndf.to_str().unwrap()
    ])
    .status
    .success());
    let t = dir.join("tile");
    let out = brdfmill(&[
        "facets",
        "--ndf",
        ndf.to_str().unwrap(),
        "--facets",
        "4x4",
        "--pitch-um",
        "20",
        "--sweeps",
        "500",
        "--out",
        t.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    t.join("tile.json")
}

#[test]
fn writes_a_program_and_prints_its_figures() {
    let dir = tempfile::tempdir().unwrap();
    let tile = small_tile(dir.path());
    let nc = dir.path().join("p.nc");
    let out = brdfmill(&[
        "toolpath",
        "--tile",
        tile.to_str().unwrap(),
        "--machine",
        &machine("grbl-3018.toml"),
        "--tool",
        "ball1",
        "--area",
        "6x5",
        "--scallop-um",
        "2",
        "--angle-deg",
        "30",
        "--stock",
        "wax",
        "--out",
        nc.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    for needle in ["lines", "path", "estimated", "gouge"] {
        assert!(stdout.contains(needle), "{stdout}");
    }
    let g = std::fs::read_to_string(&nc).unwrap();
    assert!(
        g.contains("(estimated run time") && g.lines().all(|l| l.len() <= 80),
        "GRBL's 80-character line limit"
    );
    assert!(!g.contains("G64"), "GRBL has no G64");
}

#[test]
fn refusals_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let tile = small_tile(dir.path());
    let nc = dir.path().join("p.nc");
    let t = tile.to_str().unwrap();
    let n = nc.to_str().unwrap();
    for (args, needle) in [
        (
            vec![
                "--machine",
                &machine("grbl-3018.toml") as &str,
                "--tool",
                "ball1",
                "--area",
                "20x400",
            ],
            "travel",
        ),
        (
            vec![
                "--machine",
                &machine("grbl-3018.toml"),
                "--tool",
                "ball1",
                "--area",
                "5x5",
                "--feed-mm-min",
                "9000",
            ],
            "max_feed_mm_min",
        ),
        (
            vec![
                "--machine",
                &machine("grbl-3018.toml"),
                "--tool",
                "flat3",
                "--area",
                "5x5",
            ],
            "ball-nose",
        ),
        (
            vec![
                "--machine",
                &machine("grbl-3018.toml"),
                "--tool",
                "ball9",
                "--area",
                "5x5",
            ],
            "no tool `ball9`",
        ),
        (
            vec!["--machine", "/no/such/machine.toml", "--tool", "ball1"],
            "/no/such/machine.toml",
        ),
        (
            vec![
                "--machine",
                &machine("grbl-3018.toml"),
                "--tool",
                "ball1",
                "--area",
                "5by5",
            ],
            "--area",
        ),
    ] {
        let mut all = vec!["toolpath", "--tile", t, "--out", n];
        all.extend(args);
        let out = brdfmill(&all);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{all:?}");
        assert!(stderr.contains(needle), "{all:?}: `{stderr}` should mention `{needle}`");
        assert!(!nc.exists(), "{all:?} wrote a program");
    }
}

/// Issue 15: shipped profiles are found by name from any folder, and the program is the one the file on
/// disk gives; an unknown name lists the shipped ones.
#[test]
fn a_shipped_profile_is_found_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let tile = small_tile(dir.path());
    let run = |m: &str, out: &Path| {
        Command::new(env!("CARGO_BIN_EXE_brdfmill"))
            .current_dir(dir.path())
            .args([
                "toolpath",
                "--tile",
                tile.to_str().unwrap(),
                "--machine",
                m,
                "--tool",
                "ball1",
            ])
            .args(["--area", "4x4", "--stock", "wax", "--out", out.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let (by_name, by_path) = (dir.path().join("a.nc"), dir.path().join("b.nc"));
    let o = run("grbl-3018", &by_name);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(run(&machine("grbl-3018.toml"), &by_path).status.success());
    assert_eq!(std::fs::read(&by_name).unwrap(), std::fs::read(&by_path).unwrap());
    let bad = run("grbl-9999", &dir.path().join("c.nc"));
    let e = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && e.contains("grbl-router-6040") && e.contains("linuxcnc-mill"),
        "{e}"
    );
    assert!(!dir.path().join("c.nc").exists());
}
