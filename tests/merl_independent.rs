//! brdfmill's MERL reader on a file it did not write: `tests/data/peers/merl/independent.binary.zip` holds a
//! full 90 × 90 × 180 MERL `.binary` written by `scripts/peer_merl_independent.py` from the published layout
//! (the database's own sample reader, `BRDFRead.cpp`), without reference to brdfmill's reader or writer.
//! Until now MERL files were only tested by writing with brdfmill's writer and reading with its reader,
//! which cannot see a mistake the two share.
//!
//! The file tabulates, at each bin's centre in index space (θh at ((i + ½)/90)²·π/2, θd at (j + ½)/90·π/2,
//! φd at (k + ½)/180·π), a closed form in which each channel depends on one angle:
//!
//! red = 0.05 + 0.8 cos⁴θh, green = 0.3 + 0.2 cos θd, blue = 0.4 + 0.15 cos 2φd + 0.05 sin 2φd.
//!
//! So every red value tests the θh index and stride, every green value θd, every blue value φd (and its
//! fold by π; blue is not symmetric about π/2, so a mirrored φd is seen), and any mix-up of channel blocks or
//! scales changes the numbers by far more than rounding.
//!
//! The directions are built the way MERL's reader takes them apart (`in = Rz(φh)·Ry(θh)·d`, `out` its
//! mirror about the half vector), by code in this file, and the test first checks that MERL's published
//! forward transform gives the angles back.

mod common;

use brdfmill::base::geometry::Vec3;
use brdfmill::stages::brdf::merl::Merl;
use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Read;
use std::path::PathBuf;

const NH: usize = 90;
const ND: usize = 90;
const NP: usize = 180;

fn red(theta_h: f64) -> f64 {
    0.05 + 0.8 * theta_h.cos().powi(4)
}
fn green(theta_d: f64) -> f64 {
    0.3 + 0.2 * theta_d.cos()
}
fn blue(phi_d: f64) -> f64 {
    0.4 + 0.15 * (2.0 * phi_d).cos() + 0.05 * (2.0 * phi_d).sin()
}

/// Bin-centre angles, as the script places them.
fn th_c(i: usize) -> f64 {
    let u = (i as f64 + 0.5) / NH as f64;
    u * u * FRAC_PI_2
}
fn td_c(j: usize) -> f64 {
    (j as f64 + 0.5) / ND as f64 * FRAC_PI_2
}
fn pd_c(k: usize) -> f64 {
    (k as f64 + 0.5) / NP as f64 * PI
}

fn read_independent() -> Merl {
    let zip_path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/peers/merl/independent.binary.zip");
    let mut archive = zip::ZipArchive::new(std::fs::File::open(&zip_path).unwrap()).unwrap();
    let mut entry = archive.by_name("independent.binary").unwrap();
    let mut bytes = Vec::new();
    entry.read_to_end(&mut bytes).unwrap();
    assert_eq!(bytes.len(), 12 + 3 * NH * ND * NP * 8);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("independent.binary");
    std::fs::write(&path, &bytes).unwrap();
    Merl::read(&path).unwrap()
}

fn rotate(v: Vec3, axis: Vec3, angle: f64) -> Vec3 {
    // Rodrigues, as MERL's rotate_vector
    let (s, c) = angle.sin_cos();
    v * c + axis * (axis.dot(&v) * (1.0 - c)) + axis.cross(&v) * s
}

/// (in, out) for the given half/difference angles, MERL's convention.
fn directions(theta_h: f64, phi_h: f64, theta_d: f64, phi_d: f64) -> (Vec3, Vec3) {
    let d = Vec3::new(theta_d.sin() * phi_d.cos(), theta_d.sin() * phi_d.sin(), theta_d.cos());
    let z = Vec3::new(0.0, 0.0, 1.0);
    let y = Vec3::new(0.0, 1.0, 0.0);
    let wi = rotate(rotate(d, y, theta_h), z, phi_h);
    let h = Vec3::new(theta_h.sin() * phi_h.cos(), theta_h.sin() * phi_h.sin(), theta_h.cos());
    let wo = h * (2.0 * wi.dot(&h)) - wi;
    (wi, wo)
}

