//! Facets stage benchmarks: periodic Poisson integration at 1024² and 2048², and annealing swaps.

use brdfmill::stages::facets::{Arrangement, PoissonSolver};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::{Rng, SeedableRng};

fn poisson(c: &mut Criterion) {
    let mut g = c.benchmark_group("poisson");
    g.sample_size(10);
    for n in [1024usize, 2048] {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let gx: Vec<f64> = (0..n * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let gy: Vec<f64> = (0..n * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut solver = PoissonSolver::new(n, n);
        let mut z = vec![0.0; n * n];
        g.throughput(Throughput::Elements((n * n) as u64));
        g.bench_function(format!("integrate_{n}x{n}"), |b| {
            b.iter(|| solver.integrate_edge_gradients(&gx, &gy, 0.01, &mut z))
        });
    }
    g.finish();
}

fn anneal_swaps(c: &mut Criterion) {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2);
    let slopes: Vec<(f64, f64)> = (0..1024)
        .map(|_| (rng.gen_range(-0.4..0.4), rng.gen_range(-0.4..0.4)))
        .collect();
    let mut a = Arrangement::new(32, 32, &slopes, 0.02);
    let mut g = c.benchmark_group("anneal");
    const SWAPS: u64 = 100_000;
    g.throughput(Throughput::Elements(SWAPS));
    g.bench_function("swap_delta_32x32", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for _ in 0..SWAPS {
                let (i, j) = (rng.gen_range(0..1024), rng.gen_range(0..1024));
                acc += a.swap(i, j);
            }
            acc
        })
    });
    g.finish();
}

criterion_group!(benches, poisson, anneal_swaps);
criterion_main!(benches);
