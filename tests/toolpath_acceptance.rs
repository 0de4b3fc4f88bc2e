//! The toolpath stage's acceptance figures (issue "Toolpath: …"): the default job's program passes LinuxCNC's
//! own interpreter, covers the requested area, never dips below the design, and limit violations are
//! refused before anything is written.

use brdfmill::brdf::Brdf;
use brdfmill::facets::{self, FacetsConfig};
use brdfmill::gcode::moves::Move;
use brdfmill::heightfield::Heightfield;
use brdfmill::ndf::{self, NdfConfig};
use brdfmill::toolpath::{self, check, machine::Machine, ToolpathConfig, ToolpathError};
use std::path::Path;
use std::sync::OnceLock;

/// The default job's tile: beckmann α = 0.3, 32×32 facets of 1 mm at 10 µm.
fn tile() -> &'static Heightfield {
    static T: OnceLock<Heightfield> = OnceLock::new();
    T.get_or_init(|| {
        let n = ndf::run(&NdfConfig::default(), &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
        facets::run(&FacetsConfig::default(), &n.target).unwrap().heightfield
    })
}

fn machine(name: &str) -> Machine {
    Machine::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("machines").join(name)).unwrap()
}

/// LinuxCNC's standalone interpreter `rs274` (Debian package linuxcnc-uspace). The tests that use it are
/// `#[ignore]`d, so that plain `cargo test` reports them as ignored rather than passing them; run with
/// `cargo test -- --ignored` (as `.ci/run` does after installing it), they fail when it is missing.
fn require_rs274() {
    let found = std::process::Command::new("rs274")
        .arg("-h")
        .stdin(std::process::Stdio::null())
        .output()
        .is_ok();
    assert!(
        found,
        "rs274 is required by this test but not installed (apt-get install linuxcnc-uspace)"
    );
}

/// Run LinuxCNC's standalone interpreter; Ok(canonical command count) or Err(its message).
fn interpret(gcode: &str) -> Result<usize, String> {
    let dir = tempfile::tempdir().unwrap();
    let (prog, canon) = (dir.path().join("p.ngc"), dir.path().join("p.canon"));
    std::fs::write(&prog, gcode).unwrap();
    let out = std::process::Command::new("rs274")
        .arg("-g")
        .arg(&prog)
        .arg(&canon)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    let canon = std::fs::read_to_string(&canon).unwrap_or_default();
    if !out.status.success() || !canon.contains("PROGRAM_END") || text.to_lowercase().contains("error") {
        return Err(format!("rs274 exit {:?}: {text}", out.status.code()));
    }
    Ok(canon.lines().count())
}

/// The default job's finishing program for each machine profile, with the 1 mm ball.
fn default_programs() -> Vec<(&'static str, toolpath::Toolpath)> {
    ["linuxcnc-mill.toml", "grbl-3018.toml"]
        .into_iter()
        .map(|profile| {
            let cfg = ToolpathConfig {
                tool: "ball1".into(),
                ..Default::default()
            };
            (profile, toolpath::run(&cfg, tile(), &machine(profile)).unwrap())
        })
        .collect()
}

#[test]
fn default_job_covers_the_area_without_gouging() {
    for (profile, p) in default_programs() {
        let s = &p.summary;
        println!("{profile}: {s:?}");
        // the cut covers the requested area: tool-centre extents within one sample of it
        let feeds: Vec<[f64; 3]> = p
            .moves
            .iter()
            .filter_map(|m| if let Move::Feed(q, _) = m { Some(*q) } else { None })
            .collect();
        let (xmin, xmax) = feeds.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, q| {
            (a.0.min(q[0]), a.1.max(q[0]))
        });
        let (ymin, ymax) = feeds.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, q| {
            (a.0.min(q[1]), a.1.max(q[1]))
        });
        let pitch = tile().pitch_mm;
        assert!(
            xmin >= -1e-9 && xmin <= pitch && xmax <= 40.0 + 1e-9 && xmax >= 40.0 - pitch,
            "x {xmin}..{xmax}"
        );
        assert!(ymin.abs() < 1e-9 && (ymax - 40.0).abs() < 1e-9, "y {ymin}..{ymax}");
        // scallop target met and no gouge at any emitted CL point
        assert!(s.scallop_um <= 1.0 + 1e-9);
        assert!(s.max_gouge_um <= 1e-6, "gouge {} µm", s.max_gouge_um);
        assert!(s.checked_points >= 40_000);
        // the design is deeper than one cut: roughing layers exist, and no layer cuts deeper than a cut
        assert!(s.roughing_layers >= 1);
        assert!(p.gcode.contains("G21 G90 G17 G94") && p.gcode.contains("M3 S") && p.gcode.contains("G4 P"));
        assert!(p.gcode.trim_end().ends_with("M2"));
    }
}

