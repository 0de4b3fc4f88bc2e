//! Cross-check against a peer: the direction of `G2`/`G3` in the `G18` (Z→X) and `G19` (Y→Z) planes, as
//! LinuxCNC's interpreter `rs274` reads it, against brdfmill's G-code reader and against the arcs
//! `brdfmill toolpath` writes.
//!
//! `rs274 -g` prints each arc as `ARC_FEED(first_end, second_end, first_axis, second_axis, rotation, …)` in the
//! plane's own (first, second) axes (Z, X for XZ; Y, Z for YZ), rotation −1 clockwise and +1
//! counter-clockwise in those axes. From the record the test takes the point halfway round the arc and
//! compares it with the reader's chord vertex nearest to it: a mirrored convention puts that point on the
//! other side of the chord, a full sagitta away.

use brdfmill::stages::simulate::gcode::{self, ParseOptions};

/// The (first, second) axes of a canonical plane.
fn axes(plane: &str) -> (usize, usize) {
    match plane {
        "CANON_PLANE_XZ" => (2, 0),
        "CANON_PLANE_YZ" => (1, 2),
        _ => (0, 1),
    }
}

/// One ARC_FEED: the plane's (first, second) axes, the start (x, y, z), the end and the centre in the plane's
/// axes, and the rotation.
type ArcRecord = ((usize, usize), [f64; 3], [f64; 2], [f64; 2], i64);

/// `rs274 -g` on `program`: its arcs.
fn rs274_arcs(program: &str) -> Vec<ArcRecord> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.ngc");
    std::fs::write(&path, program).unwrap();
    let out = std::process::Command::new("rs274")
        .arg("-g")
        .arg(&path)
        .stdin(std::process::Stdio::null())
        .output()
        .expect("rs274 (Debian package linuxcnc-uspace) must be installed for this test");
    let text = String::from_utf8_lossy(&out.stdout);
    let (mut plane, mut at, mut arcs) = ("CANON_PLANE_XY".to_string(), [0.0f64; 3], vec![]);
    let args = |l: &str| -> Vec<f64> {
        let inner = &l[l.find('(').unwrap() + 1..l.rfind(')').unwrap()];
        inner.split(',').filter_map(|v| v.trim().parse().ok()).collect()
    };
    for l in text.lines() {
        if let Some(i) = l.find("SELECT_PLANE(") {
            plane = l[i + 13..l.rfind(')').unwrap()].to_string();
        } else if l.contains("STRAIGHT_FEED(") || l.contains("STRAIGHT_TRAVERSE(") {
            let v = args(l);
            at = [v[0], v[1], v[2]];
        } else if l.contains("ARC_FEED(") {
            let v = args(l);
            let (f, s) = axes(&plane);
            let normal = 3 - f - s;
            let mut end = at;
            end[f] = v[0];
            end[s] = v[1];
            end[normal] = v[5];
            arcs.push(((f, s), at, [v[0], v[1]], [v[2], v[3]], v[4] as i64));
            at = end;
        }
    }
    arcs
}

/// The point halfway round an arc in plane axes (`rotation` −1 clockwise, +1 counter-clockwise).
fn halfway(start: [f64; 2], end: [f64; 2], c: [f64; 2], rotation: i64) -> [f64; 2] {
    let (a0, a1) = (
        (start[1] - c[1]).atan2(start[0] - c[0]),
        (end[1] - c[1]).atan2(end[0] - c[0]),
    );
    let tau = std::f64::consts::TAU;
    let sweep = if rotation < 0 {
        -(a0 - a1).rem_euclid(tau)
    } else {
        (a1 - a0).rem_euclid(tau)
    };
    let r = (start[0] - c[0]).hypot(start[1] - c[1]);
    let a = a0 + sweep / 2.0;
    [c[0] + r * a.cos(), c[1] + r * a.sin()]
}

#[test]
#[ignore = "needs rs274 (linuxcnc-uspace)"]
fn g18_and_g19_arcs_turn_as_linuxcnc_turns_them() {
    // each arc's end on its circle: a G2 and a G3 in each plane, none a half turn (whose side only the
    // direction decides, which is the point)
    let program = "G21 G90 G17\nG1 X0 Y0 Z0 F100\nG18 G2 X2 Z1 I1 K0.5\nG3 X2.8 Z0.6 I0.5 K0\n\
                   G19 G2 Y2 Z1.6 J1 K0.5\nG3 Y2.96 Z1.12 J0.6 K0\nG17\nM2\n";
    let arcs = rs274_arcs(program);
    assert_eq!(arcs.len(), 4, "rs274 read four arcs");
    let ours = gcode::parse(program, &ParseOptions::default()).unwrap();
    for ((f, s), start, end, c, rot) in arcs {
        let mid = halfway([start[f], start[s]], end, c, rot);
        // distance to our chords (which lie within the 0.1 µm arc tolerance of the arc we read)
        let nearest = ours
            .segments
            .iter()
            .map(|sg| {
                let (a, b) = ([sg.from[f], sg.from[s]], [sg.to[f], sg.to[s]]);
                let d = [b[0] - a[0], b[1] - a[1]];
                let l2 = d[0] * d[0] + d[1] * d[1];
                let t = if l2 > 0.0 {
                    (((mid[0] - a[0]) * d[0] + (mid[1] - a[1]) * d[1]) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (a[0] + t * d[0] - mid[0]).hypot(a[1] + t * d[1] - mid[1])
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest < 1e-3,
            "our arc passes {nearest} mm from rs274's halfway point {mid:?}"
        );
    }
}
