//! The design and the simulated cut over the same window, side by side on one height scale, and both along
//! one line across it: the comparison a reader makes first, before any statistic.
//!
//! The design's height at a stock cell is the one [`super::deviation()`] compared with (the tile repeated from
//! the work origin, read bilinearly), recovered as `cut − (cut − design)` from its map, so that the picture
//! and the deviation figures cannot disagree.

use super::{Deviation, Simulation};
use crate::base::heightfield::Heightfield;
use crate::base::plot::{Canvas, LinePlot, Series, PALETTE};

/// Side of the window shown, mm: a few 1 mm facets, drawn at the simulation's own pitch.
pub const WINDOW_MM: f64 = 3.0;

/// Largest side of either relief's raster, px (a finer simulation is box-averaged down to it).
const RELIEF_PX: usize = 1024;

/// The figure and what its caption needs.
#[derive(Clone, Debug)]
pub struct SideBySide {
    /// Design relief, cut relief, the profile of both below them and the profile of their difference.
    pub canvas: Canvas,
    /// The window, work coordinates `[x0, y0, x1, y1]`, mm.
    pub window_mm: [f64; 4],
    /// Work y of the profile, mm.
    pub profile_y_mm: f64,
    /// The design's heights along the profile, from the window's left edge at the pitch, mm.
    pub design_profile_mm: Vec<f64>,
    /// The cut's heights along the profile, mm.
    pub cut_profile_mm: Vec<f64>,
    /// Cut − design over the window's cells the bit can reach: root mean square, µm.
    pub rms_reachable_um: f64,
    /// Share of the window's cells the bit cannot reach (concave corners narrower than it).
    pub unreachable_fraction: f64,
}

