//! Drop-cutter: the cutter-location (CL) surface of a bit over a heightfield (DESIGN.md §4).
//!
//! For a ball of radius `r` the tool-tip height above `(x, y)` is the dilation of the design by the ball's
//! lower hemisphere, `CL(x, y) = max_{|u| ≤ r} h(x + u) + sqrt(r² − |u|²) − r`, taken over the design's
//! samples: the ball then touches the design at a sample and is on or above every sample it covers, so it
//! never gouges the sampled design. Between samples the ball's own curvature bounds the miss by
//! `pitch² / (4r)` (0.05 µm for a 1 mm ball at 10 µm pitch). Any [`Shape`] works the same way with its own
//! underside `b(ρ)` in place of the hemisphere (a flat end mill's disc takes a sliding maximum instead).
//!
//! Rows are computed as a sum of 1D passes: for each design row within `r` of the output row, the run of
//! column offsets `dx` within the circle is one max-plus correlation of that row with `b(dx, dy)`
//! (`crate::cut::morphology::max_plus`, sixteen outputs at a time in registers, with the CPU's widest vector
//! instructions), and output rows run in parallel with rayon.

use crate::base::heightfield::Heightfield;
use crate::cut::morphology::{max_plus, pad_row};
use crate::cut::tool::Shape;
use rayon::prelude::*;

/// How samples outside the heightfield are seen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    /// Wrap around (a periodic tile).
    Periodic,
    /// Nothing there (the tool may go down): samples outside are ignored.
    Open,
}

/// A drop-cutter over one heightfield.
pub struct DropCutter<'a> {
    hf: &'a Heightfield,
    cutter: Shape,
    edge: Edge,
    /// Column offsets reach: `m = ceil(r / pitch) + 1` (one spare column for rounding at the rim).
    m: usize,
}

impl<'a> DropCutter<'a> {
    /// Prepare a drop-cutter.
    pub fn new(hf: &'a Heightfield, cutter: Shape, edge: Edge) -> Self {
        let m = (cutter.radius_mm() / hf.pitch_mm).ceil() as usize + 1;
        Self { hf, cutter, edge, m }
    }

    /// The bit.
    pub fn cutter(&self) -> Shape {
        self.cutter
    }

    /// Columns `i0 − m ..` of row `j` (any integer) into `buf`: the row seen by output columns `i0 ..
    /// i0 + buf.len() − 2m`.
    fn padded_row(&self, j: isize, i0: usize, buf: &mut [f64]) -> bool {
        let (nx, ny, m) = (self.hf.nx, self.hf.ny as isize, self.m);
        let jj = match self.edge {
            Edge::Periodic => j.rem_euclid(ny) as usize,
            Edge::Open if j < 0 || j >= ny => return false,
            Edge::Open => j as usize,
        };
        let row = &self.hf.z_mm[jj * nx..(jj + 1) * nx];
        // buf[k] is column i0 + k − m
        pad_row(row, i0 as isize - m as isize, self.edge == Edge::Periodic, buf);
        true
    }

    /// CL tip heights along the row at `y` (mm, any value), at the sample columns `x_i = (i + ½)·pitch`.
    /// Columns where the cutter covers no sample are `-∞`.
    pub fn row(&self, y: f64, out: &mut [f64]) {
        assert_eq!(out.len(), self.hf.nx);
        self.row_from(y, 0, out);
    }

