//! `brdfmill simulate` through the binary: its files and figures, and refusals that name the file, line and
//! column and write nothing.

use std::process::Command;

fn brdfmill(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

#[test]
fn simulate_writes_its_files_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let prog = dir.path().join("groove.nc");
    std::fs::write(
        &prog,
        "%\nG21 G90 G17\nG0 X0 Y0 Z1\nG1 Z-0.2 F200\nX2\nG2 X3 Y1 I0 J1\nG0 Z1\nM2\n%\n",
    )
    .unwrap();
    let out = dir.path().join("sim");
    let o = brdfmill(&[
        "simulate",
        prog.to_str().unwrap(),
        "--tool",
        "ball:1.0",
        "--pitch-um",
        "10",
        "--stl",
        "--out",
        out.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{text}");
    for f in ["sim.npy", "sim.png", "sim.json", "sim.stl"] {
        assert!(out.join(f).is_file(), "{f} missing: {text}");
    }
    assert!(text.contains("removed") && text.contains("estimated"), "{text}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sim.json")).unwrap()).unwrap();
    assert_eq!(json["stats"]["arcs"], 1);
    assert!(json["stats"]["removed_volume_mm3"].as_f64().unwrap() > 0.1);
    let (rows, cols, z) = brdfmill::base::npy::read_f64_2d(&out.join("sim.npy")).unwrap();
    assert_eq!(
        [cols, rows],
        [
            json["stats"]["cells"][0].as_u64().unwrap() as usize,
            json["stats"]["cells"][1].as_u64().unwrap() as usize
        ]
    );
    assert!((z.iter().copied().fold(f64::INFINITY, f64::min) + 0.2).abs() < 1e-3);
}

#[test]
fn refusals_name_file_line_and_column_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let prog = dir.path().join("bad.ngc");
    std::fs::write(&prog, "G21\nG0 X0 Y0 Z1\nG1 Z-0.1 F100\n  G28 X1\n").unwrap();
    let out = dir.path().join("sim");
    let o = brdfmill(&[
        "simulate",
        prog.to_str().unwrap(),
        "--tool",
        "ball:1",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("bad.ngc") && err.contains("line 4, column 3"), "{err}");
    assert!(!out.exists(), "nothing may be written on a refusal");
    for (tool, what) in [
        ("ball", "ball:D"),
        ("bull:1:0.8", "corner_radius_mm"),
        ("cone:1", "expected"),
    ] {
        let o = brdfmill(&[
            "simulate",
            prog.to_str().unwrap(),
            "--tool",
            tool,
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(what), "{tool}: {err}");
    }
    let o = brdfmill(&[
        "simulate",
        prog.to_str().unwrap(),
        "--tool",
        "ball:1",
        "--bounds",
        "0,0,1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--bounds"));
    assert!(!out.exists());
}
