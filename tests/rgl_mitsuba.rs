//! RGL `.bsdf` files against their peer, Mitsuba 3's `measured` plugin (`pip install mitsuba`; the Python is
//! `$BRDFMILL_MITSUBA_PYTHON`, else `python3`). Mitsuba is run by `tests/mitsuba/measured_eval.py`, which
//! returns its `BSDF.eval` (f·cosθo, in float32) at directions drawn here and renders a small image.
//!
//! - The two published files in `tests/data/rgl`: brdfmill's reader gives Mitsuba's values (negative
//!   reflectance clipped, as brdfmill clips it), so a file means to brdfmill what it means to Mitsuba.
//! - Files brdfmill writes (an analytic BRDF, and `brdfmill export`'s `target.bsdf`, `design.bsdf`,
//!   `milled.bsdf`): Mitsuba loads them, its values agree with brdfmill's reader of the same file to float32
//!   precision, and with the BRDF brdfmill tabulated to the tabulation's resolution (relative L1, cosine
//!   weighted, under 2%); an image of the material under a directional light has the brightness that BRDF
//!   gives.
//!
//! Without Mitsuba these tests fail (they are ignored in `cargo test`; `.ci/run` installs Mitsuba and runs them).

use brdfmill::base::geometry::{spherical, Vec3};
use brdfmill::stages::brdf::rgl_write::{write_rgl, RglSource};
use brdfmill::stages::brdf::{Brdf, RglBsdf};
mod common;

use common::root;
use std::path::Path;
use std::process::Command;

type Rgb = [f64; 3];

/// A BRDF `f(wi, wo)` without the cosine.
type BrdfFn<'a> = &'a dyn Fn(&Vec3, &Vec3) -> Rgb;

