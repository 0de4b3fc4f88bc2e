//! The regression corpus of hostile and broken inputs (issue "Hostile and broken input"): every case that
//! once panicked, aborted, ran without end, was accepted without a word or gave a misleading message. Each
//! must now be refused through the binary with exit code 1 (never 101, a panic, or 134, an abort), a message
//! naming the file and the field or line, and nothing written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn brdfmill(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

/// The run was refused cleanly: exit 1, every `want` in the message, and `out` empty or absent.
fn refused(o: &Output, want: &[&str], out: &Path) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(1),
        "expected a refusal, got {:?}: {err}",
        o.status
    );
    for w in want {
        assert!(err.contains(w), "missing `{w}` in: {err}");
    }
    let left: Vec<PathBuf> = std::fs::read_dir(out)
        .map(|d| d.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    assert!(left.is_empty(), "a refusal wrote {left:?}");
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `examples/default.toml` with `edits` (old text → new text) applied, written beside the examples so its
/// relative paths still resolve.
fn job_with(dir: &Path, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = std::fs::read_to_string(root().join("examples/default.toml")).unwrap();
    for (a, b) in edits {
        assert!(text.contains(a), "{a}");
        text = text.replacen(a, b, 1);
    }
    let text = text.replace("../machines/", &format!("{}/machines/", root().display()));
    let p = dir.join("job.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn job_values_that_would_overflow_or_never_end_are_refused_before_any_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (edit, want) in [
        (("facets_x = 12", "facets_x = 4611686018427387905"), "facets"),
        (("facets_y = 12", "facets_y = 0"), "facets"),
        (("scallop_um = 1.0", "scallop_um = 1e-9"), "passes"),
        (("scallop_um = 1.0", "scallop_um = 0.0"), "toolpath.scallop_um"),
        (("scallop_um = 1.0", "scallop_um = -3.0"), "toolpath.scallop_um"),
        (("scallop_um = 1.0", "scallop_um = nan"), "toolpath.scallop_um"),
        (
            ("[simulate]\npitch_um = 5.0", "[simulate]\npitch_um = 0.001"),
            "simulate.pitch_um",
        ),
        (
            (
                "incident_deg = [0.0, 30.0, 60.0]",
                "incident_deg = [0.0]\n[verify.tolerances]\ncov_ratio = [1.1, 0.9]",
            ),
            "cov_ratio",
        ),
        (
            ("max_angle_deg = 60.0", "max_angle_deg = 60.0\niterations = 100000000"),
            "iterations",
        ),
    ] {
        let job = job_with(dir.path(), &[edit]);
        let o = brdfmill(&["run", job.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        refused(&o, &["job.toml", want], &out);
    }
}

/// Values the toolpath stage used to refuse only after the NDF and the design had run and written their
/// files, or not at all (a feed written as `F0`, a third area value dropped, a test of a billion
/// permutations): each is refused before any file, naming its key.
#[test]
fn toolpath_and_facets_values_are_refused_before_any_stage_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let job = job_with(dir.path(), &[]);
    for (set, want) in [
        ("toolpath.feed_mm_min=0.01", "feed_mm_min"),
        ("toolpath.feed_mm_min=1e9", "feed_mm_min"),
        ("toolpath.feed_mm_min=-1", "feed_mm_min"),
        ("toolpath.feed_mm_min=nan", "feed_mm_min"),
        ("toolpath.rough_tool=nope", "nope"),
        ("toolpath.tolerance_um=-1", "tolerance_um"),
        ("toolpath.tolerance_um=nan", "tolerance_um"),
        ("toolpath.angle_deg=inf", "angle_deg"),
        ("toolpath.area_mm=[5.0, 5.0, 5.0]", "two numbers"),
        ("toolpath.area_mm=[300.0, 0.6]", "area"),
        ("facets.test_permutations=1000000000", "test_permutations"),
        ("facets.cvt_weight_exponent=0", "cvt_weight_exponent"),
        ("facets.anneal.initial_temperature=inf", "initial_temperature"),
        ("facets.anneal.final_temperature_ratio=2", "final_temperature_ratio"),
        ("facets.seed=\"-1\"", "seed"),
    ] {
        let o = brdfmill(&[
            "run",
            job.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--set",
            set,
        ]);
        refused(&o, &[want], &out);
    }
    // a job name that would break out of the program's header comment
    let job = job_with(
        dir.path(),
        &[("version = 1\n", "version = 1\nname = \"evil)\\nG0 Z-20 (\"\n")],
    );
    let o = brdfmill(&["run", job.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    refused(&o, &["job.toml", "`name`"], &out);
}

/// The seeds a run prints for its candidate arrangements reach 2⁶⁴ − 1, beyond TOML's integers: given back
/// as text they are read (the run then gets past the job's checks; `--until ndf` keeps it short).
#[test]
fn a_printed_seed_above_toml_integers_is_read_back_as_text() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let job = job_with(dir.path(), &[("seed = 1", "seed = \"11400714819323198486\"")]);
    let o = brdfmill(&[
        "run",
        job.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--until",
        "ndf",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn facet_counts_that_wrap_are_refused_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let ndf = dir.path().join("ndf.json");
    let o = brdfmill(&[
        "ndf",
        "--brdf",
        "beckmann:alpha=0.3",
        "--res",
        "32",
        "--out",
        ndf.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = dir.path().join("tile");
    let o = brdfmill(&[
        "facets",
        "--ndf",
        ndf.to_str().unwrap(),
        "--facets",
        "4611686018427387905x4",
        "--out",
        out.to_str().unwrap(),
    ]);
    refused(&o, &["facets"], &out);
    // one column or one row of facets passed the old "at least 4 facets" check and then panicked in the
    // periodic Poisson solver
    for grid in ["1x6", "6x1", "1x1"] {
        let o = brdfmill(&[
            "facets",
            "--ndf",
            ndf.to_str().unwrap(),
            "--facets",
            grid,
            "--out",
            out.to_str().unwrap(),
        ]);
        refused(&o, &["facets", "2×2"], &out);
    }
}

#[test]
fn g_code_numbers_beyond_any_machine_are_refused_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    for (line, want) in [
        (format!("G1 X{} F100", "9".repeat(309)), "line 2"),
        ("G1 Z-1000000000000 F100".to_string(), "line 2"),
        ("G1 Z-1e30 F100".to_string(), "line 2"),
    ] {
        let p = dir.path().join("p.nc");
        std::fs::write(&p, format!("G21 G90 G0 X0 Y0 Z1\n{line}\nM2\n")).unwrap();
        let o = brdfmill(&[
            "simulate",
            p.to_str().unwrap(),
            "--tool",
            "ball:1",
            "--out",
            out.to_str().unwrap(),
        ]);
        refused(&o, &["p.nc", want], &out);
    }
}

#[test]
fn a_csv_too_large_to_integrate_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("huge.csv");
    let mut text = String::new();
    for t in [0.0, 10.0, 20.0, 30.0] {
        for p in [0.0, 90.0, 180.0, 270.0] {
            text.push_str(&format!("{t},{p},1e308\n"));
        }
    }
    std::fs::write(&csv, text).unwrap();
    let out = dir.path().join("ndf");
    let spec = format!("csv:{}", csv.display());
    let o = brdfmill(&["ndf", "--brdf", &spec, "--out", out.join("ndf.json").to_str().unwrap()]);
    refused(&o, &["huge.csv", "too large"], &out);
}

/// Fields of a `tensor_file` (RGL `.bsdf`): name → (offset of its shape in the header, offset of its data).
fn tensor_fields(b: &[u8]) -> Vec<(String, usize, usize, Vec<u64>)> {
    let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]) as usize;
    let n = u32::from_le_bytes(b[14..18].try_into().unwrap()) as usize;
    let mut o = 18;
    let mut out = vec![];
    for _ in 0..n {
        let l = u16_at(o);
        let name = String::from_utf8(b[o + 2..o + 2 + l].to_vec()).unwrap();
        o += 2 + l;
        let nd = u16_at(o);
        let data = u64::from_le_bytes(b[o + 3..o + 11].try_into().unwrap()) as usize;
        o += 11;
        let shape = (0..nd)
            .map(|k| u64::from_le_bytes(b[o + 8 * k..o + 8 * k + 8].try_into().unwrap()))
            .collect();
        out.push((name, o, data, shape));
        o += 8 * nd;
    }
    out
}

#[test]
fn rgl_files_that_would_be_misread_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let real = std::fs::read(root().join("tests/data/rgl/paper_white_rgb.bsdf")).unwrap();
    let fields = tensor_fields(&real);
    let field = |name: &str| fields.iter().find(|f| f.0 == name).unwrap().clone();
    let mut cases: Vec<(Vec<u8>, &str)> = vec![];
    // theta_i out of order: swap its second and third values (f32)
    let (_, _, t, _) = field("theta_i");
    let mut b = real.clone();
    let (x, y) = (b[t + 4..t + 8].to_vec(), b[t + 8..t + 12].to_vec());
    b[t + 4..t + 8].copy_from_slice(&y);
    b[t + 8..t + 12].copy_from_slice(&x);
    cases.push((b, "theta_i"));
    // the ndf's shape declared [128, 2] instead of [2, 128] (same data size)
    let (_, s, _, shape) = field("ndf");
    assert_eq!(shape, [2, 128]);
    let mut b = real.clone();
    b[s..s + 8].copy_from_slice(&128u64.to_le_bytes());
    b[s + 8..s + 16].copy_from_slice(&2u64.to_le_bytes());
    cases.push((b, "ndf"));
    // an ndf of 3e38 everywhere
    let (_, _, d, _) = field("ndf");
    let mut b = real.clone();
    for k in 0..256 {
        b[d + 4 * k..d + 4 * k + 4].copy_from_slice(&3e38f32.to_le_bytes());
    }
    cases.push((b, "ndf"));
    let out = dir.path().join("ndf");
    for (k, (bytes, want)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("bad{k}.bsdf"));
        std::fs::write(&p, bytes).unwrap();
        let spec = format!("rgl:{}", p.display());
        let o = brdfmill(&["ndf", "--brdf", &spec, "--out", out.join("ndf.json").to_str().unwrap()]);
        refused(&o, &[&format!("bad{k}.bsdf"), want], &out);
    }
}

#[test]
fn an_integer_npy_names_its_path_once() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("i32.npy");
    std::fs::write(&p, npy_bytes("<i4", "(4, 4)", &[0u8; 64])).unwrap();
    let out = dir.path().join("a");
    let o = brdfmill(&[
        "analyze",
        p.to_str().unwrap(),
        "--pitch-um",
        "5",
        "--out",
        out.to_str().unwrap(),
    ]);
    refused(&o, &["i32.npy", "float64 or float32"], &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.matches("i32.npy").count(), 1, "{err}");
}

