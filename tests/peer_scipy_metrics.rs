//! Cross-check against peers: the verdict's distances on grids whose figures SciPy 1.17 and NumPy 2.4
//! computed (arrays and figures in `tests/data/peers/scipy/`, written by `scripts/peer_scipy_metrics.py`).
//!
//! - Jensen–Shannon divergence in bits: `scipy.spatial.distance.jensenshannon(a, b, base=2)²` (SciPy returns
//!   the distance, the divergence's square root);
//! - relative L1 `∑|a − b| / ∑|b|` and Pearson correlation (`numpy.corrcoef`);
//! - the slope variances behind the verdict's variance ratios (`numpy.cov` with `aweights`, `ddof = 0`).
//!
//! The cases are a smooth pair, a pair with disjoint zero cells (SciPy's `rel_entr` takes `0·log 0` as 0),
//! and spikes on a floor of 1e-9 against a broad lobe (a flat-facet design against a measured lobe). The
//! figures are sums of a few thousand terms of order 1: both sides round to about 1e-13, so 1e-10 relative.

use brdfmill::base::distance::{correlation, jensen_shannon, relative_l1};
use brdfmill::base::npy::read_f64_2d;
use brdfmill::base::slope::{SlopeDomain, SlopeGrid};
use std::path::PathBuf;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/peers/scipy")
}

/// A case's two grids on the slope domain [-1, 1]² the script's cell centres assume.
fn grids(case: &str) -> (SlopeGrid, SlopeGrid) {
    let read = |side: &str| {
        let p = dir().join(format!("{case}_{side}.npy"));
        read_f64_2d(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let ((ny, nx, a), (ny_b, nx_b, b)) = (read("a"), read("b"));
    assert_eq!((ny, nx), (ny_b, nx_b), "{case}: shapes differ");
    let domain = SlopeDomain {
        nx,
        ny,
        p_min: -1.0,
        p_max: 1.0,
        q_min: -1.0,
        q_max: 1.0,
    };
    (SlopeGrid { domain, density: a }, SlopeGrid { domain, density: b })
}

/// The peers' figures, `metrics.json`.
fn peers() -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir().join("metrics.json")).unwrap()).expect("metrics.json")
}

fn close(ours: f64, theirs: f64, what: &str) {
    assert!(
        (ours - theirs).abs() <= 1e-10 * theirs.abs().max(1e-3),
        "{what}: brdfmill {ours:.15e}, peer {theirs:.15e}"
    );
}

#[test]
fn the_verdicts_distances_agree_with_scipy_and_numpy() {
    let peers = peers();
    let cases = peers["cases"].as_object().expect("cases");
    assert_eq!(cases.len(), 3);
    for (case, want) in cases {
        let (a, b) = grids(case);
        let num = |k: &str| want[k].as_f64().unwrap_or_else(|| panic!("{case}: {k}"));
        close(
            jensen_shannon(&a.density, &b.density),
            num("js_bits"),
            &format!("{case} JS"),
        );
        close(
            jensen_shannon(&b.density, &a.density),
            num("js_bits"),
            &format!("{case} JS swapped"),
        );
        close(a.relative_l1(&b), num("l1_rel"), &format!("{case} L1"));
        close(
            relative_l1(&a.density, &b.density),
            num("l1_rel"),
            &format!("{case} L1"),
        );
        close(
            correlation(&a.density, &b.density),
            num("corr"),
            &format!("{case} corr"),
        );
        let s = b.stats();
        close(s.cov[0][0], num("var_p"), &format!("{case} var p"));
        close(s.cov[1][1], num("var_q"), &format!("{case} var q"));
    }
}

/// The figures differ enough between the cases that a metric returning a constant (0 bits, say) fails.
#[test]
fn the_peer_cases_span_the_range() {
    let peers = peers();
    let js: Vec<f64> = ["smooth", "sparse", "spiky"]
        .iter()
        .map(|c| peers["cases"][c]["js_bits"].as_f64().unwrap())
        .collect();
    assert!(js[0] < 0.1 && js[1] > 0.5 && js[2] > 0.9, "{js:?}");
}
