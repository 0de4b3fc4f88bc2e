//! The virtual controller's fault-trial programs: random cuts in a 20 × 20 mm square, a third of them
//! helical arcs, half of those in `R` form. Shared by `tests/stream_emulator.rs` (the fault trials on the
//! virtual controller) and `tests/grbl_firmware.rs` (the same programs read by the real firmware).
#![allow(dead_code)]

/// A small deterministic generator (xorshift).
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// A program of random cuts in a 20 × 20 mm square, every motion line with a distinct end point; about a
/// third of them helical arcs (G2 or G3, bulging to either side by up to their chord), which GRBL plans
/// chord by chord and answers only once the last chord is planned.
pub fn random_program(rng: &mut Rng, moves: usize) -> String {
    let mut t = String::from("G21 G90\nG0 X0 Y0 Z2\nM3 S8000\nG1 Z-0.5 F1200\n");
    let (mut px, mut py) = (0.0f64, 0.0f64);
    for i in 0..moves {
        // Cuts of at least 3 mm, so that the planner is busy when a fault comes.
        let (x, y) = loop {
            let x = rng.below(20_000) as f64 / 1000.0;
            let y = rng.below(20_000) as f64 / 1000.0;
            if (x - px).hypot(y - py) >= 3.0 {
                break (x, y);
            }
        };
        let z = -0.5 - (i % 5) as f64 * 0.01;
        if rng.below(3) == 0 {
            // the centre on the chord's perpendicular bisector, up to half a chord to either side
            let (dx, dy) = (x - px, y - py);
            let h = (rng.below(2001) as f64 / 1000.0 - 1.0) * 0.5;
            let (cx, cy) = ((px + x) / 2.0 - h * dy, (py + y) / 2.0 + h * dx);
            let g = if rng.below(2) == 0 { 2 } else { 3 };
            if i % 2 == 0 {
                t += &format!("G{g} X{x:.3} Y{y:.3} Z{z:.3} I{:.3} J{:.3}\n", cx - px, cy - py);
            } else {
                // every other arc in radius form: positive the short way (the centre left of the chord
                // for G3, right for G2), negative the long way; rounded up, a micrometre or two beyond
                // half the chord, which GRBL would refuse below it (error:34)
                let r = ((cx - px).hypot(cy - py) * 1000.0 + 1.0).ceil() / 1000.0;
                let short = (g == 3) == (h >= 0.0);
                t += &format!("G{g} X{x:.3} Y{y:.3} Z{z:.3} R{}{r:.3}\n", if short { "" } else { "-" });
            }
        } else {
            t += &format!("G1 X{x:.3} Y{y:.3} Z{z:.3}\n");
        }
        (px, py) = (x, y);
    }
    t += "G0 Z5\nM5\n";
    t
}
