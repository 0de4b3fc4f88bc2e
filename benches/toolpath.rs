//! Drop-cutter throughput: CL points per second for a 1024² heightfield with a 1 mm ball at 10 µm pitch.

use brdfmill::base::heightfield::Heightfield;
use brdfmill::cut::dropcutter::{DropCutter, Edge};
use brdfmill::cut::tool::Shape;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn bench(c: &mut Criterion) {
    let n = 1024;
    let mut hf = Heightfield::flat(n, n, 0.01, true, 0.0);
    for (k, z) in hf.z_mm.iter_mut().enumerate() {
        let (x, y) = ((k % n) as f64 / n as f64, (k / n) as f64 / n as f64);
        *z = -0.1
            + 0.05 * (std::f64::consts::TAU * (3.0 * x + y)).sin()
            + 0.03 * (std::f64::consts::TAU * 5.0 * y).cos();
    }
    let dc = DropCutter::new(&hf, Shape::Ball { diameter_mm: 1.0 }, Edge::Periodic);
    let mut g = c.benchmark_group("dropcutter");
    g.sample_size(10);
    g.throughput(Throughput::Elements((n * n) as u64));
    g.bench_function("ball_1mm_1024x1024_10um", |b| b.iter(|| dc.surface()));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
