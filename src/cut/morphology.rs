//! Grey-scale morphology of a heightfield by a tool's underside (DESIGN.md §4): the drop-cutter dilation
//! (the CL surface) and the opening (the surface an infinitely fine raster of the bit leaves). Shared by the
//! simulator's reach check and the design loop's as-milled model, so both see one model of what a bit can
//! reach.

use crate::cut::tool::Shape;
use rayon::prelude::*;

/// Height of the opening above the design beyond which a sample counts as unreachable, µm (covers the
/// sampling of the opening itself, see `simulate::deviation`).
pub const REACH_TOLERANCE_UM: f64 = 0.25;

/// A height sample the max-plus kernels take: `f64`, and `f32` where half the precision (0.12 nm at 1 mm)
/// buys twice the lanes per vector (the design loop's as-milled model, [`opening_f32`]).
pub trait Sample: Copy + PartialOrd + std::ops::Add<Output = Self> + Send + Sync + 'static {
    /// No sample: `−∞`.
    const NONE: Self;
    /// [`max_plus`] for this type, with its own register block.
    fn max_plus(out: &mut [Self], src: &[Self], kernel: &[Self]);
}

impl Sample for f64 {
    const NONE: Self = f64::NEG_INFINITY;
    fn max_plus(out: &mut [Self], src: &[Self], kernel: &[Self]) {
        pulp::Arch::new().dispatch(MaxPlus::<f64, 16> { out, src, kernel });
    }
}

impl Sample for f32 {
    const NONE: Self = f32::NEG_INFINITY;
    fn max_plus(out: &mut [Self], src: &[Self], kernel: &[Self]) {
        pulp::Arch::new().dispatch(MaxPlus::<f32, 32> { out, src, kernel });
    }
}

/// `out[i] = max(out[i], src[i] + b)`: one kernel entry over a run of outputs ([`max_plus`]'s tail). Written
/// as a select (`if v > o { v } else { o }`), which compiles to packed `max` instructions; a conditional
/// store compiled to a compare and branch per element and ran at half the speed.
#[inline(always)]
fn max_add<T: Sample>(out: &mut [T], src: &[T], b: T) {
    for (o, s) in out.iter_mut().zip(src) {
        let v = *s + b;
        *o = if v > *o { v } else { *o };
    }
}

/// `out[i] = max(out[i], max_k src[i + k] + kernel[k])` for every `i`: one row of a max-plus correlation, the
/// inner loop of every ball dilation here and in the drop-cutter (`kernel` is the bit's underside along one
/// row of its footprint, `−prof(√(dx² + dy²))` for consecutive `dx`). `src` holds at least
/// `out.len() + kernel.len() − 1` samples.
///
/// Outputs are taken a block at a time (sixteen `f64`, thirty-two `f32`: four vector registers with AVX2)
/// and held in registers across the whole kernel, so each step is one load of `src`, an add and a `max` (a
/// select, which compiles to packed `max` instructions); the loop that swept all of `out` once per kernel
/// entry also loaded and stored `out` at every step, and that store was its bound. `max` is exact, so the
/// order in which the entries are taken does not change a bit of the result.
pub fn max_plus<T: Sample>(out: &mut [T], src: &[T], kernel: &[T]) {
    T::max_plus(out, src, kernel);
}

/// [`max_plus`]'s arguments, run by `pulp` with the widest vector instructions this CPU has (AVX2 or
/// AVX-512 where present; the baseline x86-64 build has only SSE2's two lanes), `N` outputs per block.
struct MaxPlus<'a, T, const N: usize> {
    out: &'a mut [T],
    src: &'a [T],
    kernel: &'a [T],
}

impl<T: Sample, const N: usize> pulp::WithSimd for MaxPlus<'_, T, N> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        max_plus_lanes::<T, N>(self.out, self.src, self.kernel);
    }
}

/// [`max_plus`]'s loop, inlined into each instruction set's version of its caller.
#[inline(always)]
fn max_plus_lanes<T: Sample, const N: usize>(out: &mut [T], src: &[T], kernel: &[T]) {
    let (n, w) = (out.len(), kernel.len());
    if w == 0 {
        return;
    }
    assert!(
        src.len() + 1 >= n + w,
        "max_plus: {} source samples for {n} outputs of a {w}-wide kernel",
        src.len()
    );
    let full = n - n % N;
    for c in (0..full).step_by(N) {
        let mut acc = [T::NONE; N];
        acc.copy_from_slice(&out[c..c + N]);
        let s = &src[c..c + w + N - 1];
        for (k, &b) in kernel.iter().enumerate() {
            let v = &s[k..k + N];
            for l in 0..N {
                let x = v[l] + b;
                acc[l] = if x > acc[l] { x } else { acc[l] };
            }
        }
        out[c..c + N].copy_from_slice(&acc);
    }
    for (k, &b) in kernel.iter().enumerate() {
        max_add(&mut out[full..], &src[full + k..n + k], b);
    }
}

