//! Cross-check against a peer: the arcs LinuxCNC's RS274/NGC interpreter makes of a program (its ARC_FEED
//! canonical commands, in `tests/data/peers/rs274/*_arcs.csv`, written by `scripts/peer_rs274_arcs.py` with
//! LinuxCNC 2.9's interpreter as Debian packages it) against brdfmill's G-code reader on the same text.
//!
//! * `arcs_mixed.ngc` (checked in, written for this test): every arc form the reader accepts — G2/G3, I/J
//!   relative (G91.1) and absolute (G90.1), R short and long way, P turns, full circles, helices, G91
//!   incremental end points, spaces inside numbers, millimetres and inches. 23 arcs.
//! * LinuxCNC's own `arcspiral.ngc` (999 R-form arcs in inches), read from the Debian package
//!   linuxcnc-uspace where it is installed (as `.ci/run` does): it is GPL-2+, which is not this project's
//!   licence, so only the interpreter's numeric output is checked in, with the program's MD5.
//!
//! The reader's public output is the chords of each arc (kind `Arc`, tagged with the program line), whose
//! vertices lie on the arc: `c + r(cos a, sin a)` at evenly spaced angles, the last vertex the programmed end.
//! From them the test recovers the start (first vertex), the end (last vertex), the centre (circumcentre of
//! three well-spread vertices) and the signed sweep (the sum of the chords' angles about that
//! centre), and compares each with the ARC_FEED record: end and centre, and the sweep that the record's
//! rotation implies (sign: direction; |rotation| − 1: extra full turns).
//!
//! Units: the interpreter's binding gives inches; × 25.4 (the reader multiplies inch words by 25.4, and
//! the binding divides millimetre words by it, so both sides are within a few ulp of the decimal).
//!
//! Tolerances: coordinates are below 60 mm, where one ulp is 7e-15 mm. End points come from the same
//! decimals: 1e-12 mm. Centres: the two sides solve for R-form centres with different algebra (both well
//! conditioned here: R is at least 1.6 × the half chord), and the circumcentre of three vertices spread over
//! a sweep θ (for short arcs: the two ends and the middle) amplifies their rounding by about 8 / (θ/2)² (the
//! sagitta's conditioning): for the shortest sweeps, arcspiral's 0.1 rad, ~3200 × 7e-15 = 2e-11 mm; the test
//! allows 1e-9 mm (1 pm). Sweeps: 1e-9 rad.
//!
//! Measured: arcs_mixed.ngc — ends and starts 8.9e-16 mm, centres 3.6e-15 mm, sweeps 8.9e-15 rad;
//! arcspiral.ngc — ends and starts identical, centres 7.4e-12 mm, sweeps 2.0e-14 rad.

use brdfmill::stages::simulate::gcode::{self, ParseOptions, SegmentKind};
use md5::{Digest, Md5};
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

const INCH: f64 = 25.4;

/// One ARC_FEED record, converted to mm.
struct Record {
    line: usize,
    rotation: i64,
    start: [f64; 3],
    end: [f64; 3],
    centre: [f64; 2],
}

fn peers(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/peers/rs274")
        .join(name)
}

/// The records and the MD5 of the program they came from.
fn records(csv: &Path) -> (Vec<Record>, String) {
    let text = std::fs::read_to_string(csv).unwrap();
    let md5 = text
        .lines()
        .find_map(|l| l.split("(md5 ").nth(1).map(|s| s[..32].to_string()))
        .expect("md5 in the header");
    let recs = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("line"))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let v: Vec<f64> = f[2..].iter().map(|s| s.parse::<f64>().unwrap() * INCH).collect();
            Record {
                line: f[0].parse().unwrap(),
                rotation: f[1].parse().unwrap(),
                start: [v[0], v[1], v[2]],
                end: [v[3], v[4], v[5]],
                centre: [v[6], v[7]],
            }
        })
        .collect();
    (recs, md5)
}

/// What brdfmill's reader made of one arc line: its chord vertices.
struct OurArc {
    vertices: Vec<[f64; 3]>,
}

