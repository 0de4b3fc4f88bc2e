//! Drop-cutter throughput: the full ball-nose CL surface of an N×N heightfield (default 1024) at 10 µm pitch
//! with a 1 mm ball, printed as CL points per second. With DUMP_DIR, also writes a 256² heightfield and its
//! CL surface (`hf_256.npy`, `cl_256.npy`) so `scripts/bench_dropcutter_vs_ocl.py` runs OpenCAMLib's
//! BatchDropCutter on the same surface and compares the heights.
//!
//! `cargo run --release --example bench_dropcutter -- [N] [DUMP_DIR]`

use brdfmill::base::heightfield::Heightfield;
use brdfmill::cut::dropcutter::{DropCutter, Edge};
use brdfmill::cut::tool::Shape;
use std::time::Instant;

/// A smooth random-looking periodic surface (sum of sinusoids), 0.2 mm deep.
fn surface(n: usize, pitch: f64) -> Heightfield {
    let mut hf = Heightfield::flat(n, n, pitch, true, 0.0);
    let l = n as f64 * pitch;
    for j in 0..n {
        for i in 0..n {
            let (x, y) = ((i as f64 + 0.5) * pitch / l, (j as f64 + 0.5) * pitch / l);
            let tau = std::f64::consts::TAU;
            hf.z_mm[j * n + i] = -0.1
                + 0.05 * (tau * (3.0 * x + y)).sin()
                + 0.03 * (tau * (5.0 * y - 2.0 * x)).cos()
                + 0.02 * (tau * 9.0 * x).sin() * (tau * 7.0 * y).cos();
        }
    }
    hf
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1024);
    let hf = surface(n, 0.01);
    let dc = DropCutter::new(&hf, Shape::Ball { diameter_mm: 1.0 }, Edge::Periodic);
    let t = Instant::now();
    let cl = dc.surface();
    let s = t.elapsed().as_secs_f64();
    println!(
        "dropcutter {n}x{n} at 10 µm, 1 mm ball: {:.2} s, {:.3} M CL points/s, {} rayon threads",
        s,
        (n * n) as f64 / s / 1e6,
        rayon::current_num_threads()
    );
    if let Some(dir) = args.get(2) {
        let small = surface(256, 0.01);
        let cl = DropCutter::new(&small, Shape::Ball { diameter_mm: 1.0 }, Edge::Open).surface();
        let dir = std::path::Path::new(dir);
        small.write_npy(&dir.join("hf_256.npy")).unwrap();
        cl.write_npy(&dir.join("cl_256.npy")).unwrap();
        let t = Instant::now();
        let _ = DropCutter::new(&small, Shape::Ball { diameter_mm: 1.0 }, Edge::Open).surface();
        println!("dropcutter 256x256 open edges: {:.4} s", t.elapsed().as_secs_f64());
    }
    std::hint::black_box(cl);
}
