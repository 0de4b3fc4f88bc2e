//! Machining time from feeds and acceleration: a look-ahead planner in the manner of GRBL's.
//!
//! Each linear move is a segment with a nominal speed (its feed, or the rapid rate) and an acceleration
//! limited by the slowest axis it uses. The speed at a junction is limited by the junction-deviation
//! model (GRBL `$11`): `v² = a·δ·sin(θ/2) / (1 − sin(θ/2))` with θ the angle between the two directions'
//! reversal; a full stop at reversals, spindle and dwell commands. A backward then a forward pass keep every
//! speed change within `v² = v₀² + 2·a·d`; each segment then takes the time of its trapezoid (or triangle).

use super::machine::Machine;
use crate::gcode::moves::{self, Move, P3};

struct Seg {
    /// The motion block (program line) it belongs to: an arc is one block of many chords.
    block: usize,
    len: f64,
    dir: P3,
    v_nom: f64,
    acc: f64,
    rapid: bool,
}

/// Run time of a program and its block rate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Estimate {
    /// Run time with feeds, acceleration and junction deviation only, s.
    pub s: f64,
    /// Run time when each motion block also takes at least `1 / max_blocks_s` (the planner's block rate,
    /// GRBL's ~300 blocks/s on an 8-bit AVR): `Σ max(t_k, 1/rate)`, s. Equal to `s` without a limit.
    pub block_limited_s: f64,
    /// Motion blocks.
    pub blocks: usize,
    /// The most motion blocks that fall in any one second of the unlimited run, blocks/s.
    pub peak_blocks_s: f64,
    /// The part of `s` spent in rapids (`G0`), s.
    pub rapid_s: f64,
}

/// Estimated time of a move list in seconds.
pub fn estimate_s(moves: &[Move], start: P3, machine: &Machine) -> f64 {
    estimate(moves, start, machine, None).s
}

/// Estimated time of a move list, with and without a block-rate limit (`max_blocks_s`), and its peak block
/// rate over a sliding one-second window.
pub fn estimate(moves: &[Move], start: P3, machine: &Machine, max_blocks_s: Option<f64>) -> Estimate {
    let (dwell, seg_times) = segment_times(moves, start, machine);
    let rapid_s = seg_times.iter().filter(|s| s.2).map(|s| s.1).sum();
    // per motion block (an arc's chords are one block)
    let mut times: Vec<f64> = vec![];
    let mut last = usize::MAX;
    for (block, t, _) in seg_times {
        if block == last {
            *times.last_mut().expect("a block was started") += t;
        } else {
            times.push(t);
            last = block;
        }
    }
    let s = dwell + times.iter().sum::<f64>();
    let block_limited_s = match max_blocks_s {
        Some(r) if r > 0.0 => dwell + times.iter().map(|t| t.max(1.0 / r)).sum::<f64>(),
        _ => s,
    };
    // sliding window of one second over the block end times
    let mut ends = Vec::with_capacity(times.len());
    let mut acc = 0.0;
    for t in &times {
        acc += t;
        ends.push(acc);
    }
    let (mut lo, mut peak) = (0usize, 0usize);
    for hi in 0..ends.len() {
        while ends[hi] - ends[lo] > 1.0 {
            lo += 1;
        }
        peak = peak.max(hi - lo + 1);
    }
    Estimate {
        s,
        block_limited_s,
        blocks: times.len(),
        peak_blocks_s: peak as f64,
        rapid_s,
    }
}