/// A reader that goes away (`brdfmill run … | head -2`) does not end the run: its progress lines are
/// dropped, not a panic on the broken pipe, and the stage finishes with its files and exit code.
#[test]
fn a_closed_standard_output_does_not_end_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let job = job_with(dir.path(), &[]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args([
            "run",
            job.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--until",
            "ndf",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("ndf.json").is_file());
    let run = std::fs::read_to_string(out.join("run.json")).unwrap();
    assert!(!run.contains("\"running\""), "{run}");
}

/// A .npy header whose shape multiplies past 2⁶⁴ (2⁶² × 4 wraps to 0, so the 4096 values that follow
/// passed for it and the reader indexed beyond them: a panic) is refused, naming the file and the shape.
#[test]
fn an_npy_shape_that_wraps_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for shape in ["(4611686018427388928, 4)", "(4294967296, 4294967296)"] {
        let values: Vec<f64> = (0..4096).map(|k| k as f64 * 1e-3).collect();
        let npy = dir.path().join("wrap.npy");
        std::fs::write(&npy, npy_f64(shape, &values)).unwrap();
        let o = brdfmill(&[
            "analyze",
            npy.to_str().unwrap(),
            "--pitch-um",
            "5",
            "--out",
            out.to_str().unwrap(),
        ]);
        refused(&o, &["wrap.npy", "shape"], &out);
    }
}

