//! Registering a scan of a cut part to the simulated cut (`brdfmill compare`): the rotation and translation
//! in the plane that carry the simulation's frame onto the scan's, and the plane in height (the part's tilt
//! under the instrument, its offset) between them.
//!
//! A simulation point `x` (mm from the simulation's corner) lies at the scan point
//!
//! ```text
//!   X = R(φ)·(x − c_sim) + c_scan + t,    φ = k·90° + θ,
//! ```
//!
//! `c` the grids' centres, and the registered scan is `W(x) = C(X) − (p₀ + p₁·(x − c_sim)ₓ + p₂·(x − c_sim)ᵧ)`,
//! `C` the scan's heights read bilinearly between its points. Found in three steps:
//!
//! 1. **Coarse** (`search.rs`): both box-averaged to at most [`COARSE_CELLS`] cells along the longer side, the
//!    scan levelled; for each quarter turn `k` and each `θ` in ±[`MAX_ANGLE_DEG`] in 1° steps, the
//!    translation of greatest masked normalised cross-correlation of their slopes. The best few distinct peaks are each
//!    refined (step 2) on the two coarsest levels, and the one that leaves the least rms height difference
//!    there goes on: a scan of part of the part can correlate best, coarsely, at a wrong pose.
//! 2. **Fine**: Gauss–Newton on `Σ (W − S)²` over `(θ, t, p)`, level by level of a pyramid (each level half
//!    the cell of the last) down to the simulation's own pitch (Lucas & Kanade 1981).
//! 3. **Result**: the scan (not levelled this time) read onto the simulation's grid, the plane of
//!    `W − S` fitted and removed by least squares over the overlap, the correlation of `W` with `S`, the
//!    rms of `W − S`, and the agreement of their slopes: `Σ ∇W·∇S / √(Σ|∇W|² Σ|∇S|²)` with the gradients
//!    taken as differences across `±slope_step` (a part's heights are dominated by the relief's long
//!    waves, which another design of the same target shares; its slopes are not).
//!
//! A scan at another pitch is first read onto the simulation's (box-averaged when finer). Missing points
//! stay missing: a point of `W` is measured when the four scan points around `X` were.

mod search;

use rayon::prelude::*;

/// Cells along the longer side at the coarse search's level.
pub const COARSE_CELLS: usize = 160;
/// The small angles searched on each side of each quarter turn, degrees.
pub const MAX_ANGLE_DEG: f64 = 5.0;
/// Gauss–Newton iterations at each level of the pyramid, at most.
const ITERATIONS: usize = 12;
/// The scan may be at most this many times the simulated cut's extent along each axis (beyond it the coarse
/// level would leave the cut a few cells).
pub const MAX_EXTENT_RATIO: f64 = 2.0;
/// Coarse peaks refined and judged by what they leave.
const CANDIDATES: usize = 6;

/// A grid of heights with its missing points: cell `(i, j)` at `((i + ½)·pitch, (j + ½)·pitch)` mm.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
    /// Cell side, mm.
    pub pitch_mm: f64,
    /// Heights, mm, row-major (a missing point's value is not read).
    pub z: Vec<f64>,
    /// `valid[k]`: point `k` was measured.
    pub valid: Vec<bool>,
}

impl Grid {
    /// A grid with every point measured.
    pub fn whole(hf: &crate::base::heightfield::Heightfield) -> Self {
        Self {
            nx: hf.nx,
            ny: hf.ny,
            pitch_mm: hf.pitch_mm,
            z: hf.z_mm.clone(),
            valid: vec![true; hf.z_mm.len()],
        }
    }