fn our_arcs(text: &str) -> Vec<(usize, OurArc)> {
    let prog = gcode::parse(text, &ParseOptions::default()).expect("brdfmill reads the program");
    let mut out: Vec<(usize, OurArc)> = vec![];
    for s in prog.segments.iter().filter(|s| s.kind == SegmentKind::Arc) {
        let line = s.line as usize;
        match out.last_mut() {
            Some((l, a)) if *l == line => a.vertices.push(s.to),
            _ => out.push((
                line,
                OurArc {
                    vertices: vec![s.from, s.to],
                },
            )),
        }
    }
    assert_eq!(out.len(), prog.arcs, "one group of chords per arc block");
    out
}

/// Circumcentre of three points in the plane.
fn circumcentre(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 2] {
    // relative to a, for accuracy
    let (bx, by, cx, cy) = (b[0] - a[0], b[1] - a[1], c[0] - a[0], c[1] - a[1]);
    let d = 2.0 * (bx * cy - by * cx);
    let (b2, c2) = (bx * bx + by * by, cx * cx + cy * cy);
    [a[0] + (cy * b2 - by * c2) / d, a[1] + (bx * c2 - cx * b2) / d]
}

/// The centre of the circle through the vertices: the circumcentre of the first vertex, the vertex farthest
/// from it, and the vertex farthest from the line through those two (well spread for any sweep, also for
/// several full turns, where vertices repeat).
fn centre_of(v: &[[f64; 3]]) -> [f64; 2] {
    let a = v[0];
    let d2 = |p: &[f64; 3]| (p[0] - a[0]).powi(2) + (p[1] - a[1]).powi(2);
    let b = *v.iter().max_by(|p, q| d2(p).total_cmp(&d2(q))).unwrap();
    let off = |p: &[f64; 3]| ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])).abs();
    let c = *v.iter().max_by(|p, q| off(p).total_cmp(&off(q))).unwrap();
    circumcentre(a, b, c)
}

/// Signed sweep of the chord polygon about `c` (counter-clockwise positive).
fn sweep_about(v: &[[f64; 3]], c: [f64; 2]) -> f64 {
    v.windows(2)
        .map(|w| {
            let (ax, ay, bx, by) = (w[0][0] - c[0], w[0][1] - c[1], w[1][0] - c[0], w[1][1] - c[1]);
            (ax * by - ay * bx).atan2(ax * bx + ay * by)
        })
        .sum()
}

/// The sweep an ARC_FEED record describes: from start to end in the rotation's direction (a whole turn when
/// they coincide), plus |rotation| − 1 turns.
fn record_sweep(r: &Record) -> f64 {
    let a0 = (r.start[1] - r.centre[1]).atan2(r.start[0] - r.centre[0]);
    let a1 = (r.end[1] - r.centre[1]).atan2(r.end[0] - r.centre[0]);
    let ccw = r.rotation > 0;
    let mut s = if ccw { a1 - a0 } else { a0 - a1 }.rem_euclid(TAU);
    let same = (r.end[0] - r.start[0]).abs() < 1e-9 && (r.end[1] - r.start[1]).abs() < 1e-9;
    if same || s < 1e-12 {
        s = TAU;
    }
    s += TAU * (r.rotation.unsigned_abs() - 1) as f64;
    if ccw {
        s
    } else {
        -s
    }
}

#[derive(Debug)]
struct Worst {
    end: f64,
    start: f64,
    centre: f64,
    sweep: f64,
}