/// MERL's `std_coords_to_half_diff_coords` on vectors: (θh, θd, φd).
fn merl_forward(wi: Vec3, wo: Vec3) -> (f64, f64, f64) {
    let h = (wi + wo).normalize();
    let theta_h = h.z.clamp(-1.0, 1.0).acos();
    let phi_h = h.y.atan2(h.x);
    let t = rotate(wi, Vec3::new(0.0, 0.0, 1.0), -phi_h);
    let d = rotate(t, Vec3::new(0.0, 1.0, 0.0), -theta_h);
    (theta_h, d.z.clamp(-1.0, 1.0).acos(), d.y.atan2(d.x))
}

/// A small deterministic generator (no dependency on brdfmill's).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        ((self.next() * n as f64) as usize).min(n - 1)
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn the_table_holds_the_closed_form_in_the_published_order_and_scales() {
    let m = read_independent();
    let n = NH * ND * NP;
    assert_eq!(m.data.len(), 3 * n);
    let mut worst = 0.0f64;
    for i in 0..NH {
        for j in 0..ND {
            for k in 0..NP {
                let idx = k + NP * j + NP * ND * i;
                for (c, want) in [red(th_c(i)), green(td_c(j)), blue(pd_c(k))].into_iter().enumerate() {
                    worst = worst.max(rel(m.data[c * n + idx], want));
                }
            }
        }
    }
    println!(
        "all {} values: largest relative difference from the closed form {worst:.2e}",
        3 * n
    );
    // the script stored value / scale, the reader multiplies by the scale: two roundings
    assert!(worst < 1e-15, "{worst:e}");
}

#[test]
fn eval_at_bin_centres_gives_the_closed_form() {
    let m = read_independent();
    let mut rng = Lcg(7);
    let (mut tested, mut worst, mut worst_recip, mut worst_angle) = (0, 0.0f64, 0.0f64, 0.0f64);
    while tested < 20_000 {
        let (i, j, k) = (rng.below(NH), rng.below(ND), rng.below(NP));
        let (th, td, pd, ph) = (th_c(i), td_c(j), pd_c(k), rng.next() * 2.0 * PI);
        // also the other half of φd, which reciprocity folds onto the same bin
        let pd_asked = if rng.next() < 0.5 { pd } else { pd - PI };
        let (wi, wo) = directions(th, ph, td, pd_asked);
        if wi.z < 0.02 || wo.z < 0.02 {
            continue;
        }
        let (a, b, c) = merl_forward(wi, wo);
        worst_angle = worst_angle
            .max((a - th).abs())
            .max((b - td).abs())
            .max((c - pd_asked).abs());
        let want = [red(th), green(td), blue(pd)];
        let got = m.eval(&wi, &wo);
        let back = m.eval(&wo, &wi);
        for c in 0..3 {
            worst = worst.max(rel(got[c], want[c]));
            worst_recip = worst_recip.max(rel(back[c], want[c]));
        }
        tested += 1;
    }
    println!(
        "{tested} bin centres: relative difference {worst:.2e} (swapped directions {worst_recip:.2e}); \
         the test's directions reproduce their angles under MERL's transform to {worst_angle:.1e} rad"
    );
    assert!(
        worst_angle < 1e-9,
        "the test's direction construction is not MERL's: {worst_angle:e}"
    );
    // At a bin centre the reader's interpolation weights are 1 on that bin up to the rounding of the angles
    // recovered from the directions: φh and φd are ill-conditioned at the smallest θh and θd (error ≈ ε / sin θ,
    // measured above: ~1e-10 rad at the first θh bin's 4.8e-5 rad), i.e. ≤ 1e-8 of a bin, times the change to
    // the neighbouring bin (≤ 5 %): ≤ 5e-10 relative. The test allows 1e-9.
    assert!(worst < 1e-9 && worst_recip < 1e-9, "{worst:e} {worst_recip:e}");
}