    /// Measured points.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|v| **v).count()
    }

    /// Mean of the measured points (0 when none).
    pub fn mean(&self) -> f64 {
        let (s, n) = self
            .z
            .iter()
            .zip(&self.valid)
            .filter(|(_, v)| **v)
            .fold((0.0, 0usize), |(s, n), (z, _)| (s + z, n + 1));
        s / n.max(1) as f64
    }

    /// The centre, mm.
    pub fn centre(&self) -> [f64; 2] {
        [
            0.5 * self.nx as f64 * self.pitch_mm,
            0.5 * self.ny as f64 * self.pitch_mm,
        ]
    }

    /// The height at `(x, y)` mm, bilinear between the four points around it; `None` outside or when one
    /// of them is missing.
    #[inline]
    pub fn sample(&self, x: f64, y: f64) -> Option<f64> {
        let (u, v) = (x / self.pitch_mm - 0.5, y / self.pitch_mm - 0.5);
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (i, j) = (u as usize, v as usize);
        if i + 1 >= self.nx || j + 1 >= self.ny {
            return None;
        }
        let (fx, fy) = (u - i as f64, v - j as f64);
        let k = j * self.nx + i;
        let n = self.nx;
        if !(self.valid[k] && self.valid[k + 1] && self.valid[k + n] && self.valid[k + n + 1]) {
            return None;
        }
        let z = &self.z;
        Some((z[k] * (1.0 - fx) + z[k + 1] * fx) * (1.0 - fy) + (z[k + n] * (1.0 - fx) + z[k + n + 1] * fx) * fy)
    }

    /// Box-averaged by `f` (a cell of `f × f` points, measured when at least three quarters of them were).
    pub fn coarsen(&self, f: usize) -> Grid {
        if f <= 1 {
            return self.clone();
        }
        let (nx, ny) = ((self.nx / f).max(1), (self.ny / f).max(1));
        let cells: Vec<(f64, bool)> = (0..nx * ny)
            .into_par_iter()
            .map(|c| {
                let (ci, cj) = (c % nx, c / nx);
                let (mut s, mut n) = (0.0, 0usize);
                for j in cj * f..((cj + 1) * f).min(self.ny) {
                    for i in ci * f..((ci + 1) * f).min(self.nx) {
                        let k = j * self.nx + i;
                        if self.valid[k] {
                            s += self.z[k];
                            n += 1;
                        }
                    }
                }
                (s / n.max(1) as f64, 4 * n >= 3 * f * f)
            })
            .collect();
        Grid {
            nx,
            ny,
            pitch_mm: self.pitch_mm * f as f64,
            z: cells.iter().map(|c| c.0).collect(),
            valid: cells.iter().map(|c| c.1).collect(),
        }
    }

    /// Read onto a grid of pitch `pitch_mm` covering the same extent (box-averaged first where this grid is
    /// at least twice as fine).
    pub fn at_pitch(&self, pitch_mm: f64) -> Grid {
        let f = (pitch_mm / self.pitch_mm).floor() as usize;
        let src = if f >= 2 { self.coarsen(f) } else { self.clone() };
        let (w, h) = (self.nx as f64 * self.pitch_mm, self.ny as f64 * self.pitch_mm);
        let (nx, ny) = (
            ((w / pitch_mm).floor() as usize).max(1),
            ((h / pitch_mm).floor() as usize).max(1),
        );
        let cells: Vec<Option<f64>> = (0..nx * ny)
            .into_par_iter()
            .map(|k| src.sample(((k % nx) as f64 + 0.5) * pitch_mm, ((k / nx) as f64 + 0.5) * pitch_mm))
            .collect();
        Grid {
            nx,
            ny,
            pitch_mm,
            z: cells.iter().map(|c| c.unwrap_or(0.0)).collect(),
            valid: cells.iter().map(Option::is_some).collect(),
        }
    }

    /// The least-squares plane `p₀ + p₁·(x − cₓ) + p₂·(y − cᵧ)` through the measured points, `c` the centre
    /// ([`crate::base::scan::fit_plane`], whose origin is point 0, moved to the centre).
    fn plane(&self) -> [f64; 3] {
        let [a, b, c] = crate::base::scan::fit_plane(&self.z, &self.valid, self.nx, self.pitch_mm).unwrap_or([0.0; 3]);
        let (o, h) = (self.centre(), 0.5 * self.pitch_mm);
        [a + b * (o[0] - h) + c * (o[1] - h), b, c]
    }

    /// This grid with its rows in reverse order: the point at `y` moved to `ny·pitch − y` (a scan whose
    /// instrument counts rows the other way).
    pub fn mirrored(&self) -> Grid {
        let mut g = self.clone();
        for j in 0..self.ny {
            let (to, from) = (j * self.nx, (self.ny - 1 - j) * self.nx);
            g.z[to..to + self.nx].copy_from_slice(&self.z[from..from + self.nx]);
            g.valid[to..to + self.nx].copy_from_slice(&self.valid[from..from + self.nx]);
        }
        g
    }

    /// This grid less its least-squares plane.
    fn levelled(&self) -> Grid {
        let mut g = self.clone();
        crate::base::scan::remove_plane(&mut g.z, &g.valid, g.nx, g.pitch_mm);
        g
    }
}