/// The dwell total and the planned time of each motion segment with its block and whether it is a rapid, s; an arc is planned as
/// chords within [`moves::CHORD_TOL_MM`] (a controller's arc segments are of that order: GRBL's `$12` is
/// 2 µm), which only changes its junction speeds by the chords' small angles.
fn segment_times(moves: &[Move], start: P3, machine: &Machine) -> (f64, Vec<(usize, f64, bool)>) {
    let l = &machine.limits;
    let mut segs: Vec<Seg> = vec![];
    let mut stops: Vec<usize> = vec![]; // indices of segments that must start from rest
    let mut dwell = 0.0;
    let mut at = start;
    for &(block, ref m) in &moves::chords(moves, start) {
        let (p, speed_mm_min, rapid) = match *m {
            Move::Rapid(p) => (p, 0.0, true),
            Move::Feed(p, f) => (p, f, false),
            Move::Arc(_) => unreachable!("arcs are expanded above"),
            Move::Dwell(s) => {
                dwell += s;
                stops.push(segs.len());
                continue;
            }
            Move::SpindleOn(_) | Move::SpindleOff | Move::ToolChange { .. } | Move::Coolant(_) => {
                stops.push(segs.len());
                continue;
            }
            Move::Comment(_) => continue,
        };
        let d = [p[0] - at[0], p[1] - at[1], p[2] - at[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len < 1e-12 {
            continue;
        }
        let dir = [d[0] / len, d[1] / len, d[2] / len];
        let xy = (dir[0] * dir[0] + dir[1] * dir[1]).sqrt();
        // axis limits: scale the speed so no axis exceeds its own limit
        let (vxy, vz) = if rapid {
            (l.rapid_mm_min, l.rapid_z_mm_min)
        } else {
            (speed_mm_min, l.max_feed_z_mm_min.min(speed_mm_min))
        };
        let mut v = if rapid { f64::INFINITY } else { speed_mm_min };
        if xy > 1e-12 {
            v = v.min(vxy / xy);
        }
        if dir[2].abs() > 1e-12 {
            v = v.min(vz / dir[2].abs());
        }
        let mut acc = f64::INFINITY;
        if xy > 1e-12 {
            acc = acc.min(l.acceleration_mm_s2 / xy);
        }
        if dir[2].abs() > 1e-12 {
            acc = acc.min(l.acceleration_z_mm_s2 / dir[2].abs());
        }
        segs.push(Seg {
            block,
            len,
            dir,
            v_nom: v / 60.0,
            acc,
            rapid,
        });
        at = p;
    }
    let n = segs.len();
    if n == 0 {
        return (dwell, vec![]);
    }
    // entry speed limits (m/s in mm/s) from junctions
    let mut vmax_entry = vec![0.0; n + 1];
    let delta = l.path_tolerance_mm;
    for k in 1..n {
        let (a, b) = (&segs[k - 1], &segs[k]);
        let cos = -(a.dir[0] * b.dir[0] + a.dir[1] * b.dir[1] + a.dir[2] * b.dir[2]);
        let v = if cos > 0.999999 {
            0.0 // reversal
        } else if cos < -0.999999 {
            f64::INFINITY // straight on
        } else {
            let sin_half = ((1.0 - cos) / 2.0).sqrt();
            let acc = a.acc.min(b.acc);
            (acc * delta * sin_half / (1.0 - sin_half)).sqrt()
        };
        vmax_entry[k] = v.min(a.v_nom).min(b.v_nom);
    }
    for &s in &stops {
        if s <= n {
            vmax_entry[s] = 0.0;
        }
    }
    vmax_entry[0] = 0.0;
    vmax_entry[n] = 0.0;
    // backward pass: can decelerate to the next entry
    let mut v = vmax_entry.clone();
    for k in (0..n).rev() {
        let reach = (v[k + 1] * v[k + 1] + 2.0 * segs[k].acc * segs[k].len).sqrt();
        v[k] = v[k].min(reach);
    }
    // forward pass: can accelerate from the previous entry
    for k in 0..n {
        let reach = (v[k] * v[k] + 2.0 * segs[k].acc * segs[k].len).sqrt();
        v[k + 1] = v[k + 1].min(reach);
    }
    let mut times = Vec::with_capacity(n);
    for (k, s) in segs.iter().enumerate() {
        let (v0, v1, vn, a) = (v[k], v[k + 1], s.v_nom, s.acc);
        // peak speed of the trapezoid
        let vp = ((2.0 * a * s.len + v0 * v0 + v1 * v1) / 2.0).sqrt().min(vn);
        let d_acc = (vp * vp - v0 * v0) / (2.0 * a);
        let d_dec = (vp * vp - v1 * v1) / (2.0 * a);
        let d_cruise = (s.len - d_acc - d_dec).max(0.0);
        times.push((
            s.block,
            (vp - v0) / a + (vp - v1) / a + d_cruise / vp.max(1e-12),
            s.rapid,
        ));
    }
    (dwell, times)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine() -> Machine {
        let text =
            std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/grbl-3018.toml"))
                .unwrap();
        Machine::parse(&text).unwrap()
    }

    #[test]
    fn long_straight_move_takes_length_over_feed_plus_ramps() {
        let m = machine();
        let a = m.limits.acceleration_mm_s2;
        let f = 600.0; // 10 mm/s
        let t = estimate_s(&[Move::Feed([100.0, 0.0, 0.0], f)], [0.0; 3], &m);
        // trapezoid: L/v + v/a (one extra v/(2a) for each ramp)
        let exact = 100.0 / 10.0 + 10.0 / a;
        assert!((t - exact).abs() < 1e-9, "{t} vs {exact}");
    }

    #[test]
    fn collinear_split_moves_take_the_same_time_and_corners_cost() {
        let m = machine();
        let one = estimate_s(&[Move::Feed([10.0, 0.0, 0.0], 600.0)], [0.0; 3], &m);
        let split: Vec<Move> = (1..=100)
            .map(|k| Move::Feed([k as f64 * 0.1, 0.0, 0.0], 600.0))
            .collect();
        let two = estimate_s(&split, [0.0; 3], &m);
        assert!((one - two).abs() < 1e-9, "{one} vs {two}");
        let zig: Vec<Move> = (1..=100)
            .map(|k| Move::Feed([k as f64 * 0.1, if k % 2 == 0 { 0.0 } else { 0.1 }, 0.0], 600.0))
            .collect();
        assert!(
            estimate_s(&zig, [0.0; 3], &m) > 1.5 * one,
            "sharp corners slow the machine down"
        );
    }
}