    /// CL tip heights at the columns `i0 .. i0 + out.len()` of the row at `y` (the same values [`Self::row`]
    /// gives there, computed over only the samples those columns' cutters cover).
    pub fn row_from(&self, y: f64, i0: usize, out: &mut [f64]) {
        let (nx, p, m, r) = (out.len(), self.hf.pitch_mm, self.m, self.cutter.radius_mm());
        out.iter_mut().for_each(|v| *v = f64::NEG_INFINITY);
        let mut buf = vec![0.0; nx + 2 * m];
        let mut kern: Vec<f64> = Vec::with_capacity(2 * m + 1);
        let jc = y / p - 0.5;
        let (j0, j1) = ((jc - r / p).floor() as isize, (jc + r / p).ceil() as isize);
        for j in j0..=j1 {
            let dy = (j as f64 + 0.5) * p - y;
            let rho2 = r2_incl(r) - dy * dy;
            if rho2 < 0.0 || !self.padded_row(j, i0, &mut buf) {
                continue;
            }
            match self.cutter {
                Shape::Ball { .. } | Shape::Bull { .. } => {
                    // the offsets within the circle are one run of columns, `dx² ≤ ρ²` from its first
                    let first = (-(m as isize)..=(m as isize)).find(|&di| (di as f64 * p).powi(2) <= rho2);
                    let Some(first) = first else { continue };
                    kern.clear();
                    kern.extend((first..=(m as isize)).map_while(|di| {
                        let dx = di as f64 * p;
                        (dx * dx <= rho2).then(|| -self.cutter.profile_sq(dx * dx + dy * dy))
                    }));
                    let k0 = (m as isize + first) as usize;
                    max_plus(out, &buf[k0..k0 + nx + kern.len() - 1], &kern);
                }
                Shape::Flat { .. } => {
                    let mut w = (rho2.sqrt() / p).floor() as usize;
                    while ((w + 1) as f64 * p).powi(2) <= rho2 {
                        w += 1;
                    }
                    while w > 0 && (w as f64 * p).powi(2) > rho2 {
                        w -= 1;
                    }
                    let w = w.min(m);
                    sliding_max(&buf[m - w..m + w + nx], 2 * w + 1, out);
                }
            }
        }
    }

    /// The CL surface at every sample (rows in parallel), as a heightfield of the same grid.
    pub fn surface(&self) -> Heightfield {
        let (nx, ny, p) = (self.hf.nx, self.hf.ny, self.hf.pitch_mm);
        let mut cl = Heightfield::flat(nx, ny, p, self.hf.periodic, 0.0);
        cl.z_mm
            .par_chunks_mut(nx)
            .enumerate()
            .for_each(|(j, row)| self.row((j as f64 + 0.5) * p, row));
        cl
    }

    /// The CL height at one arbitrary point by direct summation over the samples under the cutter (the slow
    /// reference, and the independent check that a CL point does not gouge): `max h(u) − prof(|u − x|²)`
    /// over the samples with `|u − x|² ≤ r²`, row by row, each row's run of columns taken eight at a time
    /// with the widest vector instructions this CPU has (`pulp`).
    pub fn point(&self, x: f64, y: f64) -> f64 {
        let bit = self.cutter;
        pulp::Arch::new().dispatch(Point {
            dc: self,
            x,
            y,
            prof: move |rho2: f64| bit.profile_sq(rho2),
        })
    }

    /// How far a cutter with its tip at `(x, y, z)` dips below the design (mm, ≤ 0 means no gouge).
    pub fn gouge(&self, x: f64, y: f64, z: f64) -> f64 {
        self.point(x, y) - z
    }
}

/// [`DropCutter::point`]'s sums for one point, with the bit's underside `prof(ρ²)`.
struct Point<'a, F> {
    dc: &'a DropCutter<'a>,
    x: f64,
    y: f64,
    prof: F,
}

impl<F: Fn(f64) -> f64> pulp::WithSimd for Point<'_, F> {
    type Output = f64;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> f64 {
        let Self { dc, x, y, prof } = self;
        let hf = dc.hf;
        let (nx, ny, p, r) = (hf.nx as isize, hf.ny as isize, hf.pitch_mm, dc.cutter.radius_mm());
        let r2 = r2_incl(r);
        let (ic, jc) = (x / p - 0.5, y / p - 0.5);
        let (i_lo, i_hi) = ((ic - r / p).floor() as isize, (ic + r / p).ceil() as isize);
        // dx² of the columns i_lo..=i_hi, the same on every row
        let dx2: Vec<f64> = (i_lo..=i_hi)
            .map(|i| {
                let dx = (i as f64 + 0.5) * p - x;
                dx * dx
            })
            .collect();
        let mut best = f64::NEG_INFINITY;
        for j in (jc - r / p).floor() as isize..=(jc + r / p).ceil() as isize {
            let dy = (j as f64 + 0.5) * p - y;
            let dy2 = dy * dy;
            // no column of this row is within the circle (dx² + dy² ≥ dy² in floating point too)
            if dy2 > r2 {
                continue;
            }
            let jj = match dc.edge {
                Edge::Periodic => j.rem_euclid(ny),
                Edge::Open if j < 0 || j >= ny => continue,
                Edge::Open => j,
            } as usize;
            let row = &hf.z_mm[jj * hf.nx..(jj + 1) * hf.nx];
            // the columns i_lo..=i_hi as runs of the stored row (wrapped, or clipped at open edges)
            let (mut i, end) = match dc.edge {
                Edge::Periodic => (i_lo, i_hi + 1),
                Edge::Open => (i_lo.max(0), (i_hi + 1).min(nx)),
            };
            while i < end {
                let c = i.rem_euclid(nx);
                let n = (nx - c).min(end - i);
                let z = &row[c as usize..(c + n) as usize];
                let k = (i - i_lo) as usize;
                best = best.max(row_max(z, &dx2[k..k + n as usize], dy2, r2, &prof));
                i += n;
            }
        }
        best
    }
}