/// `buf[k] = row[first + k]` for every `k`: the row seen through a window that may overhang it, wrapped
/// around when `periodic`, `−∞` (no sample) beyond its ends otherwise; copied in whole runs.
pub fn pad_row<T: Sample>(row: &[T], first: isize, periodic: bool, buf: &mut [T]) {
    let (nx, n) = (row.len() as isize, buf.len());
    if periodic {
        let mut k = 0;
        while k < n {
            let i = (first + k as isize).rem_euclid(nx) as usize;
            let len = (row.len() - i).min(n - k);
            buf[k..k + len].copy_from_slice(&row[i..i + len]);
            k += len;
        }
        return;
    }
    let lo = (-first).clamp(0, n as isize) as usize;
    let hi = (nx - first).clamp(lo as isize, n as isize) as usize;
    buf[..lo].fill(T::NONE);
    buf[hi..].fill(T::NONE);
    if hi > lo {
        let i = (first + lo as isize) as usize;
        buf[lo..hi].copy_from_slice(&row[i..i + hi - lo]);
    }
}

/// `out(x) = max_{|u| ≤ R} z(x + u) − prof(|u|)` over a grid (the drop-cutter dilation, DESIGN.md §4), rows
/// in parallel; with `periodic` the grid wraps, otherwise samples beyond it are absent.
///
/// The same samples and rim tolerance as `cut::dropcutter::DropCutter::surface`, but not the same
/// rounding: that forms the row offset as `(j′ + ½)·p − y` and the profile from `ρ²`, this one as `dj·p` and
/// from `ρ`, so the two agree only to a few ulp (≤ 6e-17 mm on ball and bull tests, exact for a flat), which
/// would move the last digits of the reported opening statistics.
pub fn dilate<T: Sample>(
    z: &[T],
    nx: usize,
    ny: usize,
    pitch: f64,
    periodic: bool,
    tool: &Shape,
    to_sample: impl Fn(f64) -> T,
) -> Vec<T> {
    let bit = tool.normalized();
    let r = bit.radius_mm();
    let m = (r / pitch).ceil() as usize + 1;
    let mi = m as i64;
    // per row offset dj: the first column offset within the circle and the underside from there on (the
    // offsets within a circle are one run of columns)
    let within = |di: i64, dy: f64| {
        let dx = di as f64 * pitch;
        let d2 = dx * dx + dy * dy;
        (d2 <= r * r * (1.0 + 1e-12)).then(|| -bit.profile(d2.sqrt().min(r)))
    };
    // the underside is the same at ±dj, so rows j + dj and j − dj go through one kernel row together:
    // max(a + k, b + k) = max(a, b) + k exactly (rounding is monotone), and half the max-plus work is left
    let rows: Vec<(i64, i64, Vec<T>)> = (0..=mi)
        .filter_map(|dj| {
            let dy = dj as f64 * pitch;
            let first = (-mi..=mi).find(|&di| within(di, dy).is_some())?;
            let kern: Vec<T> = (first..=mi).map_while(|di| within(di, dy).map(&to_sample)).collect();
            Some((dj, first, kern))
        })
        .collect();
    // every row padded by m columns either side once, so each output row reads its source rows in place
    let w = nx + 2 * m;
    let mut padded = vec![T::NONE; w * ny];
    padded
        .par_chunks_mut(w)
        .zip(z.par_chunks(nx))
        .for_each(|(buf, row)| pad_row(row, -(m as isize), periodic, buf));
    let source = |jj: i64| -> Option<usize> {
        if periodic {
            Some(jj.rem_euclid(ny as i64) as usize)
        } else {
            (0..ny as i64).contains(&jj).then_some(jj as usize)
        }
    };
    let mut out = vec![T::NONE; nx * ny];
    out.par_chunks_mut(nx).enumerate().for_each_init(
        || vec![T::NONE; w],
        |pair, (j, orow)| {
            for (dj, first, kern) in &rows {
                let (n, k0) = (nx + kern.len() - 1, (mi + first) as usize);
                let (up, down) = (source(j as i64 + dj), source(j as i64 - dj));
                let src: &[T] = match (up, down) {
                    (Some(a), Some(b)) if *dj != 0 => {
                        let (ra, rb) = (&padded[a * w + k0..a * w + k0 + n], &padded[b * w + k0..b * w + k0 + n]);
                        pair[..n]
                            .iter_mut()
                            .zip(ra.iter().zip(rb))
                            .for_each(|(p, (x, y))| *p = if *x > *y { *x } else { *y });
                        &pair[..n]
                    }
                    (Some(a), _) | (None, Some(a)) => &padded[a * w + k0..a * w + k0 + n],
                    (None, None) => continue,
                };
                max_plus(orow, src, kern);
            }
        },
    );
    out
}

