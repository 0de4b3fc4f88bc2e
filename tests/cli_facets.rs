//! `brdfmill facets` through the binary: outputs, and bad input refused with no partial output.

use std::path::Path;
use std::process::Command;

fn brdfmill(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

fn ndf_json(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("ndf.json");
    let out = brdfmill(&[
        "ndf",
        "--brdf",
        "beckmann:alpha=0.3",
        "--res",
        "128",
        "--out",
        p.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    p
}

#[test]
fn writes_the_four_artifacts() {
    let dir = tempfile::tempdir().unwrap();
    let ndf = ndf_json(dir.path());
    let out_dir = dir.path().join("tile");
    let out = brdfmill(&[
        "facets",
        "--ndf",
        ndf.to_str().unwrap(),
        "--facets",
        "8x6",
        "--pitch-um",
        "50",
        "--sweeps",
        "2000",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        stdout.contains("energy") && stdout.contains("KS") && stdout.contains("beyond 45°"),
        "{stdout}"
    );
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(out_dir.join("tile.json")).unwrap()).unwrap();
    for key in ["cov", "relief_mm", "energy", "energy_random"] {
        assert!(v["stats"].get(key).is_some(), "stats.{key} missing");
    }
    for key in ["C", "I", "V", "valleys"] {
        assert!(v["stats"]["energy"].get(key).is_some() && v["stats"]["energy_random"].get(key).is_some());
    }
    let (rows, cols, z) = brdfmill::base::npy::read_f64_2d(&out_dir.join("tile.npy")).unwrap();
    assert_eq!((rows, cols), (6 * 20, 8 * 20));
    assert!(z.iter().all(|v| *v <= 1e-12));
    assert_eq!(&std::fs::read(out_dir.join("tile.png")).unwrap()[1..4], b"PNG");
    let stl = std::fs::read(out_dir.join("tile.stl")).unwrap();
    assert_eq!(
        stl.len(),
        84 + 50 * u32::from_le_bytes(stl[80..84].try_into().unwrap()) as usize
    );
}

fn refuses(args: &[&str], needles: &[&str], out_dir: &Path) {
    let out = brdfmill(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} should fail");
    assert_eq!(stderr.trim().lines().count(), 1, "one message: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "`{stderr}` should mention `{n}`");
    }
    assert!(!out_dir.exists(), "{args:?}: output written");
}

#[test]
fn bad_input_is_refused_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let ndf = ndf_json(dir.path());
    let out_dir = dir.path().join("tile");
    let o = out_dir.to_str().unwrap();
    let n = ndf.to_str().unwrap();
    refuses(
        &["facets", "--ndf", n, "--facets", "0x4", "--out", o],
        &["facets", "0x4"],
        &out_dir,
    );
    refuses(
        &["facets", "--ndf", n, "--facets", "4by4", "--out", o],
        &["--facets", "WxH"],
        &out_dir,
    );
    refuses(
        &["facets", "--ndf", n, "--pitch-um", "2000", "--out", o],
        &["pitch_um", "larger than a facet"],
        &out_dir,
    );
    refuses(
        &["facets", "--ndf", n, "--pitch-um", "30", "--out", o],
        &["pitch_um", "divide"],
        &out_dir,
    );
    // malformed JSON
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"version\": 1, \"nx\": ").unwrap();
    refuses(
        &["facets", "--ndf", bad.to_str().unwrap(), "--out", o],
        &["bad.json", "not a valid ndf.json"],
        &out_dir,
    );
    // a density that is not of unit mass
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&ndf).unwrap()).unwrap();
    for x in v["density"].as_array_mut().unwrap() {
        *x = serde_json::json!(x.as_f64().unwrap() * 3.0);
    }
    let heavy = dir.path().join("heavy.json");
    std::fs::write(&heavy, v.to_string()).unwrap();
    refuses(
        &["facets", "--ndf", heavy.to_str().unwrap(), "--out", o],
        &["heavy.json", "mass"],
        &out_dir,
    );
    refuses(
        &["facets", "--ndf", "/no/such/ndf.json", "--out", o],
        &["/no/such/ndf.json"],
        &out_dir,
    );
}
