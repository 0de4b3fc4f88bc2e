//! Sweep throughput in swept cells per second: a zigzag finishing raster (1 mm ball, 0.063 mm stepover,
//! points every 10 µm over a wavy surface) across 2×2 mm of stock at 5 µm.

use brdfmill::stages::simulate::{self, Shape, SimulateConfig};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::fmt::Write;

fn program() -> String {
    let mut g = String::from("G21 G90 G17\nG0 X0 Y0 Z1\nG1 Z-0.1 F1000\n");
    let (step, n) = (0.0632, 32);
    for k in 0..n {
        let y = k as f64 * step;
        let xs: Vec<f64> = (0..=200).map(|i| i as f64 * 0.01).collect();
        let it: Box<dyn Iterator<Item = &f64>> = if k % 2 == 0 {
            Box::new(xs.iter())
        } else {
            Box::new(xs.iter().rev())
        };
        for x in it {
            let z = -0.1 + 0.03 * (x * 3.0).sin() * (y * 2.0).cos();
            let _ = writeln!(g, "X{x:.4} Y{y:.4} Z{z:.4}");
        }
    }
    g.push_str("G0 Z1\nM2\n");
    g
}

fn bench(c: &mut Criterion) {
    let text = program();
    let cfg = SimulateConfig {
        tool: Shape::Ball { diameter_mm: 1.0 },
        pitch_um: 5.0,
        ..Default::default()
    };
    let cells = simulate::run(&text, &cfg).unwrap().stats.swept_cells;
    let mut g = c.benchmark_group("simulate");
    g.sample_size(10);
    g.throughput(Throughput::Elements(cells));
    g.bench_function("ball_1mm_raster_2x2mm_5um", |b| {
        b.iter(|| simulate::run(&text, &cfg).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