/// The opening of a grid by the bit, `O = erode(dilate(h))`: the highest surface the bit can leave on `h`
/// from above, however fine its raster (the erosion of the drop-cutter CL surface, DESIGN.md §4).
pub fn opening(h: &[f64], nx: usize, ny: usize, pitch: f64, periodic: bool, tool: &Shape) -> Vec<f64> {
    open(h, nx, ny, pitch, periodic, tool, |v| v)
}

/// `erode(dilate(h))` in the sample type, the erosion as the negated dilation of the negated CL surface.
fn open<T: Sample + std::ops::Neg<Output = T>>(
    h: &[T],
    nx: usize,
    ny: usize,
    pitch: f64,
    periodic: bool,
    tool: &Shape,
    to_sample: impl Fn(f64) -> T,
) -> Vec<T> {
    let cl = dilate(h, nx, ny, pitch, periodic, tool, &to_sample);
    erode(cl, nx, ny, pitch, periodic, tool, to_sample)
}

/// The surface the bit leaves when its tip follows the CL surface `cl`: the negated dilation of the negated
/// CL surface.
fn erode<T: Sample + std::ops::Neg<Output = T>>(
    cl: Vec<T>,
    nx: usize,
    ny: usize,
    pitch: f64,
    periodic: bool,
    tool: &Shape,
    to_sample: impl Fn(f64) -> T,
) -> Vec<T> {
    let neg: Vec<T> = cl.into_iter().map(|v| -v).collect();
    dilate(&neg, nx, ny, pitch, periodic, tool, &to_sample)
        .into_iter()
        .map(|v| -v)
        .collect()
}

/// `h` relative to its highest sample, in single precision (a 1.4 mm relief keeps 0.12 nm steps), and that
/// highest sample.
fn relative_f32(h: &[f64]) -> (f64, Vec<f32>) {
    let top = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let top = if top.is_finite() { top } else { 0.0 };
    (top, h.iter().map(|v| (v - top) as f32).collect())
}

/// An opening taken on [`relative_f32`] heights, back in millimetres: an opening never lies below the
/// surface, and the rounding could put it a hair under, so it is held there.
fn held_on(opened: Vec<f32>, top: f64, h: &[f64]) -> Vec<f64> {
    opened
        .into_iter()
        .zip(h)
        .map(|(v, h)| (top + f64::from(v)).max(*h))
        .collect()
}

/// [`opening`] in single precision, for twice the lanes per vector: the heights are taken relative to their
/// highest (so a 1.4 mm relief keeps 0.12 nm steps), and the result differs from the double-precision
/// opening by a few of those steps (the test bounds it at 1 nm), three orders under [`REACH_TOLERANCE_UM`];
/// it is held at or above the surface, as an opening is. The design loop's as-milled model uses it; the
/// verification's reach check keeps [`opening`].
pub fn opening_f32(h: &[f64], nx: usize, ny: usize, pitch: f64, periodic: bool, tool: &Shape) -> Vec<f64> {
    let (top, rel) = relative_f32(h);
    held_on(open(&rel, nx, ny, pitch, periodic, tool, |v| v as f32), top, h)
}

/// [`opening_f32`] of a periodic grid, and beside it, when `chords` is given, the surface the bit leaves
/// when its centre follows the chords of each pass of the CL surface instead ([`crate::cut::chords`]: the
/// controller's arcs): `erode(chords(dilate(h)))`, from the same dilation. The first is what the bit can
/// reach; the second is what a controller that cuts arcs as chords leaves, which may stand below `h` by up to
/// the chords' sagitta.
pub fn opening_f32_chorded(
    h: &[f64],
    nx: usize,
    ny: usize,
    pitch: f64,
    tool: &Shape,
    chords: Option<crate::cut::chords::PassChords>,
) -> (Vec<f64>, Option<Vec<f64>>) {
    let Some(chords) = chords else {
        return (opening_f32(h, nx, ny, pitch, true, tool), None);
    };
    let (top, rel) = relative_f32(h);
    let to = |v: f64| v as f32;
    let cl = dilate(&rel, nx, ny, pitch, true, tool, to);
    let mut chorded = cl.clone();
    crate::cut::chords::chord_passes(&mut chorded, nx, ny, pitch, chords, to);
    let erode = |cl| erode(cl, nx, ny, pitch, true, tool, to);
    let (opened, chorded) = rayon::join(|| erode(cl), || erode(chorded));
    // the opening is held at or above the surface as `opening_f32`'s is; the chords' cut is not: on a crest
    // they pass below the arc, and the bit with them
    let chorded = chorded.into_iter().map(|v| top + f64::from(v)).collect();
    (held_on(opened, top, h), Some(chorded))
}

