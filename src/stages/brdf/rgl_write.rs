//! Writing a BRDF as an RGL `.bsdf` file (Dupuy & Jakob 2018), the format Mitsuba 3's `measured` plugin
//! loads, in its RGB form (the `rgb` field; Mitsuba's RGB variants read it).
//!
//! The file tabulates a BRDF `f` given with its NDF `D` (normalised by projected area, `∫ D cosθm dω = 1`).
//! Every grid is over the unit square of `u = √(θ / (π/2))` and `v = (φ + π) / 2π`, vertices at both ends; the
//! file is anisotropic (incident azimuths over the whole circle, `[−π, π]`, so a reader folds nothing):
//! - `ndf[φ, θ]`: `D` at the vertices (128 × 128);
//! - `sigma[φ, θ]`: the projected area `σ(w) = ∫ D(m) ⟨m, w⟩⁺ dm`, by the midpoint rule over `u`
//!   (`dω = 2π² u sinθ du dv`) on 256 × 256 cells;
//! - `vndf[φi, θi, v, u]`: per incident direction, the visible NDF as a density over `(u, v)`,
//!   `D(m) ⟨m, wi⟩⁺ · 2π² u sinθm` at the `ndf` vertices;
//! - `rgb[φi, θi, c, y, x]` on a 32 × 32 grid of the warped `sample` coordinate: for each vertex the half
//!   vector `m` the vndf's inverse cumulative distribution sends to it, `wo` the mirror of `wi` about `m`,
//!   and `rgb = f(wi, wo) cosθo · 4 σ(wi) / D(m)`, with `σ` read back from the file's grid and `D` the
//!   NDF itself. A reader returns `rgb · D_file / (4σ)` (the `jacobian` flag): `f cosθo` where the `ndf`
//!   grid holds `D`, and otherwise `f` scaled by how the grid resolves `D`. For a microfacet BRDF `rgb` is
//!   `F(wi·m) G2(wi, wo) / G1(wi)`, smooth over the grid; dividing by the grid's `D` instead would make
//!   `f cosθo` exact at the 32 × 32 vertices but spike wherever the grid under-resolves a sharp NDF (a
//!   milled surface's), which interpolation then spreads. Vertices where `D` is zero or `wo` is below the
//!   horizon take their neighbours' values;
//! - `luminance[φi, θi, y, x]`: the luminance of `rgb` (what a renderer samples by).
//!
//! Incident directions: the 12 polar angles of [`THETA_I_DEG`] (0° to 89°), 13 azimuths 30° apart.

use super::rgl::{Grid2, Warp};
use super::tensor::{encode, Values};
use super::{luminance, Rgb};
use crate::base::geometry::{spherical, Vec3};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::path::Path;

/// Vertices of the `ndf` grid and of every `vndf` slice, per axis.
pub const NDF_VERTICES: usize = 128;
/// Vertices of the `sigma` grid per axis.
pub const SIGMA_VERTICES: usize = 64;
/// Vertices of the reflectance (`rgb`, `luminance`) grids per axis.
pub const SAMPLE_VERTICES: usize = 32;
/// Incident polar angles, degrees: `cosθi` evenly spaced by 1/8 from 1 down to 75.5°, then denser toward
/// grazing, where masking and Fresnel change fastest; the last short of 90° (a reader holds the last slice
/// beyond it, and at 90° itself every reflection is masked).
pub const THETA_I_DEG: [f64; 12] = [
    0.0, 28.955, 41.410, 51.318, 60.0, 67.976, 75.522, 80.0, 83.0, 85.5, 87.5, 89.0,
];
/// Incident polar angles.
pub const THETA_I: usize = THETA_I_DEG.len();
/// Incident azimuths over `[−π, π]`.
pub const PHI_I: usize = 13;
/// Midpoint-rule cells per axis of the projected-area quadrature.
const SIGMA_CELLS: usize = 256;