/// Where the simulation's frame lies in the scan's (module notes).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// Quarter turns `k` of the rotation, 0–3.
    pub quarter_turns: u8,
    /// The small angle `θ` beyond them, degrees.
    pub angle_deg: f64,
    /// The translation `t` in the scan's frame, mm.
    pub shift_mm: [f64; 2],
    /// The plane `(p₀ mm, p₁, p₂)` of the scan's heights over the simulation's.
    pub plane: [f64; 3],
    /// The scan was read mirrored ([`Grid::mirrored`]) before the rotation: its instrument counts rows the
    /// other way.
    #[serde(default)]
    pub mirrored: bool,
}

impl Pose {
    /// The whole rotation `φ`, radians.
    pub fn phi(&self) -> f64 {
        (self.quarter_turns as f64 * 90.0 + self.angle_deg).to_radians()
    }

    /// The whole rotation, degrees in (−180, 180].
    pub fn rotation_deg(&self) -> f64 {
        let d = (self.quarter_turns as f64 * 90.0 + self.angle_deg).rem_euclid(360.0);
        if d > 180.0 {
            d - 360.0
        } else {
            d
        }
    }
}

/// What [`register`] found.
#[derive(Clone, Debug)]
pub struct Registered {
    /// The pose.
    pub pose: Pose,
    /// The coarse search's best normalised cross-correlation.
    pub coarse_correlation: f64,
    /// Correlation of the registered scan with the simulation over their overlap.
    pub correlation: f64,
    /// Agreement of their slopes over the overlap (module notes, step 3): 1 when they are the same.
    pub slope_correlation: f64,
    /// Share of the simulation's cells the scan covers.
    pub coverage: f64,
    /// RMS of the registered scan less the simulation over the overlap, µm.
    pub residual_rms_um: f64,
    /// The scan's tilt against the simulation: the angle of the plane removed, degrees.
    pub tilt_deg: f64,
    /// The registered scan on the simulation's grid (`W`), its points measured where the scan covers them.
    pub scan: Grid,
}

/// A scan that cannot be registered.
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// Too few points to correlate.
    #[error("the {what} has {points} measured points: registration needs at least 16×16")]
    TooSmall {
        /// `scan` or `simulated cut`.
        what: &'static str,
        /// Its measured points.
        points: usize,
    },
    /// The scan is far larger than the simulated cut.
    #[error("the scan is {:.1} × {:.1} mm, more than {MAX_EXTENT_RATIO} times the simulated cut's {:.1} × {:.1} mm along an axis: crop it to the part", scan_mm[0], scan_mm[1], sim_mm[0], sim_mm[1])]
    TooLarge {
        /// The scan's extent, mm.
        scan_mm: [f64; 2],
        /// The simulated cut's, mm.
        sim_mm: [f64; 2],
    },
    /// No pose overlaps enough.
    #[error("no rotation or translation lays the scan over a quarter of the simulated cut (or the cut over a quarter of the scan)")]
    NoOverlap,
}

