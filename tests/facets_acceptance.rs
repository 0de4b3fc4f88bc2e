//! The facets stage's acceptance figures (issue "Facets: …") on the issue's own example, `beckmann:alpha=0.3`
//! with 32×32 facets: slope statistics against the closed form, a two-sample test against the NDF, CVT
//! against plain importance sampling, the annealed energy against random arrangements, and seams.

use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::facets::{self, FacetsConfig};
use brdfmill::stages::ndf::{self, NdfConfig};

fn tile() -> facets::Tile {
    let n = ndf::run(&NdfConfig::default(), &Brdf::parse("beckmann:alpha=0.3").unwrap(), None).unwrap();
    // 100 µm pitch: the statistics do not depend on the raster, which is tested elsewhere.
    let cfg = FacetsConfig {
        pitch_um: 100.0,
        ..Default::default()
    };
    facets::run(&cfg, &n.target).unwrap()
}

#[test]
fn beckmann_tile_meets_the_issue_figures() {
    let t = tile();
    let c = t.slope_stats.cov;
    let s = &t.sampling;
    let (e, r) = (&t.anneal.energy, &t.anneal.energy_random);
    println!("cov {c:?}");
    println!(
        "KS: iid {:.4} halton {:.4} cvt {:.4}; energy test p {:.3}",
        s.ks_random, s.ks_halton, s.ks_cvt, s.energy_p_value
    );
    println!("energy {e:?}\nrandom {r:?}\nratio {:.4}", e.total() / r.total());
    println!("seams {:?}", t.seams);
    for d in [c[0][0], c[1][1]] {
        assert!(
            (d - 0.045).abs() <= 0.03 * 0.045,
            "slope variance {d} not within 3% of 0.045"
        );
    }
    assert!(
        s.energy_p_value >= 0.05,
        "two-sample test rejects the facets: p = {}",
        s.energy_p_value
    );
    assert!(
        s.ks_cvt < s.ks_random,
        "CVT {} should beat i.i.d. importance sampling {}",
        s.ks_cvt,
        s.ks_random
    );
    assert!(
        e.total() <= 0.10 * r.total(),
        "energy {} > 10% of random {}",
        e.total(),
        r.total()
    );
    assert!(
        e.valleys <= 0.5 * r.valleys,
        "valleys {} > half of random {}",
        e.valleys,
        r.valleys
    );
    // The tile joins itself as well as it joins inside.
    assert!(t.seams.max_seam_um <= t.seams.max_interior_um, "{:?}", t.seams);
    // Zero mean slope: every row's heights close up.
    assert!(t.slope_stats.mean[0].abs() < 1e-12 && t.slope_stats.mean[1].abs() < 1e-12);
    // The energy trace starts at the random start and ends at the result.
    let tr = &t.anneal.trace;
    assert!(tr[0] > 0.5 * r.total() && (tr[tr.len() - 1] - e.total()).abs() < 1e-6 * r.total());
}

#[test]
fn heightfield_is_periodic_and_follows_the_facet_planes() {
    let t = tile();
    let hf = &t.heightfield;
    let a = &t.arrangement;
    let m = t.config.samples_per_facet();
    assert!(hf.periodic && hf.nx == a.w * m && hf.ny == a.h * m);
    assert!(hf.range().1.abs() < 1e-12, "top of the tile at z = 0");
    // finite-difference slopes inside a facet are the facet's slopes
    for k in [0, 37, 500, 1023] {
        let (fx, fy) = (k % a.w, k / a.w);
        let (i, j) = (fx * m + m / 2, fy * m + m / 2);
        let dzdx = (hf.at(i + 1, j) - hf.at(i - 1, j)) / (2.0 * hf.pitch_mm);
        let dzdy = (hf.at(i, j + 1) - hf.at(i, j - 1)) / (2.0 * hf.pitch_mm);
        assert!((dzdx - a.p[k]).abs() < 1e-9 && (dzdy - a.q[k]).abs() < 1e-9);
    }
}