/// A BRDF to write and the NDF its file is parameterised by.
pub struct RglSource<'a> {
    /// What the file holds, in words (printable ASCII is kept, the rest dropped).
    pub description: String,
    /// `D(wm)`, normalised by projected area.
    pub ndf: &'a (dyn Fn(&Vec3) -> f64 + Sync),
    /// `f(wi, wo)` in RGB, without the cosine.
    pub brdf: &'a (dyn Fn(&Vec3, &Vec3) -> Rgb + Sync),
}

/// `θ` of a grid coordinate `u`.
fn u2theta(u: f64) -> f64 {
    u * u * FRAC_PI_2
}

/// `φ` of a grid coordinate `v`.
fn v2phi(v: f64) -> f64 {
    v * TAU - PI
}

/// The direction at grid coordinate `(u, v)`.
fn direction(u: f64, v: f64) -> Vec3 {
    spherical(u2theta(u), v2phi(v))
}

/// The grid of `f` at `nx` vertices along `u` (the fast axis) and `ny` along `v`, as the file stores it
/// (values rounded to `f32`) and a reader interpolates it.
fn grid(nx: usize, ny: usize, f: impl Fn(&Vec3) -> f64 + Sync) -> Grid2 {
    let v = (0..nx * ny)
        .into_par_iter()
        .map(|k| {
            let (x, y) = (k % nx, k / nx);
            f(&direction(x as f64 / (nx - 1) as f64, y as f64 / (ny - 1) as f64)) as f32 as f64
        })
        .collect();
    Grid2 { nx, ny, v }
}

/// The incident polar angles, radians.
pub fn theta_i() -> Vec<f64> {
    THETA_I_DEG.iter().map(|d| d.to_radians()).collect()
}

/// The incident azimuths: `[−π, π]` in equal steps.
pub fn phi_i() -> Vec<f64> {
    (0..PHI_I).map(|k| v2phi(k as f64 / (PHI_I - 1) as f64)).collect()
}

/// The projected area `σ(w) = ∫ D(m) ⟨m, w⟩⁺ dm` on the `sigma` grid, by the midpoint rule over `(u, v)`.
fn projected_area(ndf: &(dyn Fn(&Vec3) -> f64 + Sync)) -> Grid2 {
    let n = SIGMA_CELLS;
    let nodes: Vec<(Vec3, f64)> = (0..n * n)
        .into_par_iter()
        .filter_map(|k| {
            let (u, v) = (((k % n) as f64 + 0.5) / n as f64, ((k / n) as f64 + 0.5) / n as f64);
            let m = direction(u, v);
            let jac = 2.0 * PI * PI * u * u2theta(u).sin() / (n * n) as f64;
            let w = ndf(&m) * jac;
            (w > 0.0).then_some((m, w))
        })
        .collect();
    grid(SIGMA_VERTICES, SIGMA_VERTICES, |w| {
        nodes.iter().map(|(m, d)| d * m.dot(w).max(0.0)).sum()
    })
}

/// Replace the `bad` vertices of an `n × n` grid of RGB values by the mean of their good neighbours,
/// growing inward from the good ones; a grid with no good vertex becomes zero.
fn fill(values: &mut [Rgb], good: &mut [bool], n: usize) {
    if !good.iter().any(|g| *g) {
        values.iter_mut().for_each(|v| *v = [0.0; 3]);
        return;
    }
    while good.iter().any(|g| !*g) {
        let before = good.to_vec();
        for k in 0..n * n {
            if before[k] {
                continue;
            }
            let (x, y) = (k % n, k / n);
            let (mut sum, mut count) = ([0.0; 3], 0.0);
            for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                let (a, b) = (x as i64 + dx, y as i64 + dy);
                if a < 0 || b < 0 || a >= n as i64 || b >= n as i64 {
                    continue;
                }
                let j = b as usize * n + a as usize;
                if before[j] {
                    (0..3).for_each(|c| sum[c] += values[j][c]);
                    count += 1.0;
                }
            }
            if count > 0.0 {
                values[k] = sum.map(|s| s / count);
                good[k] = true;
            }
        }
    }
}