/// `max_k z[k] − prof(dx2[k] + dy2)` over the `k` with `dx2[k] + dy2 ≤ r2` (−∞ when there is none), in
/// eight independent lanes.
#[inline(always)]
fn row_max(z: &[f64], dx2: &[f64], dy2: f64, r2: f64, prof: &impl Fn(f64) -> f64) -> f64 {
    const L: usize = 8;
    let term = |z: f64, dx2: f64| {
        let d2 = dx2 + dy2;
        let v = z - prof(d2);
        if d2 <= r2 {
            v
        } else {
            f64::NEG_INFINITY
        }
    };
    let mut acc = [f64::NEG_INFINITY; L];
    let (zc, dc) = (z.chunks_exact(L), dx2.chunks_exact(L));
    let (zr, dr) = (zc.remainder(), dc.remainder());
    for (zs, ds) in zc.zip(dc) {
        for l in 0..L {
            let v = term(zs[l], ds[l]);
            acc[l] = if v > acc[l] { v } else { acc[l] };
        }
    }
    for (l, (&zk, &dk)) in zr.iter().zip(dr).enumerate() {
        let v = term(zk, dk);
        acc[l] = if v > acc[l] { v } else { acc[l] };
    }
    acc.iter().fold(f64::NEG_INFINITY, |m, &v| if v > m { v } else { m })
}

/// `r²` widened by a relative 1e-12 so that samples exactly on the cutter's rim are included whichever way
/// the rounding of their offset went (the row and point methods compute offsets differently).
#[inline]
fn r2_incl(r: f64) -> f64 {
    r * r * (1.0 + 1e-12)
}