/// Register `scan` to `sim` (module notes). `sim` is the simulated cut, every point measured; slopes are
/// compared over differences across `±slope_step_mm`.
pub fn register(sim: &Grid, scan: &Grid, slope_step_mm: f64) -> Result<Registered, RegisterError> {
    for (what, g) in [("simulated cut", sim), ("scan", scan)] {
        if g.valid_count() < 256 || g.nx < 16 || g.ny < 16 {
            return Err(RegisterError::TooSmall {
                what,
                points: g.valid_count(),
            });
        }
    }
    let p = sim.pitch_mm;
    // the scan read onto the simulation's pitch: its size bounded before it is made, and checked again
    let extent = [scan.nx as f64 * scan.pitch_mm, scan.ny as f64 * scan.pitch_mm];
    let sim_extent = [sim.nx as f64 * p, sim.ny as f64 * p];
    if (0..2).any(|a| extent[a] > MAX_EXTENT_RATIO * sim_extent[a]) {
        return Err(RegisterError::TooLarge {
            scan_mm: extent,
            sim_mm: sim_extent,
        });
    }
    if (0..2).any(|a| extent[a] < 16.0 * p) {
        return Err(RegisterError::TooSmall {
            what: "scan (less than 16 of the simulated cut's cells across)",
            points: scan.valid_count(),
        });
    }
    let raw = if (scan.pitch_mm / p - 1.0).abs() > 1e-3 {
        scan.at_pitch(p)
    } else {
        scan.clone()
    };
    if raw.valid_count() < 256 || raw.nx < 16 || raw.ny < 16 {
        return Err(RegisterError::TooSmall {
            what: "scan read at the simulated cut's pitch",
            points: raw.valid_count(),
        });
    }
    let level = raw.levelled();
    let longest = sim.nx.max(sim.ny).max(level.nx).max(level.ny);
    let top = longest.div_ceil(COARSE_CELLS).next_power_of_two();
    let (sim_c, scan_c) = (sim.coarsen(top), level.coarsen(top));
    // every level maps about the full grids' centres (a coarse grid may be a cell short of the full one)
    let centres = (sim.centre(), raw.centre());
    if scan_c.valid_count() < 16 {
        return Err(RegisterError::TooSmall {
            what: "scan at the coarse search's level (its cells are the simulated cut's coarsest)",
            points: scan_c.valid_count(),
        });
    }
    let half = (top / 2).max(1);
    let sim_h = sim.coarsen(half);
    let search_at = Coarse {
        sim_c: &sim_c,
        sim_h: &sim_h,
        centres,
        half,
        min_cells: search::MIN_OVERLAP * sim.valid_count().min(level.valid_count()) as f64,
    };
    // the scan as given, and mirrored: the mirrored reading is taken only when it leaves under half the
    // height difference the scan as given does (a part with a mirror symmetry registers either way; at every
    // wrong pose a mirrored scan of an asymmetric part leaves the relief's whole amplitude)
    let mirrored_level = level.mirrored();
    let given = search_at.pick(&scan_c, &level.coarsen(half));
    let mirror = search_at.pick(&mirrored_level.coarsen(top), &mirrored_level.coarsen(half));
    let mirrored = match (&given, &mirror) {
        (Some(g), Some(m)) => m.rms_mm < 0.5 * g.rms_mm,
        (None, Some(_)) => true,
        (_, None) => false,
    };
    let chosen = if mirrored { mirror } else { given }.ok_or(RegisterError::NoOverlap)?;
    let (level, raw) = if mirrored {
        (mirrored_level, raw.mirrored())
    } else {
        (level, raw)
    };
    let (mut pose, ncc) = (chosen.pose, chosen.ncc);
    pose.mirrored = mirrored;
    let mut f = (half / 2).max(1);
    loop {
        let (s, c) = if f > 1 {
            (sim.coarsen(f), level.coarsen(f))
        } else {
            (sim.clone(), level.clone())
        };
        pose = refine(&s, &c, centres, pose, if f > 1 { ITERATIONS } else { ITERATIONS / 3 });
        if f == 1 {
            break;
        }
        f /= 2;
    }
    Ok(finish(sim, &raw, pose, ncc, slope_step_mm))
}

/// The coarse search's shared pieces: the simulated cut at the coarsest level and at the next, the grids'
/// centres, the next level's factor and the least overlap, in full-resolution cells.
struct Coarse<'a> {
    sim_c: &'a Grid,
    sim_h: &'a Grid,
    centres: ([f64; 2], [f64; 2]),
    half: usize,
    min_cells: f64,
}

/// A coarse pose refined on the two coarsest levels, with the rms height difference it leaves there (mm) and
/// its correlation peak.
struct Judged {
    pose: Pose,
    rms_mm: f64,
    ncc: f64,
}