/// One incident direction's `vndf` slice and reflectance grid.
struct Slice {
    vndf: Vec<f32>,
    rgb: Vec<Rgb>,
    /// Vertices whose outgoing direction is below the horizon: their luminance is zero, so that a
    /// renderer does not sample them (their `rgb` is filled, for interpolation beside them).
    below: Vec<bool>,
}

fn slice(src: &RglSource, ndf: &Grid2, sigma: &Grid2, theta_i: f64, phi_i: f64) -> Slice {
    let n = NDF_VERTICES;
    let wi = spherical(theta_i, phi_i);
    let vndf: Vec<f32> = (0..n * n)
        .map(|k| {
            let (x, y) = (k % n, k / n);
            let u = x as f64 / (n - 1) as f64;
            let m = direction(u, y as f64 / (n - 1) as f64);
            let visible = ndf.v[k] * m.dot(&wi).max(0.0);
            (visible * 2.0 * PI * PI * u * u2theta(u).sin()) as f32
        })
        .collect();
    let warp = Warp::new(&vndf.iter().map(|v| *v as f64).collect::<Vec<_>>(), n, n);
    let s = SAMPLE_VERTICES;
    let area = sigma.at(&wi);
    let mut good = vec![false; s * s];
    let mut below = vec![false; s * s];
    let mut rgb = vec![[0.0; 3]; s * s];
    for k in 0..s * s {
        let at = ((k % s) as f64 / (s - 1) as f64, (k / s) as f64 / (s - 1) as f64);
        let (u, v) = warp.sample((n, n), at);
        let m = direction(u, v);
        let wo = m * (2.0 * m.dot(&wi)) - wi;
        let d = (src.ndf)(&m);
        below[k] = wo.z <= 0.0;
        if below[k] || d <= 0.0 || area <= 0.0 {
            continue;
        }
        let f = (src.brdf)(&wi, &wo);
        rgb[k] = f.map(|c| c * wo.z * 4.0 * area / d);
        // stored as f32: a value beyond its range is as bad as an infinite one
        good[k] = rgb[k].iter().all(|c| (*c as f32).is_finite() && *c >= 0.0);
    }
    fill(&mut rgb, &mut good, s);
    Slice { vndf, rgb, below }
}

/// The bytes of the `.bsdf` file of `src`.
pub fn encode_rgl(src: &RglSource) -> Vec<u8> {
    let ndf = grid(NDF_VERTICES, NDF_VERTICES, |m| (src.ndf)(m).max(0.0));
    let sigma = projected_area(src.ndf);
    let (thetas, phis) = (theta_i(), phi_i());
    let slices: Vec<Slice> = (0..PHI_I * THETA_I)
        .into_par_iter()
        .map(|k| slice(src, &ndf, &sigma, thetas[k % THETA_I], phis[k / THETA_I]))
        .collect();
    let s = SAMPLE_VERTICES;
    let mut rgb = Vec::with_capacity(slices.len() * 3 * s * s);
    let mut lum = Vec::with_capacity(slices.len() * s * s);
    let mut vndf = Vec::with_capacity(slices.len() * NDF_VERTICES * NDF_VERTICES);
    for sl in &slices {
        vndf.extend_from_slice(&sl.vndf);
        for c in 0..3 {
            rgb.extend(sl.rgb.iter().map(|v| v[c] as f32));
        }
        lum.extend(
            sl.rgb
                .iter()
                .zip(&sl.below)
                .map(|(v, b)| if *b { 0.0 } else { luminance(v).max(0.0) as f32 }),
        );
    }
    let description: Vec<u8> = src.description.bytes().filter(|b| (b' '..=b'~').contains(b)).collect();
    let f32s = |v: &[f64]| Values::F32(v.iter().map(|x| *x as f32).collect());
    encode(&[
        ("version", vec![2], Values::U32(vec![1, 0])),
        ("description", vec![description.len()], Values::U8(description)),
        ("phi_i", vec![PHI_I], f32s(&phis)),
        ("theta_i", vec![THETA_I], f32s(&thetas)),
        ("sigma", vec![sigma.ny, sigma.nx], f32s(&sigma.v)),
        ("ndf", vec![ndf.ny, ndf.nx], f32s(&ndf.v)),
        (
            "vndf",
            vec![PHI_I, THETA_I, NDF_VERTICES, NDF_VERTICES],
            Values::F32(vndf),
        ),
        ("luminance", vec![PHI_I, THETA_I, s, s], Values::F32(lum)),
        ("rgb", vec![PHI_I, THETA_I, 3, s, s], Values::F32(rgb)),
        ("jacobian", vec![1], Values::U8(vec![1])),
    ])
}

