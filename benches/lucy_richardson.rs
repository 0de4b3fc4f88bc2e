//! Lucy–Richardson at 256² × 100 iterations with a Beckmann α = 0.1 base lobe (the kernel the `ndf` stage
//! builds for `--base beckmann:alpha=0.1`).

use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::ndf::{self, LucyRichardson, NdfConfig};
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let cfg = NdfConfig::default();
    let domain = cfg.domain();
    let target = Brdf::parse("beckmann:alpha=0.3").unwrap();
    let base = Brdf::parse("beckmann:alpha=0.1").unwrap();
    let (observed, _) = ndf::halfangle::half_angle_density(&target, domain, &cfg.half_angle);
    let (k, kw, kh) = ndf::base_kernel(&base, &domain, &cfg).unwrap();
    let mut lr = LucyRichardson::new(domain.nx, domain.ny, &k, kw, kh);
    let mut g = c.benchmark_group("lucy_richardson");
    g.sample_size(10);
    g.bench_function("256x256_100_iterations", |b| {
        b.iter(|| {
            let mut est = observed.density.clone();
            lr.run(&observed.density, &mut est, 100, 0.0)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
