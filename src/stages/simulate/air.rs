//! What a program cut and what it fed through air: the feed segments that removed nothing.

use super::{gcode, Simulation};
use crate::cut::sweep;
use crate::cut::tool::Shape;

/// Cutting and air length of feed segments over a stock surface already cut (`before`, on its grid), mm:
/// a segment cuts when its sweep lowers some cell of `before` by more than 1 µm (more than the
/// simplification tolerance, so retracing a surface along slightly different chords is not cutting); every
/// other feed segment is air (it retraces the surface or moves above it).
/// This measures a roughing level against the stock its previous levels left.
pub fn cut_and_air_mm(before: &Simulation, bit: Shape, segs: &[gcode::Segment]) -> (f64, f64) {
    use rayon::prelude::*;
    let hf = &before.heightfield;
    let (x0, y0, p) = (before.origin_mm[0], before.origin_mm[1], hf.pitch_mm);
    segs.par_iter()
        .filter(|s| s.kind != gcode::SegmentKind::Rapid)
        .map(|s| {
            let len = crate::gcode::moves::dist(s.from, s.to);
            let sw = sweep::Sweep::new(bit, s.from, s.to);
            let [fx0, fy0, fx1, fy1] = sw.footprint();
            let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
            let (i0, i1) = (
                clamp(((fx0 - x0) / p).floor(), hf.nx),
                clamp(((fx1 - x0) / p).ceil(), hf.nx),
            );
            let (j0, j1) = (
                clamp(((fy0 - y0) / p).floor(), hf.ny),
                clamp(((fy1 - y0) / p).ceil(), hf.ny),
            );
            let mut row = vec![0.0; i1.saturating_sub(i0)];
            for j in j0..j1 {
                let orig = &hf.z_mm[j * hf.nx + i0..j * hf.nx + i1];
                row.copy_from_slice(orig);
                let y = y0 + (j as f64 + 0.5) * p;
                sw.row(y, x0 + (i0 as f64 + 0.5) * p, p, &mut row);
                if row.iter().zip(orig).any(|(a, b)| *a < b - sweep::CUT_MM) {
                    return (len, 0.0);
                }
            }
            (0.0, len)
        })
        // added in program order, whatever the schedule
        .collect::<Vec<_>>()
        .into_iter()
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// Feed segments (`G1` and arc chords) that removed nothing when they ran (`cut` lists, ascending, those that
/// did): their length, mm, and their time at the programmed feed, s (no acceleration: a lower bound).
pub fn air_feeds(segments: &[gcode::Segment], cut: &[usize]) -> (f64, f64) {
    let mut next = cut.iter().peekable();
    let (mut mm, mut s) = (0.0, 0.0);
    for (k, seg) in segments.iter().enumerate() {
        while next.next_if(|&&c| c < k).is_some() {}
        if next.peek() == Some(&&k) || seg.kind == gcode::SegmentKind::Rapid {
            continue;
        }
        let len = crate::gcode::moves::dist(seg.from, seg.to);
        mm += len;
        if seg.feed_mm_min > 0.0 {
            s += 60.0 * len / seg.feed_mm_min;
        }
    }
    (mm, s)
}