/// The design and the cut over a square window of side `window_mm` (less when the assessed interior is
/// smaller) at the centre of the cells [`super::deviation()`] assessed. None when it assessed none, or the
/// design is not defined over the whole window (a design placed once, smaller than the window).
pub fn side_by_side(sim: &Simulation, dev: &Deviation, window_mm: f64) -> Option<SideBySide> {
    let hf = &sim.heightfield;
    if dev.nx != hf.nx || dev.ny != hf.ny || window_mm.is_nan() || window_mm <= 0.0 {
        return None;
    }
    let p = hf.pitch_mm;
    // the assessed cells' bounding box (the interior is a rectangle)
    let (mut i_lo, mut i_hi, mut j_lo, mut j_hi) = (usize::MAX, 0, usize::MAX, 0);
    for (k, v) in dev.map_um.iter().enumerate() {
        if v.is_finite() {
            let (i, j) = (k % hf.nx, k / hf.nx);
            (i_lo, i_hi, j_lo, j_hi) = (i_lo.min(i), i_hi.max(i), j_lo.min(j), j_hi.max(j));
        }
    }
    // at least two cells a side (a relief needs a neighbour to shade by)
    if i_lo > i_hi || j_lo > j_hi || i_hi - i_lo < 1 || j_hi - j_lo < 1 {
        return None;
    }
    let n = ((window_mm / p).round() as usize)
        .min(i_hi - i_lo + 1)
        .min(j_hi - j_lo + 1)
        .max(2);
    let (i0, j0) = ((i_lo + i_hi + 1 - n) / 2, (j_lo + j_hi + 1 - n) / 2);
    let mut cut = Vec::with_capacity(n * n);
    let mut design = Vec::with_capacity(n * n);
    let (mut ss, mut reach, mut unreach) = (0.0, 0usize, 0usize);
    for j in j0..j0 + n {
        for i in i0..i0 + n {
            let k = j * hf.nx + i;
            let d_um = dev.map_um[k] as f64;
            if !d_um.is_finite() {
                return None;
            }
            cut.push(hf.z_mm[k]);
            design.push(hf.z_mm[k] - d_um * 1e-3);
            if dev.unreachable[k] {
                unreach += 1;
            } else {
                ss += d_um * d_um;
                reach += 1;
            }
        }
    }
    let grid = |z_mm: Vec<f64>| Heightfield {
        nx: n,
        ny: n,
        pitch_mm: p,
        periodic: false,
        z_mm,
    };
    let (design, cut) = (grid(design), grid(cut));
    let (dl, dh) = design.range();
    let (cl, ch) = cut.range();
    let range = (dl.min(cl), dh.max(ch));
    let origin = [sim.origin_mm[0] + i0 as f64 * p, sim.origin_mm[1] + j0 as f64 * p];
    let side = n as f64 * p;
    let jm = n / 2;
    let profile_y = origin[1] + (jm as f64 + 0.5) * p;
    let mut panels = [
        design.relief_in(
            "design (the tile, repeated from the work origin)",
            RELIEF_PX,
            origin,
            range,
        ),
        cut.relief_in("simulated cut", RELIEF_PX, origin, range),
    ];
    // the profile's line on both reliefs (their plot areas start 70 px in and 28 px down, 640 px across)
    let py = 28 + 640 - (((profile_y - origin[1]) / side) * 640.0).round() as i32;
    for panel in &mut panels {
        panel.path(vec![(70, py), (70 + 639, py)], [255, 255, 255], 1, true);
    }
    let at = |hf: &Heightfield| -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| (origin[0] + (i as f64 + 0.5) * p, hf.z_mm[jm * n + i] * 1e3))
            .collect()
    };
    let top = Canvas::hstack(&panels);
    let profile = LinePlot {
        title: format!("along the dashed line, y = {profile_y:.3} mm"),
        x_label: "x (mm)".into(),
        y_label: "z (µm)".into(),
        series: vec![
            Series {
                label: "design".into(),
                points: at(&design),
                color: PALETTE[0],
                dashed: false,
            },
            Series {
                label: "simulated cut".into(),
                points: at(&cut),
                color: PALETTE[1],
                dashed: false,
            },
        ],
        size_px: (top.width.saturating_sub(90).max(200), 240),
        log_y: false,
        whole_x: false,
    }
    .render();
    // the difference on its own axis: the few µm the profile's scale hides (scallops, the runout's flat)
    let difference = LinePlot {
        title: "cut − design along the same line".into(),
        x_label: "x (mm)".into(),
        y_label: "µm".into(),
        series: vec![Series {
            label: "simulated cut − design".into(),
            points: (0..n)
                .map(|i| {
                    let k = jm * n + i;
                    (origin[0] + (i as f64 + 0.5) * p, (cut.z_mm[k] - design.z_mm[k]) * 1e3)
                })
                .collect(),
            color: PALETTE[2],
            dashed: false,
        }],
        size_px: (top.width.saturating_sub(90).max(200), 160),
        log_y: false,
        whole_x: false,
    }
    .render();
    let width = top.width.max(profile.width).max(difference.width);
    let mut canvas = Canvas::new(width, top.height + profile.height + difference.height);
    canvas.blit(&top, 0, 0);
    canvas.blit(&profile, 0, top.height as i64);
    canvas.blit(&difference, 0, (top.height + profile.height) as i64);
    Some(SideBySide {
        canvas,
        window_mm: [origin[0], origin[1], origin[0] + side, origin[1] + side],
        profile_y_mm: profile_y,
        design_profile_mm: design.z_mm[jm * n..(jm + 1) * n].to_vec(),
        cut_profile_mm: cut.z_mm[jm * n..(jm + 1) * n].to_vec(),
        rms_reachable_um: if reach > 0 {
            (ss / reach as f64).sqrt()
        } else {
            f64::NAN
        },
        unreachable_fraction: unreach as f64 / (n * n) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::simulate::{deviation, Shape};

    /// A cut that is the design plus a known offset: the window's rms is that offset, the design drawn is
    /// the design sampled directly (cut − offset), and the window sits at the centre of the interior.
    #[test]
    fn design_recovered_and_rms_is_the_offset() {
        let (n, p) = (64usize, 0.05);
        // a smooth periodic design the 0.5 mm ball reaches everywhere (curvature far below 1/r)
        let z: Vec<f64> = (0..n * n)
            .map(|k| {
                let (x, y) = ((k % n) as f64 + 0.5, (k / n) as f64 + 0.5);
                let w = std::f64::consts::TAU / n as f64;
                0.01 * (w * x).sin() * (w * y).cos() - 0.05
            })
            .collect();
        let design = Heightfield {
            nx: n,
            ny: n,
            pitch_mm: p,
            periodic: true,
            z_mm: z,
        };
        // the stock grid: the same pitch over twice the tile, cut 2 µm above the design
        let m = 2 * n;
        let offset_mm = 2e-3;
        let hf = Heightfield {
            nx: m,
            ny: m,
            pitch_mm: p,
            periodic: false,
            z_mm: (0..m * m)
                .map(|k| design.at(k % m % n, k / m % n) + offset_mm)
                .collect(),
        };
        let sim = Simulation {
            heightfield: hf,
            origin_mm: [0.0, 0.0],
            stats: Default::default(),
            tool_cuts: vec![],
        };
        let ball = Shape::Ball { diameter_mm: 0.5 };
        let dev = deviation(&sim, &design, &ball);
        let s = side_by_side(&sim, &dev, 2.0).expect("a window");
        assert!((s.rms_reachable_um - 2.0).abs() < 1e-6, "{}", s.rms_reachable_um);
        assert_eq!(s.unreachable_fraction, 0.0);
        let [x0, y0, x1, y1] = s.window_mm;
        assert!((x1 - x0 - 2.0).abs() < 1e-9 && (y1 - y0 - 2.0).abs() < 1e-9);
        // centred on the interior, which is symmetric about the stock's centre
        assert!(((x0 + x1) / 2.0 - m as f64 * p / 2.0).abs() <= p);
        assert!(s.profile_y_mm > y0 && s.profile_y_mm < y1);
        // the drawn design is the tile itself: its profile is the tile's row under the line
        let (i0, j) = ((x0 / p).round() as usize, (s.profile_y_mm / p - 0.5).round() as usize);
        assert!((s.design_profile_mm[0] - design.at(i0 % n, j % n)).abs() < 1e-9);
    }
}