impl Coarse<'_> {
    /// The best pose of a (levelled) scan given at the coarsest level (`scan_c`) and the next (`scan_h`):
    /// for every quarter turn and small angle the correlation peak; the best few distinct peaks each refined
    /// on the two levels and judged by the rms height difference left on the second (a scan of part of the
    /// part can correlate best, coarsely, at a wrong pose — the relief's long waves — which its detail then
    /// refutes). `None` when no peak overlaps enough.
    fn pick(&self, scan_c: &Grid, scan_h: &Grid) -> Option<Judged> {
        let mut searcher = search::Searcher::new(self.sim_c, scan_c, self.centres);
        let steps = (2.0 * MAX_ANGLE_DEG) as i32;
        let mut found: Vec<search::Found> = (0..4u8)
            .flat_map(|k| (0..=steps).map(move |a| (k, -MAX_ANGLE_DEG + a as f64)))
            .filter_map(|(k, angle)| searcher.best(k, angle))
            .collect();
        found.sort_by(|a, b| b.ncc.total_cmp(&a.ncc));
        let mut picks: Vec<search::Found> = vec![];
        for f in found {
            if picks.len() == CANDIDATES {
                break;
            }
            if picks.iter().all(|p| distinct(&p.pose, &f.pose, self.sim_c.pitch_mm)) {
                picks.push(f);
            }
        }
        let area = (self.half * self.half) as f64;
        picks
            .iter()
            .filter_map(|f| {
                let p = refine(self.sim_c, scan_c, self.centres, f.pose, ITERATIONS);
                let p = refine(self.sim_h, scan_h, self.centres, p, ITERATIONS);
                let (rms_mm, cells) = rms_left(self.sim_h, scan_h, self.centres, &p);
                (cells as f64 * area >= self.min_cells && rms_mm.is_finite()).then_some(Judged {
                    pose: p,
                    rms_mm,
                    ncc: f.ncc,
                })
            })
            .min_by(|a, b| a.rms_mm.total_cmp(&b.rms_mm))
    }
}

/// Two coarse poses that are not the same peak: another quarter turn, more than 2.5° apart (a peak is seen
/// from the angles either side of it too), or more than two coarse cells apart.
fn distinct(a: &Pose, b: &Pose, cell_mm: f64) -> bool {
    a.quarter_turns != b.quarter_turns
        || (a.angle_deg - b.angle_deg).abs() > 2.5
        || (a.shift_mm[0] - b.shift_mm[0]).hypot(a.shift_mm[1] - b.shift_mm[1]) > 2.0 * cell_mm
}

/// The rms of `C(X) − plane − S` over the overlap at `pose`, mm, and the cells it covers.
fn rms_left(sim: &Grid, scan: &Grid, (cs, cc): ([f64; 2], [f64; 2]), pose: &Pose) -> (f64, usize) {
    let h = sim.pitch_mm;
    let phi = pose.phi();
    let rot = (phi.cos(), phi.sin());
    let (mut s, mut n) = (0.0, 0usize);
    for k in 0..sim.z.len() {
        let x = [((k % sim.nx) as f64 + 0.5) * h, ((k / sim.nx) as f64 + 0.5) * h];
        let q = map(pose, cs, cc, rot, x);
        if let (true, Some(v)) = (sim.valid[k], scan.sample(q[0], q[1])) {
            let (dx, dy) = (x[0] - cs[0], x[1] - cs[1]);
            let r = v - (pose.plane[0] + pose.plane[1] * dx + pose.plane[2] * dy) - sim.z[k];
            s += r * r;
            n += 1;
        }
    }
    ((s / n.max(1) as f64).sqrt(), n)
}

/// The scan point of simulation point `x`.
#[inline]
fn map(pose: &Pose, cs: [f64; 2], cc: [f64; 2], (c, s): (f64, f64), x: [f64; 2]) -> [f64; 2] {
    let (dx, dy) = (x[0] - cs[0], x[1] - cs[1]);
    [
        c * dx - s * dy + cc[0] + pose.shift_mm[0],
        s * dx + c * dy + cc[1] + pose.shift_mm[1],
    ]
}

