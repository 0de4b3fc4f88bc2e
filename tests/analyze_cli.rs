//! `brdfmill analyze` end to end: the real X3P scan and a simulated .npy surface.

use std::process::Command;

fn brdfmill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
}

#[test]
fn analyzes_the_real_scan() {
    let dir = tempfile::tempdir().unwrap();
    let out = brdfmill()
        .args(["analyze", "examples/data/sample-land.x3p", "--windows", "2", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for f in [
        "ndf.png",
        "brdf_slices.png",
        "surface.png",
        "analysis.json",
        "report.html",
    ] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    let a: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("analysis.json")).unwrap()).unwrap();
    assert_eq!(a["size"], serde_json::json!([918, 256]));
    assert_eq!(a["missing_points"], 25_292);
    let cov = &a["slope_cov"];
    let (pp, qq) = (cov[0][0].as_f64().unwrap(), cov[1][1].as_f64().unwrap());
    assert!(pp > 0.0 && qq > 0.0 && pp.is_finite() && qq.is_finite());
    assert!(a["fft_vs_gabor_l2"].as_f64().unwrap() < 0.01);
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.contains("data:image/png;base64,") && !html.contains("http://") && !html.contains("https://"));
}

#[test]
fn a_npy_surface_needs_its_pitch_and_bad_input_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let hf = brdfmill::base::heightfield::Heightfield::flat(64, 64, 0.001, false, 0.0);
    let npy = dir.path().join("flat.npy");
    hf.write_npy(&npy).unwrap();
    let out = brdfmill()
        .args(["analyze"])
        .arg(&npy)
        .arg("--out")
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--pitch-um"));
    let out = brdfmill()
        .args(["analyze"])
        .arg(&npy)
        .args(["--pitch-um", "1", "--sigma-um", "4", "--windows", "1", "--out"])
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let a: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/analysis.json")).unwrap()).unwrap();
    // a flat mirror: all light in the slice (F = 1)
    assert!(
        (a["wave_albedo"].as_f64().unwrap() - 1.0).abs() < 1e-3,
        "{}",
        a["wave_albedo"]
    );
    let bad = dir.path().join("bad.x3p");
    std::fs::write(&bad, b"nope").unwrap();
    let out = brdfmill()
        .args(["analyze"])
        .arg(&bad)
        .arg("--out")
        .arg(dir.path().join("b"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.x3p"));
}
