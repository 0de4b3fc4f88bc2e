//! A second run-time planner for the tests: GRBL's, limited to its block buffer (issue 35's check of the
//! estimate).

use brdfmill::cut::machine::Machine;
use brdfmill::gcode::moves::{Move, P3};

/// A second planner: GRBL's, limited to a buffer of `BUFFER` blocks — each block may enter only as fast as
/// the machine can still stop by the end of the last block in the buffer (GRBL plans the newest block to
/// end at rest), with the same per-axis speed and acceleration limits and junction deviation. Time in s.
pub fn planner_with_buffer(moves: &[Move], start: P3, m: &Machine) -> f64 {
    const BUFFER: usize = 15;
    let l = &m.limits;
    struct S {
        len: f64,
        dir: P3,
        v: f64,
        a: f64,
        stop_before: bool,
    }
    let mut segs: Vec<S> = vec![];
    let mut at = start;
    let mut dwell = 0.0;
    let mut stop = true;
    for mv in moves {
        let (p, f, rapid) = match *mv {
            Move::Rapid(p) => (p, 0.0, true),
            Move::Feed(p, f) => (p, f, false),
            Move::Dwell(s) => {
                dwell += s;
                stop = true;
                continue;
            }
            Move::Comment(_) => continue,
            _ => {
                stop = true;
                continue;
            }
        };
        let d = [p[0] - at[0], p[1] - at[1], p[2] - at[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len < 1e-12 {
            continue;
        }
        let dir = [d[0] / len, d[1] / len, d[2] / len];
        let (xy, z) = ((dir[0] * dir[0] + dir[1] * dir[1]).sqrt(), dir[2].abs());
        let mut v: f64 = if rapid { f64::INFINITY } else { f };
        let (vxy, vz) = if rapid {
            (l.rapid_mm_min, l.rapid_z_mm_min)
        } else {
            (f, l.max_feed_z_mm_min.min(f))
        };
        if xy > 1e-12 {
            v = v.min(vxy / xy);
        }
        if z > 1e-12 {
            v = v.min(vz / z);
        }
        let mut a = f64::INFINITY;
        if xy > 1e-12 {
            a = a.min(l.acceleration_mm_s2 / xy);
        }
        if z > 1e-12 {
            a = a.min(l.acceleration_z_mm_s2 / z);
        }
        segs.push(S {
            len,
            dir,
            v: v / 60.0,
            a,
            stop_before: stop,
        });
        stop = false;
        at = p;
    }
    let n = segs.len();
    // junction limits
    let mut junction = vec![0.0; n + 1];
    for k in 1..n {
        let (a, b) = (&segs[k - 1], &segs[k]);
        let cos = -(a.dir[0] * b.dir[0] + a.dir[1] * b.dir[1] + a.dir[2] * b.dir[2]);
        let v = if b.stop_before || cos > 0.999999 {
            0.0
        } else if cos < -0.999999 {
            f64::INFINITY
        } else {
            let s = ((1.0 - cos) / 2.0).sqrt();
            (a.a.min(b.a) * l.path_tolerance_mm * s / (1.0 - s)).sqrt()
        };
        junction[k] = v.min(a.v).min(b.v);
    }
    // entry speed of block k: what the junction allows and what still stops within the buffer after it
    let mut entry = vec![0.0; n + 1];
    for k in 1..n {
        let last = (k + BUFFER - 1).min(n);
        let mut v: f64 = 0.0; // at rest after the newest buffered block
        for j in (k..last).rev() {
            v = (v * v + 2.0 * segs[j].a * segs[j].len).sqrt().min(junction[j]);
        }
        entry[k] = v.min(junction[k]);
    }
    // forward: acceleration from the previous entry
    for k in 0..n {
        let reach = (entry[k] * entry[k] + 2.0 * segs[k].a * segs[k].len).sqrt();
        entry[k + 1] = entry[k + 1].min(reach);
    }
    let mut t = dwell;
    for (k, s) in segs.iter().enumerate() {
        let (v0, v1) = (entry[k], entry[k + 1]);
        let vp = ((2.0 * s.a * s.len + v0 * v0 + v1 * v1) / 2.0).sqrt().min(s.v);
        let cruise = (s.len - (vp * vp - v0 * v0) / (2.0 * s.a) - (vp * vp - v1 * v1) / (2.0 * s.a)).max(0.0);
        t += (vp - v0) / s.a + (vp - v1) / s.a + cruise / vp.max(1e-12);
    }
    t
}