/// Every arc of `text` against its record; the first disagreement beyond the tolerances is the error.
fn compare(name: &str, text: &str, recs: &[Record]) -> Result<Worst, String> {
    let ours = our_arcs(text);
    if ours.len() != recs.len() {
        return Err(format!(
            "{name}: brdfmill read {} arcs, LinuxCNC {}",
            ours.len(),
            recs.len()
        ));
    }
    let mut w = Worst {
        end: 0.0,
        start: 0.0,
        centre: 0.0,
        sweep: 0.0,
    };
    for ((line, arc), r) in ours.iter().zip(recs) {
        if *line != r.line {
            return Err(format!("{name}: arcs on lines {line} and {}", r.line));
        }
        let v = &arc.vertices;
        let (first, last) = (v[0], *v.last().unwrap());
        let d3 = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max);
        let (de, ds) = (d3(last, r.end), d3(first, r.start));
        let n = v.len() - 1;
        if n < 3 {
            return Err(format!("{name} line {line}: only {n} chords"));
        }
        let c = centre_of(v);
        let dc = (c[0] - r.centre[0]).abs().max((c[1] - r.centre[1]).abs());
        let (s_ours, s_theirs) = (sweep_about(v, c), record_sweep(r));
        let dsw = (s_ours - s_theirs).abs();
        if de > 1e-12 {
            return Err(format!("{name} line {line}: end {last:?} vs LinuxCNC {:?}", r.end));
        }
        if ds > 1e-12 {
            return Err(format!("{name} line {line}: start {first:?} vs LinuxCNC {:?}", r.start));
        }
        if dc > 1e-9 {
            return Err(format!(
                "{name} line {line}: centre {c:?} vs LinuxCNC {:?} ({dc:.3e} mm)",
                r.centre
            ));
        }
        if dsw > 1e-9 {
            return Err(format!(
                "{name} line {line}: sweep {s_ours} rad vs {s_theirs} rad from LinuxCNC's rotation {}",
                r.rotation
            ));
        }
        w.end = w.end.max(de);
        w.start = w.start.max(ds);
        w.centre = w.centre.max(dc);
        w.sweep = w.sweep.max(dsw);
    }
    println!(
        "{name}: {} arcs agree with LinuxCNC's ARC_FEED: end {:.1e} mm, start {:.1e} mm, centre {:.1e} mm, \
         sweep {:.1e} rad",
        recs.len(),
        w.end,
        w.start,
        w.centre,
        w.sweep
    );
    Ok(w)
}

fn md5_hex(bytes: &[u8]) -> String {
    Md5::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

#[test]
fn every_arc_form_agrees_with_linuxcnc() {
    let (recs, md5) = records(&peers("arcs_mixed_arcs.csv"));
    let text = std::fs::read_to_string(peers("arcs_mixed.ngc")).unwrap();
    assert_eq!(
        md5_hex(text.as_bytes()),
        md5,
        "arcs_mixed.ngc changed since the records were written"
    );
    assert_eq!(recs.len(), 23);
    // the program exercises both directions, extra turns and helices
    assert!(recs.iter().any(|r| r.rotation < 0) && recs.iter().any(|r| r.rotation > 0));
    assert!(recs.iter().any(|r| r.rotation.abs() >= 2));
    assert!(recs.iter().any(|r| (r.end[2] - r.start[2]).abs() > 1e-3));
    compare("arcs_mixed.ngc", &text, &recs).unwrap();
}

#[test]
#[ignore = "needs linuxcnc-uspace (its sample program arcspiral.ngc, GPL, is not checked in)"]
fn linuxcnc_arcspiral_agrees_with_linuxcnc() {
    const NGC: &str = "/usr/share/linuxcnc/ncfiles/arcspiral.ngc";
    let (recs, md5) = records(&peers("arcspiral_arcs.csv"));
    assert_eq!(recs.len(), 999);
    let bytes = std::fs::read(NGC)
        .unwrap_or_else(|e| panic!("{NGC} (Debian package linuxcnc-uspace) is required by this test: {e}"));
    assert_eq!(
        md5_hex(&bytes),
        md5,
        "{NGC} is not the file the records were written from"
    );
    compare("arcspiral.ngc", &String::from_utf8(bytes).unwrap(), &recs).unwrap();
}

/// The comparison can fail: the same records against the program with one arc's direction flipped, one
/// R arc taken the long way, or one fewer turn.
#[test]
fn a_changed_direction_way_or_turn_count_is_seen() {
    let (recs, _) = records(&peers("arcs_mixed_arcs.csv"));
    let text = std::fs::read_to_string(peers("arcs_mixed.ngc")).unwrap();
    for (from, to) in [
        ("G2 X10 Y0 R10", "G3 X10 Y0 R10"),
        ("G3 X4 Y-3 R7.5", "G3 X4 Y-3 R-7.5"),
        ("I-5 J0 P3", "I-5 J0 P2"),
    ] {
        let changed = text.replacen(from, to, 1);
        assert_ne!(changed, text, "{from} is not in the program");
        let e = compare("changed", &changed, &recs).expect_err(&format!("{from} → {to} went unnoticed"));
        println!("{from} → {to}: {e}");
    }
}
