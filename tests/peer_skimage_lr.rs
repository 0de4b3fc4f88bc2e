//! Cross-check against a peer: scikit-image 0.26's `richardson_lucy` (arrays and results in
//! `tests/data/peers/skimage/`, written by `scripts/peer_skimage_lr.py`).
//!
//! Both sides compute the same operation, so every cell is compared. scikit-image iterates
//! `est ← est · (K̂ ⊛ (O / (est ⊛ K + 1e-12)))` from `est = 0.5`, with scipy's linear `convolve(…, 'same')`
//! (zeros outside the grid, odd kernels centred on their middle); brdfmill's [`LucyRichardson`] does the same
//! convolutions with zero-padded FFTs (padding ≥ n + m per axis, so nothing wraps) and is started from 0.5
//! here too; the checked-in kernels have unit sum, which brdfmill's normalisation leaves as it is.
//!
//! What differs, and the bound it gives:
//! * scikit-image adds 1e-12 to the denominator `c = est ⊛ K`; brdfmill divides by `c` itself (and sets the
//!   ratio to 0 only where `c` ≤ 1e-12·max O, which happens nowhere here). That moves the ratio `O / c` by
//!   `O · 1e-12 / c²`, so one iteration moves a cell by about `1e-12 · (est / c) · (O / c)`. Near the
//!   iteration's fixed point `c ≈ O` and, for these smooth estimates, `est ≈ c`: about 1e-12 (absolute, the
//!   values are of order 1) per iteration, whatever the cell's own size — largest, relative to the cell, at
//!   the faint edge of `compact`'s support. The moves add up over n iterations (the update does not amplify
//!   them): at most about n · 1e-12.
//! * Rounding: scipy picks direct sums or FFTs, brdfmill FFTs; each convolution is exact to a few ulp of its
//!   largest term (≈ 1e-15 of max O) and adds at most n · 1e-15, far below the first item.
//! * brdfmill clamps the estimate at 0; scipy's FFT path leaves values like −5e-164 where the true value is
//!   0 (the `compact` case's empty margin). These are below any tolerance.
//!
//! So the test asserts max |ours − theirs| ≤ 2 · n · 1e-12 · max |theirs| over every cell (twice the estimate
//! above): 1e-10 for `smooth` (50 iterations), 6e-11 for `compact` (30). Measured: 6.1e-12 and 2.2e-11.
//! The comparison sees the boundary: the same iteration with periodic or mirrored edges instead of zeros
//! (scipy.ndimage's `wrap` / `reflect`) ends 0.74 of the maximum away from scikit-image on `smooth`.
//! `compact` is zero near its edges, so it checks the kernel's orientation instead (last test).

use brdfmill::base::npy::read_f64_2d;
use brdfmill::stages::ndf::LucyRichardson;
use std::path::PathBuf;

fn data(name: &str) -> (usize, usize, Vec<f64>) {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/peers/skimage")
        .join(name);
    read_f64_2d(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Runs brdfmill on the case's arrays; returns (max |Δ| / max |theirs|, max |theirs|).
fn compare(case: &str, iterations: usize) -> (f64, f64) {
    let (ny, nx, observed) = data(&format!("{case}_observed.npy"));
    let (kh, kw, kernel) = data(&format!("{case}_kernel.npy"));
    let (ry, rx, theirs) = data(&format!("{case}_skimage.npy"));
    assert_eq!((ry, rx), (ny, nx), "{case}: result shape");
    let ksum: f64 = kernel.iter().sum();
    assert!((ksum - 1.0).abs() < 1e-12, "{case}: kernel sum {ksum}");
    let mut lr = LucyRichardson::new(nx, ny, &kernel, kw, kh);
    let mut ours = vec![0.5; nx * ny];
    let rep = lr.run(&observed, &mut ours, iterations, 0.0);
    assert_eq!(rep.iterations, iterations, "{case}: brdfmill stopped early");
    let scale = theirs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let (mut worst, mut at) = (0.0f64, 0);
    for (k, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        let d = (a - b).abs();
        if d > worst {
            worst = d;
            at = k;
        }
    }
    println!(
        "{case}: {nx}×{ny}, kernel {kw}×{kh}, {iterations} iterations: max |Δ| = {worst:.3e} at ({}, {}) \
         (ours {:.12e}, scikit-image {:.12e}), {:.3e} of max {scale:.6}",
        at % nx,
        at / nx,
        ours[at],
        theirs[at],
        worst / scale
    );
    (worst / scale, scale)
}

/// The bound derived above, relative to the largest value: 2 · n · 1e-12.
fn tolerance(iterations: usize) -> f64 {
    2.0 * iterations as f64 * 1e-12
}

#[test]
fn smooth_blobs_agree_with_scikit_image_cell_by_cell() {
    let (rel, scale) = compare("smooth", 50);
    assert!(scale > 0.5, "reference looks empty");
    assert!(
        rel <= tolerance(50),
        "smooth: relative difference {rel:.3e} > {:.1e}",
        tolerance(50)
    );
}

#[test]
fn compact_support_and_asymmetric_kernel_agree_with_scikit_image_cell_by_cell() {
    let (rel, scale) = compare("compact", 30);
    assert!(scale > 0.5, "reference looks empty");
    assert!(
        rel <= tolerance(30),
        "compact: relative difference {rel:.3e} > {:.1e}",
        tolerance(30)
    );
}

/// The check can fail: the same arrays with the kernel mirrored (the orientation a transposed or flipped
/// convolution would use) or a different iteration count disagree far beyond the tolerance.
#[test]
fn a_mirrored_kernel_or_another_iteration_count_is_seen() {
    let (ny, nx, observed) = data("compact_observed.npy");
    let (kh, kw, kernel) = data("compact_kernel.npy");
    let (_, _, theirs) = data("compact_skimage.npy");
    let scale = theirs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mirrored: Vec<f64> = kernel.iter().rev().copied().collect();
    for (k, iterations, what) in [(&mirrored, 30, "mirrored kernel"), (&kernel, 29, "29 iterations")] {
        let mut lr = LucyRichardson::new(nx, ny, k, kw, kh);
        let mut est = vec![0.5; nx * ny];
        lr.run(&observed, &mut est, iterations, 0.0);
        let worst = est.iter().zip(&theirs).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(
            worst / scale > 1e-4,
            "{what}: only {:.3e} from the reference",
            worst / scale
        );
    }
}