/// Between bin centres brdfmill interpolates linearly in each axis's bin coordinate (documented in
/// `brdf::merl`; MERL's own reader takes the bin the point falls in). With one angle per channel that is a
/// 1D linear interpolation, which the test computes from the closed form: clamped beyond the first and last
/// θ centres, periodic in φd.
#[test]
fn eval_between_bin_centres_interpolates_the_closed_form() {
    let m = read_independent();
    let mut rng = Lcg(11);
    let lerp = |u: f64, n: usize, periodic: bool, f: &dyn Fn(usize) -> f64| -> f64 {
        if periodic {
            let u0 = u.floor();
            let t = u - u0;
            let k0 = (u0 as isize).rem_euclid(n as isize) as usize;
            (1.0 - t) * f(k0) + t * f((k0 + 1) % n)
        } else {
            let u = u.clamp(0.0, (n - 1) as f64);
            let i0 = (u.floor() as usize).min(n - 2);
            let t = u - i0 as f64;
            (1.0 - t) * f(i0) + t * f(i0 + 1)
        }
    };
    // Each channel as a function of its bin coordinate u (centres at integers).
    let f_u: [&dyn Fn(f64) -> f64; 3] = [
        &|u| red(((u + 0.5) / NH as f64).powi(2) * FRAC_PI_2),
        &|u| green((u + 0.5) / ND as f64 * FRAC_PI_2),
        &|u| blue((u + 0.5) / NP as f64 * PI),
    ];
    // How far linear interpolation between centres may miss the closed form: h²/8 · max|f''| (h = 1 bin),
    // and, before the first and after the last θ centre where the reader holds the end value, the change of
    // f over that half bin.
    let bound: Vec<f64> = (0..3)
        .map(|c| {
            let (n, f) = ([NH, ND, NP][c], f_u[c]);
            let (mut f2, mut clamp) = (0.0f64, 0.0f64);
            for s in 0..=20_000 {
                let u = s as f64 / 20_000.0 * (n - 1) as f64;
                let e = 1e-3;
                f2 = f2.max(((f(u + e) - 2.0 * f(u) + f(u - e)) / (e * e)).abs());
            }
            if c < 2 {
                for s in 0..=1000 {
                    let t = s as f64 / 1000.0 * 0.5;
                    clamp = clamp
                        .max((f(-t) - f(0.0)).abs())
                        .max((f((n - 1) as f64 + t) - f((n - 1) as f64)).abs());
                }
            }
            (f2 / 8.0).max(clamp)
        })
        .collect();
    let (mut tested, mut worst, mut worst_model) = (0, 0.0f64, [0.0f64; 3]);
    while tested < 20_000 {
        let (th, td, pd, ph) = (
            rng.next() * FRAC_PI_2 * 0.999,
            rng.next() * FRAC_PI_2 * 0.999,
            (rng.next() - 0.5) * 2.0 * PI,
            rng.next() * 2.0 * PI,
        );
        let (wi, wo) = directions(th, ph, td, pd);
        if wi.z < 0.02 || wo.z < 0.02 {
            continue;
        }
        // bin coordinates with centres at integers
        let uh = (th / FRAC_PI_2).sqrt() * NH as f64 - 0.5;
        let ud = td / FRAC_PI_2 * ND as f64 - 0.5;
        let up = pd.rem_euclid(PI) / PI * NP as f64 - 0.5;
        let want = [
            lerp(uh, NH, false, &|i| red(th_c(i))),
            lerp(ud, ND, false, &|j| green(td_c(j))),
            lerp(up, NP, true, &|k| blue(pd_c(k))),
        ];
        let model = [red(th), green(td), blue(pd)];
        let got = m.eval(&wi, &wo);
        for c in 0..3 {
            worst = worst.max(rel(got[c], want[c]));
            worst_model[c] = worst_model[c].max((got[c] - model[c]).abs() / bound[c]);
        }
        tested += 1;
    }
    println!(
        "{tested} points between centres: relative difference from the interpolated closed form {worst:.2e}; \
         from the closed form itself, as a fraction of the interpolation bound (R {:.1e}, G {:.1e}, B {:.1e} \
         absolute): R {:.3}, G {:.3}, B {:.3}",
        bound[0], bound[1], bound[2], worst_model[0], worst_model[1], worst_model[2]
    );
    // (the same angle rounding as above, on weights that are now fractions)
    assert!(worst < 1e-9, "{worst:e}");
    // and the reader's values are within the interpolation bound of the closed form itself (1 % for the
    // finite-difference estimate of f'')
    assert!(worst_model.iter().all(|w| *w <= 1.01), "{worst_model:?}");
}

