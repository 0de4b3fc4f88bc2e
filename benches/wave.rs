//! Wave-optics benchmarks (filled in with the wave module).
fn main() {}