/// Gauss–Newton steps on `Σ (C(X) − plane − S)²` over `(θ, t, p)` at one level (module notes, step 2).
#[allow(clippy::needless_range_loop)] // the normal equations' packed triangle reads best with indices
fn refine(sim: &Grid, scan: &Grid, (cs, cc): ([f64; 2], [f64; 2]), mut pose: Pose, iterations: usize) -> Pose {
    let h = sim.pitch_mm;
    for _ in 0..iterations {
        let phi = pose.phi();
        let cs_ = (phi.cos(), phi.sin());
        let rows: Vec<([f64; 21], [f64; 6])> = (0..sim.ny)
            .into_par_iter()
            .map(|j| {
                let mut a = [0.0; 21];
                let mut b = [0.0; 6];
                for i in 0..sim.nx {
                    let k = j * sim.nx + i;
                    if !sim.valid[k] {
                        continue;
                    }
                    let x = [(i as f64 + 0.5) * h, (j as f64 + 0.5) * h];
                    let q = map(&pose, cs, cc, cs_, x);
                    let (Some(v), Some(xp), Some(xm), Some(yp), Some(ym)) = (
                        scan.sample(q[0], q[1]),
                        scan.sample(q[0] + h, q[1]),
                        scan.sample(q[0] - h, q[1]),
                        scan.sample(q[0], q[1] + h),
                        scan.sample(q[0], q[1] - h),
                    ) else {
                        continue;
                    };
                    let g = [(xp - xm) / (2.0 * h), (yp - ym) / (2.0 * h)];
                    let (dx, dy) = (x[0] - cs[0], x[1] - cs[1]);
                    let dq = [-cs_.1 * dx - cs_.0 * dy, cs_.0 * dx - cs_.1 * dy];
                    let r = v - (pose.plane[0] + pose.plane[1] * dx + pose.plane[2] * dy) - sim.z[k];
                    let jr = [g[0] * dq[0] + g[1] * dq[1], g[0], g[1], -1.0, -dx, -dy];
                    let mut n = 0;
                    for p in 0..6 {
                        for q in 0..=p {
                            a[n] += jr[p] * jr[q];
                            n += 1;
                        }
                        b[p] += jr[p] * r;
                    }
                }
                (a, b)
            })
            .collect();
        // added in row order: the same pose every run
        let mut m = [[0.0; 6]; 6];
        let mut rhs = [0.0; 6];
        for (a, b) in &rows {
            let mut n = 0;
            for p in 0..6 {
                for q in 0..=p {
                    m[p][q] += a[n];
                    m[q][p] = m[p][q];
                    n += 1;
                }
                rhs[p] -= b[p];
            }
        }
        for (p, row) in m.iter_mut().enumerate() {
            row[p] *= 1.0 + 1e-9;
        }
        let Some(d) = solve::<6>(m, rhs) else {
            break;
        };
        // a step of at most a cell and a fifth of a degree: the linearisation holds within about a cell
        let step = (d[1] * d[1] + d[2] * d[2]).sqrt();
        let k = if step > h { h / step } else { 1.0 };
        let dtheta = (d[0] * k).clamp(-0.2f64.to_radians(), 0.2f64.to_radians());
        pose.angle_deg += dtheta.to_degrees();
        pose.shift_mm[0] += d[1] * k;
        pose.shift_mm[1] += d[2] * k;
        for p in 0..3 {
            pose.plane[p] += d[3 + p] * k;
        }
        if step * k < 2e-3 * h && dtheta.abs() < 1e-7 {
            break;
        }
    }
    pose
}