/// A .npy (version 1.0) of type `descr` and `shape` (their header text, e.g. `<f8` and `(64, 64)`) holding
/// `payload`: magic (6) + version (2) + length (2) + header, a multiple of 64 bytes ending in a newline.
fn npy_bytes(descr: &str, shape: &str, payload: &[u8]) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes.extend(payload);
    bytes
}

/// A little-endian float64 .npy of `shape` holding `values`.
fn npy_f64(shape: &str, values: &[f64]) -> Vec<u8> {
    let payload: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    npy_bytes("<f8", shape, &payload)
}

/// Heights so large that their plane or slopes overflow (1e300 mm; big-endian data read as little can
/// read as such) used to give NaN figures, a report and exit 0; a pitch of 1e300 µm the same. Both are
/// refused, naming the file.
#[test]
fn a_surface_whose_figures_would_overflow_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let huge: Vec<f64> = (0..64 * 64).map(|k| (k % 64) as f64 * 1e300).collect();
    let npy = dir.path().join("huge.npy");
    std::fs::write(&npy, npy_f64("(64, 64)", &huge)).unwrap();
    let o = brdfmill(&[
        "analyze",
        npy.to_str().unwrap(),
        "--pitch-um",
        "5",
        "--out",
        out.to_str().unwrap(),
    ]);
    refused(&o, &["huge.npy", "overflow"], &out);
    let fine: Vec<f64> = (0..64 * 64).map(|k| ((k % 64) as f64 * 0.3).sin() * 1e-3).collect();
    std::fs::write(&npy, npy_f64("(64, 64)", &fine)).unwrap();
    for pitch in ["1e300", "1e-300"] {
        let o = brdfmill(&[
            "analyze",
            npy.to_str().unwrap(),
            "--pitch-um",
            pitch,
            "--out",
            out.to_str().unwrap(),
        ]);
        refused(&o, &["huge.npy", "--pitch-um"], &out);
    }
}

