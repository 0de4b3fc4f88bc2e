//! The facets stage's annealing with and without the exact step term (prints; no assertion), and the
//! measurement behind the default `step_weight`: rms step, relief, C and valleys over seeds 1–5 on the
//! default target. `cargo run --release --example bench_anneal [-- table]`.

use brdfmill::stages::{brdf::Brdf, facets, ndf};

fn main() {
    let n = ndf::run(
        &ndf::NdfConfig::default(),
        &Brdf::parse("beckmann:alpha=0.2").unwrap(),
        None,
    )
    .unwrap();
    let tile_cfg = |side: usize, seed: u64, sw: f64, rw: f64| {
        let mut cfg = facets::FacetsConfig {
            facets_x: side,
            facets_y: side,
            facet_mm: 1.0,
            pitch_um: 50.0,
            seed,
            ..Default::default()
        };
        cfg.anneal.step_weight = sw;
        cfg.anneal.relief_weight = rw;
        cfg
    };
    if std::env::args().nth(1).as_deref() == Some("table") {
        println!("step_weight relief_weight | rms step µm, relief µm, C, valleys (means over seeds 1–5)");
        for (sw, rw) in [
            (0.0, 0.0),
            (0.3, 0.0),
            (1.0, 0.0),
            (3.0, 0.0),
            (10.0, 0.0),
            (1.0, 0.1),
            (1.0, 1.0),
        ] {
            let mut sum = [0.0; 4];
            for seed in 1..=5 {
                let t = facets::run(&tile_cfg(12, seed, sw, rw), &n.target).unwrap();
                let (lo, hi) = t.heightfield.range();
                let row = [
                    t.seams.rms_um,
                    (hi - lo) * 1000.0,
                    t.anneal.energy.C,
                    t.anneal.energy.valleys,
                ];
                sum.iter_mut().zip(row).for_each(|(s, r)| *s += r / 5.0);
            }
            println!(
                "{sw:5} {rw:5} | {:6.1} {:7.0} {:.3} {:5.1}",
                sum[0], sum[1], sum[2], sum[3]
            );
        }
        return;
    }
    if std::env::args().nth(1).as_deref() == Some("sweeps") {
        println!("sweeps | energy E, rms step µm, C, valleys, relief µm (means over seeds 1–10), s per anneal");
        for sweeps in [1250, 2500, 5000, 10000, 20000] {
            let mut sum = [0.0; 6];
            for seed in 1..=10 {
                let mut cfg = tile_cfg(12, seed, 1.0, 0.0);
                cfg.anneal.sweeps = sweeps;
                let t0 = std::time::Instant::now();
                let t = facets::run(&cfg, &n.target).unwrap();
                let (lo, hi) = t.heightfield.range();
                let row = [
                    t.anneal.energy.total(),
                    t.seams.rms_um,
                    t.anneal.energy.C,
                    t.anneal.energy.valleys,
                    (hi - lo) * 1000.0,
                    t0.elapsed().as_secs_f64(),
                ];
                sum.iter_mut().zip(row).for_each(|(s, r)| *s += r / 10.0);
            }
            println!(
                "{sweeps:6} | {:.4} {:6.2} {:.4} {:5.1} {:6.0} {:.2}",
                sum[0], sum[1], sum[2], sum[3], sum[4], sum[5]
            );
        }
        return;
    }
    for side in [12usize, 32] {
        for (sw, rw) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)] {
            let t0 = std::time::Instant::now();
            let t = facets::run(&tile_cfg(side, 1, sw, rw), &n.target).unwrap();
            println!(
                "N = {:4}, step_weight {sw}, relief_weight {rw}: facets stage {:.2} s ({} proposals, {:.3} accepted)",
                side * side,
                t0.elapsed().as_secs_f64(),
                t.anneal.proposals,
                t.anneal.accepted as f64 / t.anneal.proposals as f64
            );
        }
    }
}