/// Samples per tool radius below which [`opening_periodic`] takes the opening on a decimated grid.
pub const OPENING_SAMPLES_PER_RADIUS: f64 = 24.0;

/// The opening of a periodic `nx × ny` grid, taken on every `k`-th sample when the grid is finer than
/// `r / 24` (`k = ⌊r / (24·pitch)⌋`, when it divides both sides) and brought back by periodic bilinear
/// interpolation, never below the grid itself (an opening never is: convex edges, where interpolation
/// would cut the corner, keep the surface). Cost falls by `k⁴` (cells by `k²`, the bit's footprint by
/// `k²`). The sampling bound of the opening becomes `(k·p)²(1 + s²)^{3/2}/(8r)` (0.15 µm for a 0.5 mm
/// ball at slope 1, under [`REACH_TOLERANCE_UM`]). Where the opening is steep — the bit's fillet falling
/// from the top of a step between facets, near vertical — a chord of `k·p` misses the sphere by up to
/// about `0.2·√(2r·k·p)` (14 µm for that ball at 10 µm), and across a kink where two fillets meet by
/// `Δslope·k·p/4`: both only where the opening stands above the grid, in cells that are unreachable
/// either way, so the reach classification barely moves (on the default job 12.41% unreachable against
/// 12.43% from the full opening).
pub fn opening_periodic(h: &[f64], nx: usize, ny: usize, pitch: f64, tool: &Shape) -> Vec<f64> {
    let k = (tool.radius_mm() / (OPENING_SAMPLES_PER_RADIUS * pitch)).floor() as usize;
    if k < 2 || nx % k != 0 || ny % k != 0 || nx / k < 4 || ny / k < 4 {
        return opening(h, nx, ny, pitch, true, tool);
    }
    let (cx, cy) = (nx / k, ny / k);
    let coarse: Vec<f64> = (0..cx * cy).map(|c| h[(c / cx) * k * nx + (c % cx) * k]).collect();
    let open = opening(&coarse, cx, cy, pitch * k as f64, true, tool);
    let mut out = vec![0.0; nx * ny];
    out.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        let (j0, fy) = (j / k, (j % k) as f64 / k as f64);
        let j1 = (j0 + 1) % cy;
        for (i, v) in row.iter_mut().enumerate() {
            let (i0, fx) = (i / k, (i % k) as f64 / k as f64);
            let i1 = (i0 + 1) % cx;
            let a = open[j0 * cx + i0] * (1.0 - fx) + open[j0 * cx + i1] * fx;
            let b = open[j1 * cx + i0] * (1.0 - fx) + open[j1 * cx + i1] * fx;
            *v = (a * (1.0 - fy) + b * fy).max(h[j * nx + i]);
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `max_plus` against the direct maximum for outputs of `n` and kernels of `w` (random, converted to the
    /// sample type by `from`), some outputs starting at −∞.
    fn check_max_plus<T: Sample + std::fmt::Debug>(sizes: &[(usize, usize)], seed: u64, from: impl Fn(f64) -> T) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        for &(n, w) in sizes {
            let src: Vec<T> = (0..n + w - 1).map(|_| from(rng.gen_range(-1.0..1.0))).collect();
            let kernel: Vec<T> = (0..w).map(|_| from(rng.gen_range(-1.0..0.0))).collect();
            let start: Vec<T> = (0..n).map(|k| if k % 3 == 0 { from(0.5) } else { T::NONE }).collect();
            let mut out = start.clone();
            max_plus(&mut out, &src, &kernel);
            for i in 0..n {
                let want = (0..w)
                    .map(|k| src[i + k] + kernel[k])
                    .fold(start[i], |m, v| if v > m { v } else { m });
                assert_eq!(out[i], want, "n {n} w {w} at {i}");
            }
        }
    }

    #[test]
    fn max_plus_equals_the_direct_maximum() {
        // outputs across the lane block boundaries (16 f64, 32 f32), kernels from one entry to wider than
        // the block
        check_max_plus(
            &[(1, 1), (15, 3), (16, 1), (17, 5), (40, 33), (63, 16), (100, 7)],
            3,
            |v| v,
        );
        check_max_plus(&[(1, 1), (31, 3), (32, 1), (33, 5), (70, 41), (96, 32)], 5, |v| {
            v as f32
        });
    }

    #[test]
    fn pad_row_wraps_or_pads_with_nothing() {
        let row = [1.0, 2.0, 3.0];
        let mut buf = [0.0; 8];
        pad_row(&row, -2, true, &mut buf);
        assert_eq!(buf, [2.0, 3.0, 1.0, 2.0, 3.0, 1.0, 2.0, 3.0]);
        let ninf = f64::NEG_INFINITY;
        pad_row(&row, -2, false, &mut buf);
        assert_eq!(buf, [ninf, ninf, 1.0, 2.0, 3.0, ninf, ninf, ninf]);
        pad_row(&row, 5, false, &mut buf[..2]);
        assert_eq!(buf[..2], [ninf, ninf]);
        pad_row(&row, 1, false, &mut buf[..2]);
        assert_eq!(buf[..2], [2.0, 3.0]);
    }

    #[test]
    fn dilation_equals_the_direct_maximum_over_the_ball() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(4);
        let (nx, ny, p) = (37, 23, 0.01);
        let z: Vec<f64> = (0..nx * ny).map(|_| rng.gen_range(-0.05..0.0)).collect();
        for periodic in [true, false] {
            let tool = Shape::Ball { diameter_mm: 0.09 };
            let d = dilate(&z, nx, ny, p, periodic, &tool, |v| v);
            let r: f64 = 0.045;
            let m = (r / p).ceil() as i64 + 1;
            for j in 0..ny as i64 {
                for i in 0..nx as i64 {
                    let mut best = f64::NEG_INFINITY;
                    for dj in -m..=m {
                        for di in -m..=m {
                            let (dx, dy) = (di as f64 * p, dj as f64 * p);
                            let (ii, jj) = (i + di, j + dj);
                            let inside = (0..nx as i64).contains(&ii) && (0..ny as i64).contains(&jj);
                            if dx * dx + dy * dy > r * r * (1.0 + 1e-12) || (!periodic && !inside) {
                                continue;
                            }
                            let (ii, jj) = (ii.rem_euclid(nx as i64), jj.rem_euclid(ny as i64));
                            let prof = tool.profile((dx * dx + dy * dy).sqrt().min(r));
                            best = best.max(z[(jj * nx as i64 + ii) as usize] - prof);
                        }
                    }
                    assert_eq!(d[(j * nx as i64 + i) as usize], best, "periodic {periodic} ({i},{j})");
                }
            }
        }
    }

    /// The chorded opening's first part is the opening itself, bit for bit; its chords' cut is a
    /// ball-eroded CL surface, so it lies on or below the opening where the chords lie below the CL
    /// surface (crests) and within the chords' sagitta of it everywhere (an erosion moves a surface by at
    /// most what its input moved; the sagitta is normal to the chord, so vertically at most `t·√(1 + s²)`,
    /// and the slopes here stay below 0.7).
    #[test]
    fn the_chords_cut_departs_from_the_opening_by_at_most_their_sagitta() {
        use crate::cut::chords::{PassAxis, PassChords};
        let (n, pitch) = (96, 0.01);
        let tau = std::f64::consts::TAU;
        let h: Vec<f64> = (0..n * n)
            .map(|k| {
                let (x, y) = ((k % n) as f64 / n as f64, (k / n) as f64 / n as f64);
                0.05 * (tau * 2.0 * x).sin() * (tau * y).cos()
            })
            .collect();
        let tool = Shape::Ball { diameter_mm: 0.5 };
        for along in [PassAxis::X, PassAxis::Y] {
            let sag = 0.002;
            let (opened, chorded) =
                opening_f32_chorded(&h, n, n, pitch, &tool, Some(PassChords { sag_mm: sag, along }));
            assert_eq!(opened, opening_f32(&h, n, n, pitch, true, &tool));
            let chorded = chorded.expect("chords asked for");
            let worst = opened
                .iter()
                .zip(&chorded)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let moved = opened
                .iter()
                .zip(&chorded)
                .filter(|(a, b)| (*a - *b).abs() > 1e-6)
                .count();
            assert!(
                worst <= sag * (1.0f64 + 0.49).sqrt() + 1e-6,
                "{along:?}: the chords' cut is {worst} mm from the opening"
            );
            assert!(moved > n * n / 10, "{along:?}: only {moved} samples moved");
        }
        assert!(opening_f32_chorded(&h, n, n, pitch, &tool, None).1.is_none());
    }
}
