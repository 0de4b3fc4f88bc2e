//! The NDF stage's acceptance figures (issue "Foundation …"), each against an independent truth:
//! closed-form slope variances, the analytic P22, and a MERL file written from a model and read back.

use brdfmill::base::slope::SlopeGrid;
use brdfmill::stages::brdf::{Brdf, Family, Merl, Microfacet};
use brdfmill::stages::ndf::{self, NdfConfig, StoppedBy};

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b
}

#[test]
fn beckmann_without_base_has_slope_variance_alpha2_over_2() {
    let n = ndf::run(&NdfConfig::default(), &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
    let c = n.stats.cov;
    println!("beckmann 0.3, no base: cov {c:?}");
    assert!(rel(c[0][0], 0.045) < 0.02 && rel(c[1][1], 0.045) < 0.02, "{c:?}");
    assert!(c[0][1].abs() < 1e-4);
    assert!((n.stats.mass - 1.0).abs() < 1e-9);
    assert_eq!(n.deconvolution.stopped_by, StoppedBy::None);
}

#[test]
fn deconvolving_a_beckmann_base_subtracts_its_variance() {
    let n = ndf::run(
        &NdfConfig::default(),
        &Brdf::parse("beckmann:alpha=0.3").unwrap(),
        Some(&Brdf::parse("beckmann:alpha=0.1").unwrap()),
    )
    .unwrap();
    let c = n.stats.cov;
    println!("beckmann 0.3 ⊘ 0.1: cov {c:?}, {:?}", n.deconvolution);
    // Gaussian slope densities convolve: variances add, (0.3² − 0.1²)/2 = 0.04.
    assert!(rel(c[0][0], 0.04) < 0.05 && rel(c[1][1], 0.04) < 0.05, "{c:?}");
    assert!(n.target.density.iter().all(|v| *v >= 0.0));
    assert!((n.stats.mass - 1.0).abs() < 1e-9);
    // The observed distribution is kept as it was measured.
    assert!(rel(n.observed_stats.cov[0][0], 0.045) < 0.02);
}

fn analytic_on_grid(m: &Microfacet, like: &SlopeGrid) -> SlopeGrid {
    let mut g = SlopeGrid::from_fn(like.domain, |p, q| m.p22(p, q));
    g.normalise();
    g
}

#[test]
fn anisotropic_ggx_recovers_the_analytic_p22() {
    let n = ndf::run(&NdfConfig::default(), &Brdf::parse("ggx:ax=0.1,ay=0.3").unwrap(), None).unwrap();
    let m = Microfacet::new(Family::Ggx, 0.1, 0.3).unwrap();
    // Both normalised over the grid: the tail beyond tan 60° is not part of the target.
    let l1 = n.target.relative_l1(&analytic_on_grid(&m, &n.target));
    println!("ggx ax=0.1 ay=0.3: relative L1 {l1:.5}");
    assert!(l1 <= 0.02, "relative L1 {l1}");
    // Anisotropy survives: more spread along y.
    assert!(n.stats.cov[1][1] > 4.0 * n.stats.cov[0][0]);
}

#[test]
fn merl_file_from_a_model_gives_the_model_ndf() {
    let brdf = Brdf::parse("beckmann:alpha=0.2,material=aluminium").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("beckmann_0.2.binary");
    Merl::from_fn(|wi, wo| brdf.eval(wi, wo)).write(&path).unwrap();
    let measured = Brdf::parse(&format!("merl:{}", path.display())).unwrap();
    let cfg = NdfConfig::default();
    let from_file = ndf::run(&cfg, &measured, None).unwrap();
    let m = Microfacet::new(Family::Beckmann, 0.2, 0.2).unwrap();
    let l1 = from_file.target.relative_l1(&analytic_on_grid(&m, &from_file.target));
    let from_model = ndf::run(&cfg, &brdf, None).unwrap();
    let l1_model = from_file.target.relative_l1(&from_model.target);
    println!("MERL(beckmann 0.2): L1 vs analytic {l1:.5}, vs model's own ndf {l1_model:.5}");
    assert!(l1 <= 0.02 && l1_model <= 0.02, "{l1} {l1_model}");
}

#[test]
fn rgl_files_give_unit_mass_ndfs() {
    let mut var = vec![];
    for name in ["paper_white_rgb.bsdf", "vch_golden_yellow_rgb.bsdf"] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/rgl")
            .join(name);
        let brdf = Brdf::parse(&format!("rgl:{}", path.display())).unwrap();
        let n = ndf::run(&NdfConfig::default(), &brdf, None).unwrap();
        println!("{name}: {:?}", n.stats);
        assert!((n.stats.mass - 1.0).abs() < 1e-9);
        assert_eq!(n.source, ndf::Source::MeasuredNdf);
        assert!(n.stats.cov[0][0] > 0.0 && n.stats.mean[0].abs() < 1e-9);
        var.push(n.stats.cov[0][0]);
    }
    assert!(
        var[1] < 0.5 * var[0],
        "vinyl lobe should be far narrower than paper's: {var:?}"
    );
}

#[test]
fn ndf_of_blinn_phong_matches_its_beckmann_equivalent_variance() {
    // A cosⁿ lobe has slope variance ≈ 1/(n+2) per axis (Walter et al. 2007, α² = 2/(n+2)).
    let n = ndf::run(&NdfConfig::default(), &Brdf::parse("blinn:n=100").unwrap(), None).unwrap();
    let c = n.stats.cov[0][0];
    assert!(rel(c, 1.0 / 102.0) < 0.05, "{c}");
}