/// `simulate --max-cells` raised past what memory holds (it once asked for 3.2 PB and aborted with exit
/// 134) is refused, naming the option.
#[test]
fn a_stock_limit_beyond_memory_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let nc = dir.path().join("p.nc");
    std::fs::write(&nc, "G21 G90\nG0 X0 Y0 Z1\nG1 Z-0.1 F100\nX1\n").unwrap();
    let out = dir.path().join("out");
    let o = brdfmill(&[
        "simulate",
        nc.to_str().unwrap(),
        "--tool",
        "ball:1",
        "--pitch-um",
        "0.0001",
        "--max-cells",
        "18446744073709551615",
        "--out",
        out.to_str().unwrap(),
    ]);
    refused(&o, &["p.nc", "max_cells"], &out);
}

/// An output that cannot be written where it is asked for (a file path that is a folder, a folder path
/// that is a file) is refused before any work: `ndf --png DIR` used to write ndf.json first.
#[test]
fn outputs_that_cannot_be_written_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("x.json");
    let o = brdfmill(&[
        "ndf",
        "--brdf",
        "beckmann:alpha=0.2",
        "--res",
        "32",
        "--out",
        json.to_str().unwrap(),
        "--png",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--png"));
    assert!(!json.exists(), "ndf.json was written before the refusal");
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    let nc = dir.path().join("p.nc");
    std::fs::write(&nc, "G21 G90\nG0 X0 Y0 Z1\nG1 Z-0.1 F100\nX1\n").unwrap();
    for out in [file.clone(), file.join("sub")] {
        let o = brdfmill(&[
            "simulate",
            nc.to_str().unwrap(),
            "--tool",
            "ball:1",
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            o.status.code() == Some(1) && err.contains("--out") && err.contains("is a file"),
            "{err}"
        );
    }
}
