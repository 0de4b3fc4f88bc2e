//! The chords a controller cuts instead of the curve a program asks for, on a cutter-location (CL) grid:
//! the design loop's model of GRBL's arcs (docs/MACHINE.md §3.1, DESIGN.md §4.3).
//!
//! GRBL's `mc_arc` replaces every `G2`/`G3` with straight segments whose vertices lie on the arc: `⌊A/L⌋` of
//! them for an arc `A` long, `L = 2√(t(2R − t))` the chord whose sagitta is `$12` = `t`. Along a finishing
//! pass the bit's centre then follows a polyline, and the surface it leaves holds one slope per segment
//! where the arc swept a range of them. A segment of angle `Δθ = 2√(2t/R)` on a path of radius `R` loses
//! the variance of a uniform spread of width `Δθ`, `Δθ²/12 = 2t/(3R)` of squared slope: a millimetre-scale
//! bow at `t` = 1 µm loses a few 10⁻⁴, a few percent of a narrow lobe's variance along the passes. The model
//! replaces each pass of the CL surface with chords whose sagitta stays within `t`, vertices on the CL
//! samples, taken greedily from the pass's start: on a long arc GRBL's segments are that long. The count
//! is rounded down, so GRBL's are never shorter: an arc between `L` and `2L` long is one chord of sagitta
//! up to `4t`, which the model does not see (the ball's own radius over a facet edge is such an arc). The
//! program's lines chord the CL surface too (the one-sided simplification, within
//! `toolpath.tolerance_um`): the job gives the design loop `t` as that tolerance plus `$12`
//! (`job::stages`, an approximation measured in DESIGN.md §4.3).

use rayon::prelude::*;

/// The direction of the finishing passes the chords are taken along.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassAxis {
    /// Passes along x (the grid's rows).
    X,
    /// Passes along y (the grid's columns).
    Y,
}

impl PassAxis {
    /// The axis of passes at `angle_deg` from x, when they run along a grid axis (within 10⁻⁶°).
    #[must_use]
    pub fn of_angle(angle_deg: f64) -> Option<Self> {
        let a = angle_deg.rem_euclid(180.0);
        if a < 1e-6 || 180.0 - a < 1e-6 {
            Some(Self::X)
        } else if (a - 90.0).abs() < 1e-6 {
            Some(Self::Y)
        } else {
            None
        }
    }
}

/// Chords along the passes: their largest sagitta (the controller's arc tolerance) and their direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassChords {
    /// The largest distance of a chord from the path it replaces, mm (GRBL's `$12`).
    pub sag_mm: f64,
    /// The passes' direction.
    pub along: PassAxis,
}

/// The greatest distance, normal to the chord, of the samples `c[1..n−1]` from the chord `c[0]`–`c[n−1]`,
/// mm (heights in mm, samples `pitch_mm` apart). The samples must be finite ([`chord_pass`] leaves a pass
/// with any that is not alone).
fn chord_sag(c: &[f64], pitch_mm: f64) -> f64 {
    let n = c.len() - 1;
    let (a, b) = (c[0], c[n]);
    let rise = (b - a) / n as f64;
    let slope = rise / pitch_mm;
    // branch-free, so that it compiles to vector instructions
    let mut worst = 0.0f64;
    let mut line = a;
    for v in &c[1..n] {
        line += rise;
        let d = (v - line).abs();
        worst = if d > worst { d } else { worst };
    }
    worst / (1.0 + slope * slope).sqrt()
}

/// A farthest sample `j > i` of `c` whose chord from `i` keeps within `sag_mm` ([`chord_sag`]), searched from
/// `guess` samples on (the previous chord's span: the curvature changes slowly along a pass, so two probes
/// usually settle it): up by doubling steps while chords fit, or down by doubling steps until one fits, then
/// bisection between the last that fitted and the first that did not. `i + 1` always fits. Past an
/// inflection a chord may fit again after one that did not, so the end found is locally, not always
/// globally, the farthest.
fn longest_chord(c: &[f64], i: usize, guess: usize, pitch_mm: f64, sag_mm: f64) -> usize {
    let last = c.len() - 1;
    let fits = |j: usize| chord_sag(&c[i..=j], pitch_mm) <= sag_mm;
    let g = (i + guess.max(2)).min(last);
    // the bracket: `ok` fits, `bad` does not (or lies past the end)
    let (mut ok, mut bad) = (i + 1, last + 1);
    if fits(g) {
        ok = g;
        let mut step = 1;
        while ok < last {
            let j = (ok + step).min(last);
            if fits(j) {
                ok = j;
                step *= 2;
            } else {
                bad = j;
                break;
            }
        }
    } else {
        bad = g;
        let mut step = 1;
        while bad > i + 2 {
            let j = bad.saturating_sub(step).max(i + 1);
            if j == i + 1 || fits(j) {
                ok = j;
                break;
            }
            bad = j;
            step *= 2;
        }
    }
    while bad - ok > 1 {
        let mid = ok + (bad - ok) / 2;
        if fits(mid) {
            ok = mid;
        } else {
            bad = mid;
        }
    }
    ok
}