/// The Python that has Mitsuba 3; panics with what to install when there is none.
fn python() -> String {
    let py = std::env::var("BRDFMILL_MITSUBA_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import mitsuba"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(
        ok,
        "needs Mitsuba 3: `{py}` cannot import mitsuba (pip install mitsuba, or point BRDFMILL_MITSUBA_PYTHON at a Python that has it)"
    );
    py
}

/// Direction pairs over the hemisphere: `cosθ` uniform in [0.0087, 1] for both (polar angles up to 89.5°),
/// azimuths uniform, from a fixed linear congruential sequence.
fn pairs(n: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let mut s = seed;
    let mut next = move || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut dir = move || {
        spherical(
            (0.0087 + (1.0 - 0.0087) * next()).acos(),
            std::f64::consts::TAU * next(),
        )
    };
    (0..n).map(|_| (dir(), dir())).collect()
}

/// What Mitsuba answered.
struct Answer {
    /// `eval` at each pair.
    values: Vec<Rgb>,
    /// The rendered square's mean pixel, when a light was given.
    render: Option<Rgb>,
    /// Per incident direction asked: the albedo by Mitsuba's own sampling, and the largest relative
    /// difference between a sample's pdf and `pdf` of its direction.
    albedo: Vec<(Rgb, f64)>,
}

/// Samples per albedo by Mitsuba's sampling (a stratified 200 × 200 grid).
const ALBEDO_SAMPLES: usize = 40_000;

/// Run Mitsuba on `bsdf`: `eval` at `pairs`, with `light` the rendered square, and the albedo at each of
/// `albedo_at`.
fn mitsuba(bsdf: &Path, pairs: &[(Vec3, Vec3)], light: Option<Vec3>, albedo_at: &[Vec3]) -> Answer {
    let dir = tempfile::tempdir().unwrap();
    let (dirs, out) = (dir.path().join("dirs.csv"), dir.path().join("out.csv"));
    let text: String = pairs
        .iter()
        .map(|(a, b)| {
            format!(
                "{:.17},{:.17},{:.17},{:.17},{:.17},{:.17}\n",
                a.x, a.y, a.z, b.x, b.y, b.z
            )
        })
        .collect();
    std::fs::write(&dirs, text).unwrap();
    let mut cmd = Command::new(python());
    cmd.arg(root().join("tests/mitsuba/measured_eval.py"))
        .arg(bsdf)
        .arg(&dirs)
        .arg(&out);
    if let Some(l) = light {
        cmd.arg("--light").args([l.x, l.y, l.z].map(|v| format!("{v:.17}")));
    }
    for w in albedo_at {
        cmd.arg("--albedo")
            .args([w.x, w.y, w.z].map(|v| format!("{v:.17}")))
            .arg(ALBEDO_SAMPLES.to_string());
    }
    let o = cmd.output().unwrap();
    assert!(
        o.status.success(),
        "Mitsuba on {}: {}",
        bsdf.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let mut a = Answer {
        values: vec![],
        render: None,
        albedo: vec![],
    };
    let num = |f: &str| -> f64 { f.parse().unwrap() };
    for line in std::fs::read_to_string(&out).unwrap().lines() {
        let f: Vec<&str> = line.split(',').collect();
        let rgb = |f: &[&str]| -> Rgb { std::array::from_fn(|c| num(f[c])) };
        match f[0] {
            "render" => a.render = Some(rgb(&f[1..])),
            "albedo" => a.albedo.push((rgb(&f[1..]), num(f[4]))),
            _ => a.values.push(rgb(&f)),
        }
    }
    assert_eq!(a.values.len(), pairs.len());
    assert_eq!(a.albedo.len(), albedo_at.len());
    a
}

/// The directional albedo `∫ f cosθo dωo` at `wi` by quadrature over the hemisphere in `(√(θ/90°), φ)`.
fn albedo(f: BrdfFn, wi: &Vec3) -> Rgb {
    let (nu, nphi) = (400, 300);
    let mut a = [0.0; 3];
    for iu in 0..nu {
        let u = (iu as f64 + 0.5) / nu as f64;
        let th = u * u * std::f64::consts::FRAC_PI_2;
        let jac = 2.0 * u * std::f64::consts::FRAC_PI_2 * th.sin() / nu as f64 * std::f64::consts::TAU / nphi as f64;
        for jp in 0..nphi {
            let wo = spherical(th, (jp as f64 + 0.5) / nphi as f64 * std::f64::consts::TAU);
            let v = f(wi, &wo);
            (0..3).for_each(|c| a[c] += v[c] * wo.z * jac);
        }
    }
    a
}

/// Relative L1 of `a` against `reference` over all channels: Σ|a − r| / Σ|r|.
fn relative_l1(a: &[Rgb], reference: &[Rgb]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (x, r) in a.iter().zip(reference) {
        for c in 0..3 {
            num += (x[c] - r[c]).abs();
            den += r[c].abs();
        }
    }
    num / den
}

/// The largest difference relative to the largest value (so float32 rounding of small values does not count
/// as much as of the peak).
fn worst_relative_to_peak(a: &[Rgb], reference: &[Rgb]) -> f64 {
    let peak = reference.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(reference)
        .flat_map(|(x, r)| (0..3).map(move |c| (x[c] - r[c]).abs()))
        .fold(0.0, f64::max)
        / peak
}

fn times_cos(f: impl Fn(&Vec3, &Vec3) -> Rgb, pairs: &[(Vec3, Vec3)]) -> Vec<Rgb> {
    pairs.iter().map(|(wi, wo)| f(wi, wo).map(|v| v * wo.z)).collect()
}

/// Check a written file against Mitsuba, brdfmill's reader and the BRDF it tabulates.
fn check_written(path: &Path, f: BrdfFn, what: &str) {
    let p = pairs(3000, 7);
    // near the mirror direction of the view, where even a narrow lobe is bright (a far tail would test the
    // tabulation's resolution, which the L1 below covers)
    let light = spherical(0.2, 0.3);
    let incident = [spherical(0.5, 0.3), spherical(1.3, -2.0)];
    let answer = mitsuba(path, &p, Some(light), &incident);
    let reader = RglBsdf::read(path).unwrap();
    let read = times_cos(|a, b| reader.eval(a, b), &p);
    let tabulated = times_cos(f, &p);
    let format = worst_relative_to_peak(&answer.values, &read);
    let l1 = relative_l1(&answer.values, &tabulated);
    // the square seen from the normal, lit from `light` with unit irradiance: L = f(view, light) cosθ_light
    let want = f(&Vec3::new(0.0, 0.0, 1.0), &light).map(|v| v * light.z);
    let got = answer.render.unwrap();
    let image = (0..3).map(|c| (got[c] / want[c] - 1.0).abs()).fold(0.0, f64::max);
    println!(
        "{what}: Mitsuba vs brdfmill's reader {format:.1e} of the peak; vs the tabulated BRDF relative L1 {l1:.4}; rendered square {got:?} vs {want:?} ({image:.4})"
    );
    assert!(
        format < 1e-3,
        "{what}: Mitsuba and brdfmill's reader differ by {format:e} of the peak"
    );
    assert!(
        l1 < 0.02,
        "{what}: Mitsuba's values differ from the tabulated BRDF by relative L1 {l1}"
    );
    assert!(image < 0.01, "{what}: rendered {got:?}, the BRDF gives {want:?}");
    // Mitsuba's importance sampling (the luminance and vndf warps) integrates to the BRDF's albedo
    for (wi, (sampled, pdf)) in incident.iter().zip(&answer.albedo) {
        let exact = albedo(f, wi);
        let rel = (0..3).map(|c| (sampled[c] / exact[c] - 1.0).abs()).fold(0.0, f64::max);
        println!(
            "{what}: at θi {:.0}°, albedo by Mitsuba's sampling {sampled:?}, by quadrature {exact:?} ({rel:.4}); pdf {pdf:.1e}",
            wi.z.acos().to_degrees()
        );
        assert!(
            rel < 0.03,
            "{what}: Mitsuba's sampled albedo {sampled:?}, the BRDF's {exact:?}"
        );
        assert!(*pdf < 1e-3, "{what}: a sample's pdf differs from pdf() by {pdf:e}");
    }
}

#[test]
#[ignore = "needs Mitsuba 3 (pip install mitsuba)"]
fn published_rgl_files_read_as_mitsuba_reads_them() {
    for name in ["paper_white_rgb.bsdf", "vch_golden_yellow_rgb.bsdf"] {
        let path = root().join("tests/data/rgl").join(name);
        let p = pairs(3000, 11);
        let theirs = mitsuba(&path, &p, None, &[]).values;
        // brdfmill clips negative reflectance (vch_golden_yellow's blue dips below zero near the peak,
        // down to −0.25 where green is 3.2); Mitsuba returns it as stored
        let theirs: Vec<Rgb> = theirs.iter().map(|v| v.map(|c| c.max(0.0))).collect();
        let r = RglBsdf::read(&path).unwrap();
        let ours = times_cos(|a, b| r.eval(a, b), &p);
        let worst = worst_relative_to_peak(&ours, &theirs);
        let l1 = relative_l1(&ours, &theirs);
        println!(
            "{name}: brdfmill's reader vs Mitsuba: largest difference {worst:.1e} of the peak, relative L1 {l1:.1e}"
        );
        assert!(
            worst < 1e-3 && l1 < 1e-3,
            "{name}: {worst:e} of the peak, relative L1 {l1:e}"
        );
    }
}

#[test]
#[ignore = "needs Mitsuba 3 (pip install mitsuba)"]
fn an_analytic_brdf_written_as_rgl_renders_in_mitsuba() {
    let dir = tempfile::tempdir().unwrap();
    for spec in [
        "ggx:ax=0.15,ay=0.3,material=gold",
        "beckmann:alpha=0.1,material=aluminium",
    ] {
        let b = Brdf::parse(spec).unwrap();
        let d = |m: &Vec3| b.known_ndf(m).unwrap();
        let f = |wi: &Vec3, wo: &Vec3| b.eval(wi, wo);
        let path = dir.path().join("analytic.bsdf");
        let src = RglSource {
            description: spec.into(),
            ndf: &d,
            brdf: &f,
        };
        write_rgl(&path, &src).unwrap();
        check_written(&path, &f, spec);
    }
}

/// `brdfmill export` on a small job's output: `target.bsdf`, `design.bsdf` and `milled.bsdf` hold, for
/// Mitsuba, the BRDFs the report shows (the target, and the microfacet BRDFs of the NDFs the verdict measured
/// with the target's material).
#[test]
#[ignore = "needs Mitsuba 3 (pip install mitsuba); runs a job (about 10 s)"]
fn exported_bsdf_files_render_in_mitsuba_as_the_report_shows_them() {
    let dir = tempfile::tempdir().unwrap();
    let job = dir.path().join("job");
    common::run_small_job(&job, &[]);
    common::brdfmill_ok(&["export", job.to_str().unwrap()]);
    // and a MERL target, whose file is parameterised by the half-angle distribution the job derived (with
    // a floor): a MERL table written here from Beckmann α 0.18 with gold's Fresnel, read as the job's target
    let table = dir.path().join("gold.binary");
    let model = Brdf::parse("beckmann:alpha=0.18,material=gold").unwrap();
    brdfmill::stages::brdf::Merl::from_fn(|a, b| model.eval(a, b))
        .write(&table)
        .unwrap();
    let merl = dir.path().join("merl");
    let spec = format!("merl:{},material=gold", table.display());
    common::run_small_job(&merl, &[&format!("target.brdf=\"{spec}\"")]);
    let exported = dir.path().join("merl-export");
    std::fs::create_dir(&exported).unwrap();
    common::brdfmill_ok(&["export", merl.to_str().unwrap(), "--out", exported.to_str().unwrap()]);
    let gold = Brdf::parse(&spec).unwrap();
    check_written(
        &exported.join("target.bsdf"),
        &|a, b| gold.eval(a, b),
        "MERL target.bsdf",
    );
    let brdfs = common::JobBrdfs::read(&job, "beckmann:alpha=0.2,material=aluminium");
    for (stem, f) in brdfs.each() {
        let name = format!("{stem}.bsdf");
        check_written(&job.join(&name), &*f, &name);
    }
}
