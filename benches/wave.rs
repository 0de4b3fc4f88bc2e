//! Wave-optics throughput: one FFT slice at 1024² (one coherence window, three 2D FFTs plus resampling)
//! and Gabor-kernel evaluations (one direction over the ≈ 266k texel kernels (λ/4 texels) of one σ = 10 µm window).

use brdfmill::base::geometry::{spherical, Vec3};
use brdfmill::base::heightfield::Heightfield;
use brdfmill::stages::optics::wave::{self, GaborWindow, OpticalSurface, WaveConfig, Xi3};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn surface() -> OpticalSurface {
    let n = 128;
    let mut hf = Heightfield::flat(n, n, 0.001, true, 0.0);
    for j in 0..n {
        for i in 0..n {
            let u = (i % 32) as f64 - 16.0;
            hf.z_mm[j * n + i] = -(100.0 - (1e4 - u * u).sqrt()) * 1e-3 + 1e-4 * (j as f64 * 0.05).sin();
        }
    }
    OpticalSurface::new(&hf).unwrap()
}

fn bench(c: &mut Criterion) {
    let surf = surface();
    let wi = spherical(0.2, 0.4);
    let cfg = WaveConfig {
        windows: 1,
        fft_size: Some(1024),
        ..Default::default()
    };
    let mut g = c.benchmark_group("wave");
    g.sample_size(10);
    g.bench_function("fft_slice_1024", |b| {
        b.iter(|| wave::fft_slice(&surf, &wi, &cfg).unwrap())
    });
    let win = GaborWindow::new(&surf, (64.0, 64.0), 10.0, cfg.sample());
    g.throughput(Throughput::Elements(win.len() as u64));
    let wo = Vec3::new(0.1, 0.05, (1.0f64 - 0.0125).sqrt());
    g.bench_function("gabor_direction_one_window", |b| {
        b.iter(|| wave::gabor_eval_windows(std::slice::from_ref(&win), &wi, &wo, &cfg, Xi3::Exact))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
