//! Write a MERL `.binary` file from an analytic model, byte for byte in the MERL layout.
//!
//! `cargo run --release --example make_merl -- OUT.binary [SPEC]` (default spec
//! `beckmann:alpha=0.18,material=gold`).

use brdfmill::stages::brdf::{Brdf, Merl};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .ok_or_else(|| anyhow::anyhow!("usage: make_merl OUT.binary [SPEC]"))?;
    let spec = args
        .get(2)
        .map(String::as_str)
        .unwrap_or("beckmann:alpha=0.18,material=gold");
    let brdf = Brdf::parse(spec)?;
    Merl::from_fn(|wi, wo| brdf.eval(wi, wo)).write(std::path::Path::new(out))?;
    println!("wrote {out} from {spec}");
    Ok(())
}
