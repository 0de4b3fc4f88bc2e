//! Periodic Poisson integration of edge gradients on an N×N grid (default 1024 and 2048), printed as
//! milliseconds per solve and Msamples/s. With DUMP_DIR, writes the gradients as `gx_N.npy`, `gy_N.npy` so
//! `scripts/bench_poisson_vs_numpy.py` runs NumPy's FFT Frankot–Chellappa on the same data.
//!
//! `cargo run --release --example bench_poisson -- [RUNS] [DUMP_DIR]`

use brdfmill::stages::facets::PoissonSolver;
use rand::{Rng, SeedableRng};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(5);
    for n in [1024usize, 2048] {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(n as u64);
        let gx: Vec<f64> = (0..n * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let gy: Vec<f64> = (0..n * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        if let Some(dir) = args.get(2) {
            let dir = std::path::Path::new(dir);
            brdfmill::base::npy::write_f64_2d(&dir.join(format!("gx_{n}.npy")), n, n, &gx).unwrap();
            brdfmill::base::npy::write_f64_2d(&dir.join(format!("gy_{n}.npy")), n, n, &gy).unwrap();
        }
        let t = Instant::now();
        let mut solver = PoissonSolver::new(n, n);
        let plan = t.elapsed().as_secs_f64();
        let mut z = vec![0.0; n * n];
        let mut times = vec![];
        for _ in 0..runs {
            let t = Instant::now();
            solver.integrate_edge_gradients(&gx, &gy, 1.0, &mut z);
            times.push(t.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let m = times[times.len() / 2];
        println!(
            "poisson {n}x{n}: median {:.1} ms/solve over {runs} runs ({:.1} Msamples/s), plan {:.1} ms, {} rayon threads",
            m * 1e3,
            (n * n) as f64 / m / 1e6,
            plan * 1e3,
            rayon::current_num_threads()
        );
    }
}
