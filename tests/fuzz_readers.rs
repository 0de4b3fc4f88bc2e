//! Mutation fuzzing of every reader, seeded from real files: byte flips, truncations, insertions of
//! hostile text (huge or non-finite numbers, control characters, huge declared sizes), empty input. Each
//! mutated input must be read or refused — never a panic — and a refusal of a file names it.
//!
//! The case count per reader is `BRDFMILL_FUZZ_CASES` (default 24, so `cargo test` stays quick); the
//! campaign in docs/VALIDATION.md's reliability section is `BRDFMILL_FUZZ_CASES=80 cargo test --release --test
//! fuzz_readers -- --nocapture`, which prints the counts per reader. Inputs are reproducible: the random
//! stream is seeded per reader.

use brdfmill::cut::machine::Machine;
use brdfmill::gcode::program::Program;
use brdfmill::job::Job;
use brdfmill::stages::brdf::Brdf;
use brdfmill::stages::simulate::gcode::{self, ParseOptions};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

const HOSTILE: &[&str] = &[
    "1e308",
    "-1e308",
    "NaN",
    "inf",
    "99999999999999999999999999999999999999",
    "4611686018427387905",
    "-0",
    "\u{7}\n",
    "(",
    ")",
    "\u{0}",
    "[",
    "\"",
    "=",
];

fn cases() -> usize {
    std::env::var("BRDFMILL_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(24)
}

/// One mutation of `seed`.
fn mutate(seed: &[u8], rng: &mut Pcg64) -> Vec<u8> {
    let mut b = seed.to_vec();
    if b.is_empty() {
        return b;
    }
    match rng.gen_range(0..6) {
        0 => b.truncate(rng.gen_range(0..b.len())),
        1 => {
            for _ in 0..rng.gen_range(1..16) {
                let k = rng.gen_range(0..b.len());
                b[k] ^= 1 << rng.gen_range(0..8);
            }
        }
        2 | 3 => {
            let k = rng.gen_range(0..b.len());
            let s = HOSTILE[rng.gen_range(0..HOSTILE.len())].as_bytes();
            let end = (k + rng.gen_range(0..8)).min(b.len());
            b.splice(k..end, s.iter().copied());
        }
        4 => {
            // a huge little-endian count where the file declares sizes
            let k = rng.gen_range(0..b.len().saturating_sub(8).max(1));
            let v = [u64::MAX, 1 << 40, 0, 0x7FFF_FFFF][rng.gen_range(0..4)];
            let end = (k + 8).min(b.len());
            b.splice(k..end, v.to_le_bytes().iter().copied().take(end - k));
        }
        _ => b.clear(),
    }
    b
}

/// Run `read` over `n` mutations of `seed` written to `path`; count reads and refusals, fail on a panic
/// or on a refusal that does not name the file.
fn campaign(name: &str, seed: &[u8], path: &Path, n: usize, read: &dyn Fn(&Path) -> Result<(), String>) {
    let mut rng = Pcg64::seed_from_u64(name.bytes().map(u64::from).sum());
    let (mut ok, mut refused) = (0, 0);
    let file = path.file_name().unwrap().to_string_lossy().to_string();
    for k in 0..n {
        let bytes = mutate(seed, &mut rng);
        std::fs::write(path, &bytes).unwrap();
        match catch_unwind(AssertUnwindSafe(|| read(path))) {
            Ok(Ok(())) => ok += 1,
            Ok(Err(e)) => {
                assert!(
                    e.contains(&file),
                    "{name} case {k}: the refusal does not name the file: {e}"
                );
                refused += 1;
            }
            Err(_) => panic!(
                "{name} case {k}: the reader panicked (input kept at {})",
                path.display()
            ),
        }
    }
    println!("{name:>8}: {n} cases, {ok} read, {refused} refused, 0 panics");
}

fn data(p: &str) -> Vec<u8> {
    std::fs::read(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(p)).unwrap()
}

#[test]
fn mutated_files_are_read_or_refused_never_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let n = cases();
    let spec = |kind: &'static str| {
        move |p: &Path| {
            Brdf::parse(&format!("{kind}:{}", p.display()))
                .map(|_| ())
                .map_err(|e| {
                    format!(
                        "{e:#}: {}",
                        std::error::Error::source(&e).map(|s| s.to_string()).unwrap_or_default()
                    )
                })
        }
    };
    campaign(
        "rgl",
        &data("tests/data/rgl/vch_golden_yellow_rgb.bsdf"),
        &d.join("m.bsdf"),
        n,
        &spec("rgl"),
    );
    let csv: String = (0..10)
        .flat_map(|t| (0..8).map(move |p| format!("{},{},{}\n", t * 8, p * 45, 1.0 / (1.0 + t as f64))))
        .collect();
    campaign("csv", csv.as_bytes(), &d.join("m.csv"), n, &spec("csv"));
    // MERL: a small valid header and a short table (the reader refuses the wrong size; mutations probe the rest)
    let mut merl = Vec::new();
    for v in [90i32, 90, 180] {
        merl.extend_from_slice(&v.to_le_bytes());
    }
    merl.extend(std::iter::repeat_n(0u8, 4096));
    campaign("merl", &merl, &d.join("m.binary"), n, &spec("merl"));
    campaign(
        "x3p",
        &data("examples/data/sample-land.x3p"),
        &d.join("m.x3p"),
        n,
        &|p: &Path| brdfmill::base::x3p::read(p).map(|_| ()).map_err(|e| e.to_string()),
    );
    let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    let h = format!(
        "{:<117}\n",
        "{'descr': '<f8', 'fortran_order': False, 'shape': (4, 4), }"
    );
    npy.extend_from_slice(&(h.len() as u16).to_le_bytes());
    npy.extend_from_slice(h.as_bytes());
    npy.extend(std::iter::repeat_n(0u8, 128));
    campaign("npy", &npy, &d.join("m.npy"), n, &|p: &Path| {
        brdfmill::base::npy::read_f64_2d(p)
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    let program = b"%\n(header)\nG21 G90 G17\nM3 S10000\nG0 X0 Y0 Z3\nG1 Z-0.5 F100\nG2 X2 Y0 I1 J0\nG3 X0 Y0 R1\nG1 X1.5 Y-0.25\nG0 Z3\nM5\nM30\n%\n";
    campaign("gcode", program, &d.join("m.nc"), n, &|p: &Path| {
        let text = String::from_utf8_lossy(&std::fs::read(p).map_err(|e| e.to_string())?).to_string();
        let opt = ParseOptions {
            max_segments: 1_000_000,
            ..Default::default()
        };
        gcode::parse(&text, &opt).map_err(|e| format!("{}: {e}", p.display()))?;
        Program::parse(p, &text, 0, true).map(|_| ()).map_err(|e| e.to_string())
    });
    let machine = data("machines/grbl-3018.toml");
    campaign("machine", &machine, &d.join("m.toml"), n, &|p: &Path| {
        Machine::load(p).map(|_| ()).map_err(|e| e.to_string())
    });
    let root = env!("CARGO_MANIFEST_DIR");
    let job = String::from_utf8(data("examples/default.toml"))
        .unwrap()
        .replace("../machines/", &format!("{root}/machines/"));
    campaign("job", job.as_bytes(), &d.join("job.toml"), n, &|p: &Path| {
        Job::load(p).map(|_| ()).map_err(|e| e.to_string())
    });
}