/// The scan read onto the simulation's grid at `pose`, the plane of its difference from the simulation
/// removed, and the figures of the fit.
fn finish(sim: &Grid, raw: &Grid, mut pose: Pose, coarse_correlation: f64, slope_step_mm: f64) -> Registered {
    let (cs, cc) = (sim.centre(), raw.centre());
    let h = sim.pitch_mm;
    let phi = pose.phi();
    let rot = (phi.cos(), phi.sin());
    let read: Vec<Option<f64>> = (0..sim.nx * sim.ny)
        .into_par_iter()
        .map(|k| {
            let x = [((k % sim.nx) as f64 + 0.5) * h, ((k / sim.nx) as f64 + 0.5) * h];
            let q = map(&pose, cs, cc, rot, x);
            raw.sample(q[0], q[1])
        })
        .collect();
    let mut w = Grid {
        nx: sim.nx,
        ny: sim.ny,
        pitch_mm: h,
        z: read.iter().map(|v| v.unwrap_or(0.0)).collect(),
        valid: read.iter().map(Option::is_some).collect(),
    };
    let diff = Grid {
        z: w.z.iter().zip(&sim.z).map(|(a, b)| a - b).collect(),
        ..w.clone()
    };
    let plane = diff.plane();
    for (k, z) in w.z.iter_mut().enumerate() {
        let (dx, dy) = (
            ((k % w.nx) as f64 + 0.5) * h - cs[0],
            ((k / w.nx) as f64 + 0.5) * h - cs[1],
        );
        *z -= plane[0] + plane[1] * dx + plane[2] * dy;
    }
    pose.plane = plane;
    let n = w.valid_count().max(1) as f64;
    let (mut sw, mut ss, mut sww, mut sss, mut sws, mut sdd) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for k in 0..w.z.len() {
        if w.valid[k] {
            let (a, b) = (w.z[k], sim.z[k]);
            sw += a;
            ss += b;
            sww += a * a;
            sss += b * b;
            sws += a * b;
            sdd += (a - b) * (a - b);
        }
    }
    let cov = sws - sw * ss / n;
    let den = ((sww - sw * sw / n) * (sss - ss * ss / n)).sqrt();
    let slope_correlation = slope_agreement(&w, sim, ((slope_step_mm / h).round() as usize).max(1));
    Registered {
        pose,
        coarse_correlation,
        correlation: if den > 0.0 { cov / den } else { 0.0 },
        slope_correlation,
        coverage: w.valid_count() as f64 / sim.valid_count().max(1) as f64,
        residual_rms_um: (sdd / n).sqrt() * 1e3,
        tilt_deg: (plane[1].hypot(plane[2])).atan().to_degrees(),
        scan: w,
    }
}

/// `Σ ∇W·∇S / √(Σ|∇W|² Σ|∇S|²)` over the cells whose neighbours `d` away along x and y are measured in `w`.
fn slope_agreement(w: &Grid, sim: &Grid, d: usize) -> f64 {
    let n = w.nx;
    let rows: Vec<[f64; 3]> = (d..w.ny.saturating_sub(d))
        .into_par_iter()
        .map(|j| {
            let mut acc = [0.0; 3];
            for i in d..n.saturating_sub(d) {
                let (l, r, b, t) = (j * n + i - d, j * n + i + d, (j - d) * n + i, (j + d) * n + i);
                if !(w.valid[l] && w.valid[r] && w.valid[b] && w.valid[t]) {
                    continue;
                }
                let gw = [w.z[r] - w.z[l], w.z[t] - w.z[b]];
                let gs = [sim.z[r] - sim.z[l], sim.z[t] - sim.z[b]];
                acc[0] += gw[0] * gs[0] + gw[1] * gs[1];
                acc[1] += gw[0] * gw[0] + gw[1] * gw[1];
                acc[2] += gs[0] * gs[0] + gs[1] * gs[1];
            }
            acc
        })
        .collect();
    let s = rows
        .iter()
        .fold([0.0; 3], |a, r| [a[0] + r[0], a[1] + r[1], a[2] + r[2]]);
    if s[1] > 0.0 && s[2] > 0.0 {
        s[0] / (s[1] * s[2]).sqrt()
    } else {
        0.0
    }
}

/// `A x = b` by Gaussian elimination with partial pivoting; `None` when `A` is singular.
#[allow(clippy::needless_range_loop)] // elimination reads best with indices
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for c in 0..N {
        let p = (c..N).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..N {
            let f = a[r][c] / a[c][c];
            for k in c..N {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; N];
    for r in (0..N).rev() {
        let s: f64 = (r + 1..N).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

#[cfg(test)]
mod tests;
