//! Throughput of Lucy–Richardson at 256² × 100 iterations (the grid and kernel the `ndf` stage uses for
//! `--brdf beckmann:alpha=0.3 --base beckmann:alpha=0.1`), printed as time per run and cell-iterations/s.
//!
//! `cargo run --release --example bench_lucy_richardson -- [RUNS] [DUMP_DIR]` — with DUMP_DIR, also writes
//! `observed.npy` and `kernel.npy` so `scripts/bench_lr_vs_skimage.py` runs scikit-image on the same arrays.

use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::ndf::{self, LucyRichardson, NdfConfig};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let cfg = NdfConfig::default();
    let d = cfg.domain();
    let (observed, _) =
        ndf::halfangle::half_angle_density(&Brdf::parse("beckmann:alpha=0.3").unwrap(), d, &cfg.half_angle);
    let (k, kw, kh) = ndf::base_kernel(&Brdf::parse("beckmann:alpha=0.1").unwrap(), &d, &cfg).unwrap();
    if let Some(dir) = args.get(2) {
        let dir = std::path::Path::new(dir);
        brdfmill::base::npy::write_f64_2d(&dir.join("observed.npy"), d.ny, d.nx, &observed.density).unwrap();
        brdfmill::base::npy::write_f64_2d(&dir.join("kernel.npy"), kh, kw, &k).unwrap();
    }
    let mut lr = LucyRichardson::new(d.nx, d.ny, &k, kw, kh);
    let mut times = vec![];
    for _ in 0..runs {
        let mut est = observed.density.clone();
        let t = Instant::now();
        lr.run(&observed.density, &mut est, 100, 0.0);
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let (px, py) = lr.padded_size();
    println!(
        "lucy_richardson 256x256 kernel {kw}x{kh} fft {px}x{py} 100 iterations: median {:.1} ms/run over {runs} runs, {:.1} M cell-iterations/s, {} rayon threads",
        median * 1e3,
        (d.nx * d.ny * 100) as f64 / median / 1e6,
        rayon::current_num_threads()
    );
}