/// The share of a parameterising NDF given to a uniform floor by [`with_floor`].
pub const FLOOR_SHARE: f64 = 0.05;

/// `(1 − ε) D(m) + ε / π`, ε = [`FLOOR_SHARE`]: an NDF to parameterise a file by when `D` is only the half-angle
/// distribution of a measured reflectance (a MERL target's). A file's reflectance reaches a reader only where
/// its NDF is non-zero (`f cosθo = rgb · D / 4σ`), and such a `D` is zero beyond its slope grid's cone, where
/// the measurement may still reflect (a diffuse part); `1/π` is the uniform NDF (`∫ cosθ/π dω = 1`), so the
/// sum stays normalised when `D` is.
pub fn with_floor(d: impl Fn(&Vec3) -> f64 + Sync) -> impl Fn(&Vec3) -> f64 + Sync {
    move |m| (1.0 - FLOOR_SHARE) * d(m) + if m.z > 0.0 { FLOOR_SHARE / PI } else { 0.0 }
}

/// Write `src` as an RGL `.bsdf` file at `path` (atomically).
pub fn write_rgl(path: &Path, src: &RglSource) -> Result<(), crate::base::io::WriteError> {
    crate::base::io::write_atomic(path, &encode_rgl(src))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::brdf::{Brdf, Model, RglBsdf};

    #[test]
    fn projected_area_of_a_ggx_ndf_is_cos_over_g1() {
        // σ(w) = cosθ / G1(w) = cosθ (1 + Λ(w)) for a microfacet NDF (Heitz 2014, Eq. 18)
        let b = Brdf::parse("ggx:ax=0.15,ay=0.3").unwrap();
        let Model::Microfacet(m) = &b.model else { unreachable!() };
        let s = projected_area(&|w: &Vec3| m.d(w));
        for (t, p) in [(0.0, 0.0), (0.7, 0.4), (1.2, -2.0), (1.45, 1.5)] {
            let w = spherical(t, p);
            let exact = w.z * (1.0 + m.lambda(&w));
            let rel = s.at(&w) / exact - 1.0;
            assert!(rel.abs() < 2e-3, "θ {t} φ {p}: σ {} vs {exact}", s.at(&w));
        }
    }

    /// Directions drawn with `cosθ` uniform in [`COS_MIN`, 1]: polar angles up to 89.5°.
    const COS_MIN: f64 = 0.0087;

    /// The file of `f` parameterised by `d`.
    fn file_with(
        description: &str,
        d: &(dyn Fn(&Vec3) -> f64 + Sync),
        f: &(dyn Fn(&Vec3, &Vec3) -> Rgb + Sync),
    ) -> Vec<u8> {
        encode_rgl(&RglSource {
            description: description.into(),
            ndf: d,
            brdf: f,
        })
    }

    /// The file of an analytic BRDF, parameterised by its own NDF.
    fn file_of(b: &Brdf, description: &str) -> Vec<u8> {
        file_with(description, &|m| b.known_ndf(m).unwrap(), &|wi, wo| b.eval(wi, wo))
    }

    /// Relative L1 of `f cosθo` read back from `r` against `f`, over 20000 seeded direction pairs with
    /// `cosθ` uniform in [`COS_MIN`, 1].
    fn hemisphere_l1(f: &dyn Fn(&Vec3, &Vec3) -> Rgb, r: &RglBsdf) -> f64 {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let mut dir = || {
            spherical(
                (COS_MIN + (1.0 - COS_MIN) * rng.gen::<f64>()).acos(),
                rng.gen::<f64>() * TAU - PI,
            )
        };
        let (mut num, mut den) = (0.0, 0.0);
        for _ in 0..20000 {
            let (wi, wo) = (dir(), dir());
            let (a, c) = (f(&wi, &wo), r.eval(&wi, &wo));
            for k in 0..3 {
                num += (a[k] - c[k]).abs() * wo.z;
                den += a[k] * wo.z;
            }
        }
        num / den
    }

    /// The file read back gives the BRDF it tabulates: relative L1 of `f cosθo` over direction pairs with
    /// polar angles up to 89.5° under 2%. Mitsuba reads these files as brdfmill's
    /// reader does (tests/rgl_mitsuba.rs), so this is what a renderer gets.
    #[test]
    fn the_file_read_back_gives_the_brdf() {
        for spec in [
            "ggx:ax=0.15,ay=0.3,material=gold",
            "ggx:alpha=0.3,material=aluminium",
            "beckmann:alpha=0.1,material=aluminium",
        ] {
            let b = Brdf::parse(spec).unwrap();
            let r = RglBsdf::from_bytes(&file_of(&b, &format!("{spec}\u{1}\n"))).unwrap();
            assert_eq!(r.description, spec, "description: printable ASCII only");
            assert_eq!((r.theta_i.len(), r.phi_i.len()), (THETA_I, PHI_I));
            let l1 = hemisphere_l1(&|wi, wo| b.eval(wi, wo), &r);
            assert!(l1 < 0.02, "{spec}: relative L1 {l1}");
        }
    }

    /// Toward grazing, where masking and Fresnel change fastest, the mirror direction's value (the
    /// highlight a silhouette shows) holds: a coarse slice spacing there loses it.
    #[test]
    fn the_highlight_holds_toward_grazing() {
        let b = Brdf::parse("beckmann:alpha=0.2,material=aluminium").unwrap();
        let r = RglBsdf::from_bytes(&file_of(&b, "")).unwrap();
        // up to the last slice, 89°: beyond it a reader holds that slice (Mitsuba clamps its interpolation)
        // over the last 1.5e-4 of the cosine-weighted hemisphere
        for deg in [70.0, 78.0, 82.0, 84.0, 86.5, 88.0, 89.0] {
            let t = f64::to_radians(deg);
            let (wi, wo) = (spherical(t, 0.3), spherical(t, 0.3 + PI));
            let ratio = r.eval(&wi, &wo)[1] / b.eval(&wi, &wo)[1];
            assert!(
                (ratio - 1.0).abs() < 0.05,
                "at θ {deg}°: the file gives {ratio} of the BRDF"
            );
        }
    }

    /// The file conserves energy where the BRDF does: at every incident direction of the file, its
    /// directional albedo `∫ f cosθo dωo` (by quadrature over the hemisphere, read back) is the BRDF's within
    /// 2%, and the mean of the stored reflectance over the warped square (what a reader's samples weigh,
    /// about the albedo) stays below 1.
    #[test]
    fn each_slice_holds_the_directional_albedo() {
        let b = Brdf::parse("ggx:ax=0.15,ay=0.3,material=gold").unwrap();
        let bytes = file_of(&b, "");
        let r = RglBsdf::from_bytes(&bytes).unwrap();
        let tf = super::super::tensor::TensorFile::parse(&bytes).unwrap();
        let rgb = &tf.fields["rgb"].data;
        let s = SAMPLE_VERTICES;
        let (thetas, phis) = (theta_i(), phi_i());
        for (ip, p) in phis.iter().enumerate().step_by(3) {
            for (it, t) in thetas.iter().enumerate() {
                let wi = spherical(*t, *p);
                // quadrature in (u = √(θ/90°), φ), fine near the normal where the lobe is
                let (nu, nphi) = (300, 200);
                let (mut exact, mut read) = (0.0, 0.0);
                for iu in 0..nu {
                    let u = (iu as f64 + 0.5) / nu as f64;
                    let th = u2theta(u);
                    let jac = 2.0 * u * FRAC_PI_2 * th.sin() / nu as f64 * TAU / nphi as f64;
                    for jp in 0..nphi {
                        let wo = spherical(th, (jp as f64 + 0.5) / nphi as f64 * TAU);
                        exact += b.eval(&wi, &wo)[1] * wo.z * jac;
                        read += r.eval(&wi, &wo)[1] * wo.z * jac;
                    }
                }
                let at = format!("θi {:.1}° φi {:.0}°", t.to_degrees(), p.to_degrees());
                assert!(
                    (read / exact - 1.0).abs() < 0.02,
                    "{at}: albedo {read} read back, {exact} of the BRDF"
                );
                let base = ((ip * THETA_I + it) * 3 + 1) * s * s;
                let w = |k: usize| if k == 0 || k == s - 1 { 0.5 } else { 1.0 };
                let mean: f64 =
                    (0..s * s).map(|k| w(k % s) * w(k / s) * rgb[base + k]).sum::<f64>() / ((s - 1) * (s - 1)) as f64;
                assert!(exact < 1.0 && mean < 1.0, "{at}: mean reflectance {mean}");
            }
        }
    }

    /// A measured reflectance with a diffuse part, parameterised by the half-angle distribution of its lobe
    /// cut at a slope grid's cone (what a MERL target's job derives): without a floor the file loses every
    /// reflection whose half vector lies beyond the cone; with [`with_floor`] it keeps them.
    #[test]
    fn a_floor_keeps_the_reflectance_beyond_the_cone() {
        let lobe = Brdf::parse("beckmann:alpha=0.2,material=aluminium").unwrap();
        let f = |wi: &Vec3, wo: &Vec3| lobe.eval(wi, wo).map(|c| c + 0.05 / PI);
        let cone = 40f64.to_radians().cos();
        let cut = |m: &Vec3| if m.z >= cone { lobe.known_ndf(m).unwrap() } else { 0.0 };
        let floored = with_floor(cut);
        let l1 =
            |d: &(dyn Fn(&Vec3) -> f64 + Sync)| hemisphere_l1(&f, &RglBsdf::from_bytes(&file_with("", d, &f)).unwrap());
        let (bare, with) = (l1(&cut), l1(&floored));
        eprintln!("relative L1: {bare} without a floor, {with} with it");
        assert!(with < 0.02, "with a floor: relative L1 {with}");
        assert!(
            bare > 2.0 * with,
            "without a floor the file should lose the reflectance beyond the cone: {bare}"
        );
    }

    #[test]
    fn bad_vertices_take_their_neighbours_values() {
        let n = 4;
        let mut v = vec![[0.0; 3]; n * n];
        let mut good = vec![false; n * n];
        v[5] = [1.0, 2.0, 3.0];
        good[5] = true;
        fill(&mut v, &mut good, n);
        assert!(good.iter().all(|g| *g));
        assert!(v.iter().all(|x| *x == [1.0, 2.0, 3.0]), "{v:?}");
        let mut none = vec![[f64::NAN; 3]; 4];
        fill(&mut none, &mut [false; 4], 2);
        assert!(none.iter().all(|x| *x == [0.0; 3]));
    }
}
