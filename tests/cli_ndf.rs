//! `brdfmill ndf` end to end through the binary: outputs on success, and on bad input a non-zero exit, one
//! clear message naming the input, and no output file.

use std::path::Path;
use std::process::Command;

fn brdfmill(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

#[test]
fn writes_json_and_png_and_prints_statistics() {
    let dir = tempfile::tempdir().unwrap();
    let (json, png) = (dir.path().join("ndf.json"), dir.path().join("ndf.png"));
    let out = brdfmill(&[
        "ndf",
        "--brdf",
        "ggx:alpha=0.2,material=gold",
        "--base",
        "beckmann:alpha=0.05",
        "--res",
        "128",
        "--out",
        json.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("cov") && stdout.contains("lucy-richardson"), "{stdout}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["version"], 1);
    assert_eq!(v["density"].as_array().unwrap().len(), 128 * 128);
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
}

#[test]
fn rgl_slope_statistics_are_printed() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("ndf.json");
    let rgl = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/rgl/vch_golden_yellow_rgb.bsdf");
    let out = brdfmill(&[
        "ndf",
        "--brdf",
        &format!("rgl:{}", rgl.display()),
        "--res",
        "128",
        "--out",
        json.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(
        stdout.contains("MeasuredNdf") && stdout.contains("mass 1.000000") && stdout.contains("cov"),
        "{stdout}"
    );
}

/// Run with bad input; expect failure, a message containing every needle, and no output file.
fn refuses(brdf: &str, needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("ndf.json");
    let png = dir.path().join("ndf.png");
    let out = brdfmill(&[
        "ndf",
        "--brdf",
        brdf,
        "--out",
        json.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{brdf}: should fail");
    assert_eq!(stderr.trim().lines().count(), 1, "{brdf}: one message, got:\n{stderr}");
    for n in needles {
        assert!(stderr.contains(n), "{brdf}: `{stderr}` should mention `{n}`");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "{brdf}: output left behind"
    );
}

#[test]
fn bad_input_is_refused_without_output() {
    let dir = tempfile::tempdir().unwrap();
    // a truncated MERL file: the right header, too few values
    let trunc = dir.path().join("trunc.binary");
    let mut b = Vec::new();
    for d in [90i32, 90, 180] {
        b.extend_from_slice(&d.to_le_bytes());
    }
    b.extend_from_slice(&[0u8; 4096]);
    std::fs::write(&trunc, &b).unwrap();
    refuses(&format!("merl:{}", trunc.display()), &["trunc.binary", "truncated"]);
    // a wrong header
    let wrong = dir.path().join("wrong.binary");
    std::fs::write(&wrong, [7u8; 64]).unwrap();
    refuses(
        &format!("merl:{}", wrong.display()),
        &["wrong.binary", "expected [90, 90, 180]"],
    );
    // NaN in a CSV
    let csv = dir.path().join("nan.csv");
    std::fs::write(&csv, "theta_h_deg,phi_h_deg,value\n0,0,1\n10,0,nan\n20,0,0.5\n").unwrap();
    refuses(&format!("csv:{}", csv.display()), &["nan.csv", "line 3", "value"]);
    refuses("beckmann:alpha=0", &["beckmann:alpha=0", "alpha", "> 0"]);
    refuses("cooktorrance:m=0.2", &["unknown model"]);
    refuses("merl:/no/such/file.binary", &["/no/such/file.binary", "No such file"]);
    refuses("rgl:/no/such/file.bsdf", &["/no/such/file.bsdf"]);
}