/// `out[i] = max(out[i], max(src[i..i + w]))` for every `i` (monotonic deque, O(n)).
fn sliding_max(src: &[f64], w: usize, out: &mut [f64]) {
    let mut dq: std::collections::VecDeque<usize> = std::collections::VecDeque::new();
    for k in 0..src.len() {
        while dq.back().is_some_and(|&b| src[b] <= src[k]) {
            dq.pop_back();
        }
        dq.push_back(k);
        if dq[0] + w <= k {
            dq.pop_front();
        }
        if k + 1 >= w {
            let i = k + 1 - w;
            if i < out.len() && src[dq[0]] > out[i] {
                out[i] = src[dq[0]];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_hf(nx: usize, ny: usize, pitch: f64, seed: u64, periodic: bool) -> Heightfield {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut hf = Heightfield::flat(nx, ny, pitch, periodic, 0.0);
        hf.z_mm.iter_mut().for_each(|v| *v = rng.gen_range(-0.3..0.0));
        hf
    }

    #[test]
    fn rows_equal_brute_force_on_random_heightfields() {
        for (seed, periodic, cutter) in [
            (1, true, Shape::Ball { diameter_mm: 0.1 }),
            (2, false, Shape::Ball { diameter_mm: 0.074 }),
            (3, true, Shape::Flat { diameter_mm: 0.08 }),
            (4, false, Shape::Flat { diameter_mm: 0.1 }),
        ] {
            let hf = random_hf(37, 29, 0.01, seed, periodic);
            let edge = if periodic { Edge::Periodic } else { Edge::Open };
            let dc = DropCutter::new(&hf, cutter, edge);
            let cl = dc.surface();
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed + 100);
            let mut row = vec![0.0; hf.nx];
            for j in 0..hf.ny {
                for i in 0..hf.nx {
                    let (x, y) = ((i as f64 + 0.5) * 0.01, (j as f64 + 0.5) * 0.01);
                    assert!((cl.at(i, j) - dc.point(x, y)).abs() < 1e-12, "{cutter:?} ({i},{j})");
                }
            }
            // off-grid rows
            for _ in 0..10 {
                let y = rng.gen_range(0.0..0.29);
                dc.row(y, &mut row);
                for (i, v) in row.iter().enumerate() {
                    assert!((v - dc.point((i as f64 + 0.5) * 0.01, y)).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn column_ranges_equal_the_full_row() {
        for (seed, periodic, cutter) in [
            (5, true, Shape::Ball { diameter_mm: 0.1 }),
            (6, false, Shape::Ball { diameter_mm: 0.074 }),
            (7, false, Shape::Flat { diameter_mm: 0.1 }),
        ] {
            let hf = random_hf(41, 23, 0.01, seed, periodic);
            let edge = if periodic { Edge::Periodic } else { Edge::Open };
            let dc = DropCutter::new(&hf, cutter, edge);
            let mut full = vec![0.0; hf.nx];
            for y in [0.0, 0.0731, 0.2249] {
                dc.row(y, &mut full);
                for (i0, n) in [(0, 1), (0, 41), (3, 9), (20, 21), (40, 1)] {
                    let mut part = vec![0.0; n];
                    dc.row_from(y, i0, &mut part);
                    assert_eq!(part[..], full[i0..i0 + n], "{cutter:?} y {y} from {i0}");
                }
            }
        }
    }

    #[test]
    fn ball_on_a_plane_matches_the_closed_form() {
        // z = a x + b y: the ball centre sits r·sqrt(1 + a² + b²) above the plane, its tip r below that.
        let (a, b, r, p) = (0.3, -0.2, 0.5, 0.01);
        let mut hf = Heightfield::flat(300, 300, p, false, 0.0);
        for j in 0..300 {
            for i in 0..300 {
                hf.z_mm[j * 300 + i] = a * (i as f64 + 0.5) * p + b * (j as f64 + 0.5) * p;
            }
        }
        let dc = DropCutter::new(&hf, Shape::Ball { diameter_mm: 2.0 * r }, Edge::Open);
        let mut row = vec![0.0; 300];
        for y in [1.0, 1.5037, 2.0] {
            dc.row(y, &mut row);
            for (i, got) in row.iter().enumerate().take(240).skip(60) {
                let x = (i as f64 + 0.5) * p;
                let exact = a * x + b * y + r * ((1.0f64 + a * a + b * b).sqrt() - 1.0);
                // discrete contact: below the continuous one by at most the ball's sag over half a pitch
                let err = exact - got;
                assert!((-1e-12..=p * p / (4.0 * r)).contains(&err), "y {y} i {i}: {err}");
            }
        }
    }

    #[test]
    fn ball_on_a_sphere_matches_the_closed_form() {
        // A spherical bump of radius R: the ball centre stays R + r from the sphere's centre.
        let (big_r, r, p, n) = (1.0, 0.25, 0.01, 301);
        let c = (n as f64 * p) / 2.0;
        let mut hf = Heightfield::flat(n, n, p, false, -10.0);
        for j in 0..n {
            for i in 0..n {
                let (x, y) = ((i as f64 + 0.5) * p - c, (j as f64 + 0.5) * p - c);
                let d2 = x * x + y * y;
                if d2 < big_r * big_r {
                    hf.z_mm[j * n + i] = (big_r * big_r - d2).sqrt();
                }
            }
        }
        let dc = DropCutter::new(&hf, Shape::Ball { diameter_mm: 2.0 * r }, Edge::Open);
        for (x, y) in [(0.0, 0.0), (0.3, 0.1), (-0.4, 0.45), (0.6, -0.2)] {
            let (px, py) = (x + c, y + c);
            let rho2 = x * x + y * y;
            let exact = ((big_r + r).powi(2) - rho2).sqrt() - r;
            let got = dc.point(px, py);
            assert!((exact - got).abs() < 2e-4, "({x},{y}): {got} vs {exact}");
        }
    }
}