#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn default_job_passes_rs274() {
    require_rs274();
    for (profile, p) in default_programs() {
        let n = interpret(&p.gcode).unwrap_or_else(|e| panic!("{profile}: {e}"));
        println!(
            "{profile}: rs274 produced {n} canonical commands for {} lines",
            p.summary.lines
        );
        assert!(
            n > p.summary.lines / 2,
            "rs274 produced {n} canonical commands for {} lines",
            p.summary.lines
        );
    }
}

#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn rs274_check_itself_catches_a_bad_program() {
    require_rs274();
    assert!(
        interpret("G21 G90\nG1 X1 Y1\nM2\n").is_err(),
        "G1 without a feed must be refused"
    );
    assert!(interpret("G21 G90\nG1 X1 F100\nM2\n").is_ok());
}

#[test]
fn limit_violations_are_refused() {
    let small = {
        let mut hf = Heightfield::flat(40, 40, 0.05, true, 0.0);
        for (k, z) in hf.z_mm.iter_mut().enumerate() {
            *z = -0.05 * ((k % 40) as f64 / 40.0 * std::f64::consts::TAU).sin().abs();
        }
        hf
    };
    let m = machine("grbl-3018.toml");
    // larger than the travel
    let cfg = ToolpathConfig {
        area_mm: [40.0, 200.0],
        ..Default::default()
    };
    match toolpath::run(&cfg, &small, &m) {
        Err(ToolpathError::Machine(e)) => assert!(e.contains("travel") && e.contains("180"), "{e}"),
        other => panic!("expected a travel refusal, got {:?}", other.map(|p| p.summary)),
    }
    // a feed above the machine's limit
    let cfg = ToolpathConfig {
        area_mm: [4.0, 4.0],
        feed_mm_min: 5000.0,
        stepover_mm: 0.2,
        ..Default::default()
    };
    match toolpath::run(&cfg, &small, &m) {
        Err(ToolpathError::Machine(e)) => assert!(e.contains("max_feed_mm_min") && e.contains("5000"), "{e}"),
        other => panic!("expected a feed refusal, got {:?}", other.map(|p| p.summary)),
    }
    // a rapid into the stock, and a rapid across X/Y below safe z
    let tool = m.tool("ball1").unwrap();
    let start = [0.0, 0.0, 3.0];
    let e = check::check(&[Move::Rapid([0.0, 0.0, -0.2])], start, &m, tool).unwrap_err();
    assert!(e.contains("into the stock"), "{e}");
    let e = check::check(
        &[Move::Rapid([0.0, 0.0, 1.0]), Move::Rapid([5.0, 0.0, 1.0])],
        start,
        &m,
        tool,
    )
    .unwrap_err();
    assert!(e.contains("safe_z_mm"), "{e}");
    let e = check::check(&[Move::SpindleOn(30000.0)], start, &m, tool).unwrap_err();
    assert!(e.contains("spindle") && e.contains("30000"), "{e}");
    // a legal program passes
    let ok = ToolpathConfig {
        area_mm: [4.0, 4.0],
        stepover_mm: 0.2,
        ..Default::default()
    };
    assert!(toolpath::run(&ok, &small, &m).is_ok());
}
