//! brdfmill's X3P reader on files it did not write (`tests/data/peers/x3p/`, written by
//! `scripts/peer_x3p_independent.py`). Until now X3P was tested by brdfmill's writer feeding its own reader,
//! plus the one real scan; here two independent writers and an independent reader take part:
//!
//! * x3pio 2.0.0 (an ISO 25178-72 reader/writer on PyPI): a float64 file (`D`, Increment 1, missing
//!   points NaN) and an int32 file (`L`, x3pio's own increment, missing points in a `ValidPointsLink` bit
//!   file) of an analytic surface, which the test evaluates in closed form;
//! * a file written by hand from the standard's layout with Python's zipfile/hashlib/xml only: int16 (`I`)
//!   with an Increment and an Offset, `z = Offset + Increment · v`;
//! * the real scan `examples/data/sample-land.x3p` as x3pio reads it (every 97th point).
//!
//! **Increment of floating-point Z data.** The schema documents `Increment` as "needed for incremental axis
//! and integer data types: Increment is the multiplyer of the integer coordinate for the computation of the
//! real coordinate" (openGPS iso5436_2.xsd), and the openGPS reference library adds only `Offset` to a Z value
//! (`ISO5436_2Container::ConvertPointToCoord`): a float Z is metres whatever `CZ/Increment` says. x3pio, on
//! the other hand, multiplies every type by the increment. brdfmill follows the schema and openGPS (with a
//! warning when a float file's increment is not 1), and its writer stores metres; the last test, a
//! hand-written float64 file of metres with `CZ/Increment = 1.0E-6`, checks that rule.

use brdfmill::base::x3p::{self, X3p};
use std::f64::consts::PI;
use std::path::PathBuf;

const NX: usize = 40;
const NY: usize = 24;
const DX: f64 = 1.5e-6;
const DY: f64 = 2.5e-6;
const MISSING: [(usize, usize); 3] = [(3, 2), (17, 11), (39, 23)];

/// The script's surface, metres.
fn z_m(i: usize, j: usize) -> f64 {
    let (x, y) = (i as f64 * DX, j as f64 * DY);
    let (lx, ly) = (60e-6, 60e-6);
    -5e-7 + 2e-6 * (2.0 * PI * 1.5 * x / lx).sin() * (2.0 * PI * y / ly).cos() + 3e-7 * x / lx
}

fn read(name: &str) -> X3p {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/peers/x3p")
        .join(name);
    x3p::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Checks size, spacing and (with `check_validity`) which points are missing, and returns the largest
/// |z_mm − closed form| over the points that are not.
fn check_grid(s: &X3p, name: &str, missing: &[(usize, usize)], check_validity: bool) -> f64 {
    assert_eq!((s.nx, s.ny), (NX, NY), "{name}: size");
    assert!(
        (s.pitch_x_mm - DX * 1e3).abs() < 1e-15 && (s.pitch_y_mm - DY * 1e3).abs() < 1e-15,
        "{name}: spacing"
    );
    let mut worst = 0.0f64;
    for j in 0..NY {
        for i in 0..NX {
            let k = j * NX + i;
            let gone = missing.contains(&(i, j));
            if check_validity {
                assert_eq!(s.valid[k], !gone, "{name}: validity of ({i}, {j})");
            }
            if gone {
                if check_validity {
                    assert!(s.z_mm[k].is_nan(), "{name}: missing ({i}, {j}) is {}", s.z_mm[k]);
                }
            } else {
                worst = worst.max((s.z_mm[k] - z_m(i, j) * 1e3).abs());
            }
        }
    }
    assert_eq!(s.data_checksum_ok, Some(true), "{name}: MD5 of the point data");
    worst
}

#[test]
fn x3pio_float64_file_reads_as_written() {
    let s = read("x3pio-f64.x3p");
    assert_eq!(s.data_type, 'D');
    let worst = check_grid(&s, "x3pio-f64", &MISSING, true);
    println!("x3pio float64: largest |Δz| {worst:.2e} mm (heights up to 2.5e-3 mm)");
    // Stored metres from NumPy's sin, read × 1000 (exact scale): NumPy's and Rust's sin may differ by an
    // ulp, ≈ 4e-22 m at these heights, and × 1000 rounds once: 1e-18 mm is ample.
    assert!(worst <= 1e-18, "{worst:e}");
}

#[test]
fn x3pio_int32_file_heights_read_as_written() {
    let s = read("x3pio-i32.x3p");
    assert_eq!(s.data_type, 'L');
    let worst = check_grid(&s, "x3pio-i32", &MISSING, false);
    // x3pio rounds z / increment to the nearest integer: |Δz| ≤ increment / 2, its increment being
    // 1.1368350445307284e-15 m (the largest height / (2³¹ − 1)).
    let half = 0.5 * 1.1368350445307284e-15 * 1e3;
    println!("x3pio int32: largest |Δz| {worst:.2e} mm (quantisation bound {half:.2e} mm)");
    assert!(worst <= half * (1.0 + 1e-9) + 1e-21, "{worst:e} > {half:e}");
}

#[test]
fn x3pio_int32_file_missing_points_are_invalid() {
    let s = read("x3pio-i32.x3p");
    check_grid(&s, "x3pio-i32", &MISSING, true);
}

#[test]
fn hand_written_int16_file_with_an_offset_reads_as_written() {
    let s = read("hand-i16-offset.x3p");
    assert_eq!(s.data_type, 'I');
    let worst = check_grid(&s, "hand-i16-offset", &[], true);
    // v = round((z − Offset) / 1e-9): |Δz| ≤ 0.5e-9 m = 5e-7 mm, plus rounding of Offset + Increment · v
    println!("hand-written int16 with offset: largest |Δz| {worst:.2e} mm (quantisation bound 5e-7 mm)");
    assert!(worst <= 5e-7 * (1.0 + 1e-9), "{worst:e}");
}

#[test]
fn the_real_scan_reads_as_x3pio_reads_it() {
    let s = x3p::read(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/data/sample-land.x3p")).unwrap();
    let csv = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/peers/x3p/sample-land-x3pio.csv"),
    )
    .unwrap();
    let field = |key: &str| -> f64 {
        let line = csv.lines().nth(1).unwrap();
        let v = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix(&format!("{key}=")))
            .unwrap();
        v.parse().unwrap()
    };
    assert_eq!((s.nx, s.ny), (field("nx") as usize, field("ny") as usize));
    assert!((s.pitch_x_mm - field("x_increment") * 1e3).abs() < 1e-15);
    assert!((s.pitch_y_mm - field("y_increment") * 1e3).abs() < 1e-15);
    assert_eq!(s.invalid_count(), field("invalid") as usize);
    let (mut n, mut worst) = (0, 0.0f64);
    for line in csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("index")) {
        let (k, z) = line.split_once(',').unwrap();
        let (k, z): (usize, f64) = (k.parse().unwrap(), z.parse().unwrap());
        if z.is_nan() {
            assert!(
                !s.valid[k] && s.z_mm[k].is_nan(),
                "point {k}: x3pio has no height, brdfmill {}",
                s.z_mm[k]
            );
        } else {
            assert!(s.valid[k], "point {k}: x3pio has a height, brdfmill marks it invalid");
            // float64 metres × 1000 (brdfmill) against × 1 then × 1000 here: within an ulp
            worst = worst.max((s.z_mm[k] - z * 1e3).abs() / (z * 1e3).abs().max(1e-300));
        }
        n += 1;
    }
    println!("sample-land.x3p: {n} points agree with x3pio to {worst:.1e} relative");
    assert!(n > 2000);
    assert!(worst <= 2.3e-16, "{worst:e}");
}