/// One pass `c` (heights, mm, samples `pitch_mm` apart) replaced by the longest chords from its start whose
/// sagitta is at most `sag_mm` (from each vertex in turn, found by doubling and bisection); the samples
/// between are moved onto the chord. A pass with a sample that is not finite (no surface there) is left as
/// it is. The pass is taken as open: on a periodic grid its first and last samples are vertices.
pub fn chord_pass(c: &mut [f64], pitch_mm: f64, sag_mm: f64) {
    let n = c.len();
    if !c.iter().all(|v| v.is_finite()) {
        return;
    }
    let mut i = 0;
    let mut span = 2;
    while i + 2 < n {
        let ok = longest_chord(c, i, span, pitch_mm, sag_mm);
        let (a, b) = (c[i], c[ok]);
        let len = (ok - i) as f64;
        for (k, v) in c[i + 1..ok].iter_mut().enumerate() {
            *v = a + (b - a) * (k + 1) as f64 / len;
        }
        span = ok - i;
        i = ok;
    }
}

/// The CL grid `cl` (`nx × ny`, row-major, `pitch_mm` apart) with every pass along `chords.along` replaced by
/// its chords ([`chord_pass`]), passes in parallel; `to_sample` writes a height back in the grid's type.
pub fn chord_passes<T: Copy + Into<f64> + Send + Sync>(
    cl: &mut [T],
    nx: usize,
    ny: usize,
    pitch_mm: f64,
    chords: PassChords,
    to_sample: impl Fn(f64) -> T + Sync,
) {
    match chords.along {
        PassAxis::X => cl.par_chunks_mut(nx).for_each_init(
            || vec![0.0; nx],
            |buf, row| {
                buf.iter_mut().zip(row.iter()).for_each(|(b, v)| *b = (*v).into());
                chord_pass(buf, pitch_mm, chords.sag_mm);
                row.iter_mut().zip(buf.iter()).for_each(|(v, b)| *v = to_sample(*b));
            },
        ),
        PassAxis::Y => {
            let columns: Vec<Vec<f64>> = (0..nx)
                .into_par_iter()
                .map(|i| {
                    let mut col: Vec<f64> = (0..ny).map(|j| cl[j * nx + i].into()).collect();
                    chord_pass(&mut col, pitch_mm, chords.sag_mm);
                    col
                })
                .collect();
            cl.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
                row.iter_mut().zip(&columns).for_each(|(v, col)| *v = to_sample(col[j]));
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_angle_names_the_axis_of_the_passes() {
        assert_eq!(PassAxis::of_angle(0.0), Some(PassAxis::X));
        assert_eq!(PassAxis::of_angle(180.0), Some(PassAxis::X));
        assert_eq!(PassAxis::of_angle(-90.0), Some(PassAxis::Y));
        assert_eq!(PassAxis::of_angle(270.0), Some(PassAxis::Y));
        assert_eq!(PassAxis::of_angle(45.0), None);
    }

    /// On a circle of radius R the chords of sagitta t span `2√(t(2R − t))` each (the segment `mc_arc`
    /// rounds its count to, on a long arc), every chord's vertices on the circle and its samples within t of
    /// it; and the slope variance the chords leave is the circle's less `Δθ²/12` (the module's loss), to the
    /// sampling.
    #[test]
    fn chords_of_a_circle_have_the_sagittas_length_and_lose_the_closed_form_variance() {
        let (r, t, pitch) = (2.0, 0.001, 0.0005);
        let half = 1.0; // x from −1 to 1 mm: slopes up to tan 30°
        let n = (2.0 * half / pitch) as usize + 1;
        let x: Vec<f64> = (0..n).map(|k| -half + k as f64 * pitch).collect();
        let z: Vec<f64> = x.iter().map(|x| (r * r - x * x).sqrt()).collect();
        let mut c = z.clone();
        chord_pass(&mut c, pitch, t);
        // the vertices: the samples the chords left where they were (interior ones: a kink)
        let vertices: Vec<usize> = (1..n - 1)
            .filter(|&k| {
                let (a, b) = ((c[k] - c[k - 1]) / pitch, (c[k + 1] - c[k]) / pitch);
                (a - b).abs() > 1e-9
            })
            .collect();
        assert!(vertices.len() > 5, "{} vertices", vertices.len());
        let chord = 2.0 * (t * (2.0 * r - t)).sqrt();
        for w in vertices.windows(2) {
            let (a, b) = (w[0], w[1]);
            assert!(c[a] == z[a] && c[b] == z[b], "a vertex off the circle");
            let len = ((x[b] - x[a]).powi(2) + (z[b] - z[a]).powi(2)).sqrt();
            // the longest chord on the samples: within one sample (and its slope's stretch) of GRBL's
            assert!(
                len <= chord + 1e-5 && len > chord - 2.5 * pitch,
                "chord {len} against {chord}"
            );
        }
        for k in 0..n {
            let d = (x[k] * x[k] + c[k] * c[k]).sqrt();
            assert!(
                d <= r + 1e-12 && r - d <= t + 1e-9,
                "sample {k} {} inside the circle",
                r - d
            );
        }
        // the slope variance along the interior vertices' span: the circle's, less Δθ²/12 per unit of angle
        let (a, b) = (vertices[0], *vertices.last().unwrap());
        let var = |v: &[f64]| {
            let s: Vec<f64> = v.windows(2).map(|w| (w[1] - w[0]) / pitch).collect();
            let m = s.iter().sum::<f64>() / s.len() as f64;
            s.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / s.len() as f64
        };
        let (whole, cut) = (var(&z[a..=b]), var(&c[a..=b]));
        let dtheta = 2.0 * (2.0 * t / r).sqrt();
        // slope = tan θ: the loss in squared slope is the loss in θ² times about (1 + s²)² ≤ 1.8 here
        let lost = whole - cut;
        let low = dtheta * dtheta / 12.0 * 0.9;
        let high = dtheta * dtheta / 12.0 * 1.8;
        assert!(
            lost > low && lost < high,
            "lost {lost:.3e}, Δθ²/12 = {:.3e}",
            dtheta * dtheta / 12.0
        );
    }

    #[test]
    fn a_straight_pass_is_one_chord_and_columns_follow_rows() {
        // a plane is its own chord; and chords along y are the chords of the transposed grid along x
        let (nx, ny, pitch) = (40, 30, 0.01);
        let mut plane: Vec<f64> = (0..nx * ny).map(|k| 0.3 * (k % nx) as f64 * pitch - 0.1).collect();
        let before = plane.clone();
        let along_x = PassChords {
            sag_mm: 1e-3,
            along: PassAxis::X,
        };
        chord_passes(&mut plane, nx, ny, pitch, along_x, |v| v);
        assert!(plane.iter().zip(&before).all(|(a, b)| (a - b).abs() < 1e-15));
        let bowl = |i: usize, j: usize| {
            let (x, y) = (i as f64 * pitch - 0.2, j as f64 * pitch - 0.15);
            0.5 - (0.25 - x * x - 0.3 * y * y).sqrt()
        };
        let mut by_y: Vec<f64> = (0..nx * ny).map(|k| bowl(k % nx, k / nx)).collect();
        let mut transposed: Vec<f64> = (0..nx * ny).map(|k| bowl(k / ny, k % ny)).collect();
        let along_y = PassChords {
            sag_mm: 2e-4,
            along: PassAxis::Y,
        };
        chord_passes(&mut by_y, nx, ny, pitch, along_y, |v| v);
        let rows = PassChords {
            along: PassAxis::X,
            ..along_y
        };
        chord_passes(&mut transposed, ny, nx, pitch, rows, |v| v);
        for j in 0..ny {
            for i in 0..nx {
                assert_eq!(by_y[j * nx + i], transposed[i * ny + j], "({i}, {j})");
            }
        }
        let moved = (0..nx * ny).filter(|&k| by_y[k] != bowl(k % nx, k / nx)).count();
        assert!(moved > nx * ny / 4, "only {moved} samples moved");
    }
}