/// φd's sign is seen: at φd ≈ π/4 and its mirror 3π/4 the blue channel differs by 0.1 (29 %), and the reader
/// gives each its own value — a reader that folded φd → π − φd (or took φd from the other direction's
/// mirror) would return the same number for both.
#[test]
fn phi_d_and_its_mirror_are_told_apart() {
    let m = read_independent();
    let (i, j) = (40, 30);
    for (k, mirror) in [(45, 134), (20, 159)] {
        assert_eq!(pd_c(k) + pd_c(mirror), PI);
        let (wi, wo) = directions(th_c(i), 0.3, td_c(j), pd_c(k));
        let a = m.eval(&wi, &wo);
        let (wi, wo) = directions(th_c(i), 0.3, td_c(j), pd_c(mirror));
        let b = m.eval(&wi, &wo);
        assert!((blue(pd_c(k)) - blue(pd_c(mirror))).abs() > 0.05);
        assert!(
            rel(a[2], blue(pd_c(k))) < 1e-9 && rel(b[2], blue(pd_c(mirror))) < 1e-9,
            "{a:?} {b:?}"
        );
    }
}

/// `brdfmill export` on a job's output folder: `target.binary`, `design.binary` and `milled.binary`, read here by the
/// published layout (three `int32` dimensions, then each channel's `float64` block, θh slowest and φd fastest,
/// times MERL's scales 1/1500, 1.15/1500, 1.66/1500) without brdfmill's reader, hold at every bin centre
/// tested the BRDFs the report shows: the target, and the microfacet BRDFs of the NDFs the verdict measured
/// (`ndf-design.json`, `ndf-milled.json`) with the target's material. Directions are this file's (MERL's construction).
#[test]
#[ignore = "slow: runs a job (about 10 s) and writes three 33 MB tables"]
fn export_writes_the_target_and_milled_brdfs_in_merls_layout() {
    let dir = tempfile::tempdir().unwrap();
    let job = dir.path().join("job");
    let spec = "beckmann:alpha=0.2,material=aluminium";
    common::run_small_job(&job, &[]);
    common::brdfmill_ok(&["export", job.to_str().unwrap()]);
    let brdfs = common::JobBrdfs::read(&job, spec);
    let scale = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];
    let n = NH * ND * NP;
    for (stem, f) in brdfs.each() {
        let file = format!("{stem}.binary");
        let bytes = std::fs::read(job.join(&file)).unwrap();
        let int = |k: usize| i32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap());
        assert_eq!(
            (int(0), int(1), int(2)),
            (NH as i32, ND as i32, NP as i32),
            "{file}: dimensions"
        );
        assert_eq!(bytes.len(), 12 + 3 * n * 8, "{file}: size");
        let raw = |c: usize, idx: usize| {
            let at = 12 + 8 * (c * n + idx);
            f64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
        };
        let mut rng = Lcg(3);
        let (mut tested, mut below, mut worst) = (0, 0, 0.0f64);
        while tested < 5000 {
            let (i, j, k) = (rng.below(NH), rng.below(ND), rng.below(NP));
            let (wi, wo) = directions(th_c(i), 0.0, td_c(j), pd_c(k));
            let idx = k + NP * j + NP * ND * i;
            if wi.z <= 1e-9 || wo.z <= 1e-9 {
                // below the horizon: MERL's −1
                if wi.z < -1e-9 || wo.z < -1e-9 {
                    assert!(
                        (0..3).all(|c| raw(c, idx) == -1.0),
                        "{file}: bin ({i}, {j}, {k}) below the horizon"
                    );
                    below += 1;
                }
                continue;
            }
            let want = f(&wi, &wo);
            for c in 0..3 {
                let got = raw(c, idx) * scale[c];
                worst = worst.max((got - want[c]).abs() / want[c].abs().max(1e-6));
            }
            tested += 1;
        }
        println!("{file}: {tested} bin centres above the horizon, largest relative difference {worst:.1e}; {below} below it, −1");
        // the same BRDF at directions built two ways (here and by the writer), each to the last bits
        assert!(worst < 1e-9, "{file}: {worst:e}");
        assert!(below > 0, "{file}: no bin below the horizon was drawn");
    }
}