#[test]
fn float64_metres_with_a_z_increment_read_as_metres() {
    let s = read("hand-f64-inc1e-6.x3p");
    assert_eq!(s.data_type, 'D');
    let worst = check_grid(&s, "hand-f64-inc1e-6", &[], true);
    assert!(worst <= 1e-18, "largest |Δz| {worst:e} mm");
}

/// brdfmill's writer read by x3pio: `brdfmill-f32.x3p` is the script's surface (no missing points) as
/// `x3p::write_as(…, Precision::F32)` writes it (the `sim.x3p` of a run), and `brdfmill-f32-x3pio.csv` every
/// height x3pio read from it. Today's writer must still write those entries (`main.xml`, the point data,
/// the checksum file) byte for byte, decompressed (else the peer read another writer's output: regenerate
/// with `BRDFMILL_BLESS=1` and the script), and x3pio's heights must be the surface to float32 rounding
/// (half an ulp of a float32, 2⁻²⁴ relative), and brdfmill's own reading of the file the same as x3pio's.
#[test]
fn x3pio_reads_brdfmills_float32_file_as_written() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/peers/x3p");
    let hf = brdfmill::base::heightfield::Heightfield {
        nx: NX,
        ny: NY,
        pitch_mm: DX * 1e3,
        periodic: false,
        z_mm: (0..NX * NY).map(|k| z_m(k % NX, k / NX) * 1e3).collect(),
    };
    let tmp = tempfile::tempdir().unwrap();
    let written = tmp.path().join("brdfmill-f32.x3p");
    x3p::write_as(&written, &hf, x3p::Precision::F32).unwrap();
    let kept = dir.join("brdfmill-f32.x3p");
    if std::env::var_os("BRDFMILL_BLESS").is_some() {
        std::fs::copy(&written, &kept).unwrap();
    }
    let entries = |p: &std::path::Path| -> Vec<(String, Vec<u8>)> {
        let mut z = zip::ZipArchive::new(std::fs::File::open(p).unwrap()).unwrap();
        (0..z.len())
            .map(|k| {
                let mut e = z.by_index(k).unwrap();
                let mut v = Vec::new();
                std::io::Read::read_to_end(&mut e, &mut v).unwrap();
                (e.name().to_string(), v)
            })
            .collect()
    };
    assert!(
        entries(&written) == entries(&kept),
        "the writer no longer writes what tests/data/peers/x3p/brdfmill-f32.x3p holds: regenerate it \
         (BRDFMILL_BLESS=1) and the peer's reading (scripts/peer_x3p_independent.py)"
    );
    let s = x3p::read(&written).unwrap();
    assert_eq!(s.data_type, 'F');
    assert!((s.pitch_x_mm - DX * 1e3).abs() < 1e-15);
    let csv = std::fs::read_to_string(dir.join("brdfmill-f32-x3pio.csv")).unwrap();
    let mut n = 0;
    for line in csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("index")) {
        let (k, z) = line.split_once(',').unwrap();
        let (k, z): (usize, f64) = (k.parse().unwrap(), z.parse().unwrap());
        let want = z_m(k % NX, k / NX);
        let bound = want.abs() * 2f64.powi(-24) + 1e-30;
        assert!(
            (z - want).abs() <= bound,
            "point {k}: x3pio {z:e} m, surface {want:e} m"
        );
        // both read the same float32: brdfmill's mm are x3pio's metres × 1000, rounded once
        assert!(
            (s.z_mm[k] - z * 1e3).abs() <= (z * 1e3).abs() * 2.3e-16,
            "point {k}: brdfmill {} mm, x3pio {z:e} m",
            s.z_mm[k]
        );
        n += 1;
    }
    assert_eq!(n, NX * NY, "x3pio read every point");
}
