//! Issue 17: a drawn highlight as the target. The shipped images are what their script draws; bad images
//! and bad combinations of keys are refused before any work with the file and the key named; the star
//! example, run end to end, casts a highlight that correlates with its image as the issue asks.

#[path = "../examples/make_highlights.rs"]
#[allow(dead_code)]
mod make_highlights;

use brdfmill::job::Job;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
    let d = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut r = d.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size()];
    let f = r.next_frame(&mut buf).unwrap();
    assert_eq!(f.color_type, png::ColorType::Grayscale);
    buf.truncate(f.buffer_size());
    (f.width, f.height, buf)
}

/// The images in examples/data are exactly what `examples/make_highlights.rs` draws.
#[test]
fn shipped_images_are_what_the_script_draws() {
    for (name, shape) in make_highlights::SHAPES {
        let (w, h, px) = decode(&root().join("examples/data").join(name));
        assert_eq!(
            (w as usize, h as usize),
            (make_highlights::SIDE_PX, make_highlights::SIDE_PX)
        );
        assert!(
            px == make_highlights::draw(shape, make_highlights::SOFT_DEG),
            "{name} differs from what the script draws: run `cargo run --release --example make_highlights -- examples/data`"
        );
    }
}

fn job(dir: &Path, target: &str) -> PathBuf {
    let machine = root().join("machines/grbl-3018.toml");
    let text = format!(
        "version = 1\nname = \"t\"\n[target]\n{target}\n[machine]\nprofile = \"{}\"\n[toolpath]\ntool = \"ball05\"\narea_mm = [13.2, 13.2]\n",
        machine.display()
    );
    let p = dir.join("job.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn grey_png(path: &Path, w: u32, h: u32, px: &[u8]) {
    let mut bytes = Vec::new();
    let mut e = png::Encoder::new(&mut bytes, w, h);
    e.set_color(png::ColorType::Grayscale);
    e.write_header().unwrap().write_image_data(px).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// Each mistake is refused by `Job::load` with the key and what was expected.
#[test]
fn bad_highlight_targets_are_refused_with_the_file_and_key_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("notes.png"), "this is text, not an image").unwrap();
    grey_png(&d.join("black.png"), 16, 16, &[0; 256]);
    let star = root().join("examples/data/star.png").display().to_string();
    let cases: Vec<(String, Vec<&str>)> = vec![
        (
            format!("brdf = \"beckmann:alpha=0.2\"\nhighlight = \"{star}\""),
            vec!["not both"],
        ),
        (
            "base = \"scallop\"".into(),
            vec!["missing `target.brdf`", "target.highlight"],
        ),
        (
            "highlight = \"notes.png\"".into(),
            vec!["target.highlight", "notes.png", "not a PNG"],
        ),
        ("highlight = \"black.png\"".into(), vec!["black.png", "no highlight"]),
        (
            "highlight = \"nowhere.png\"".into(),
            vec!["target.highlight", "nowhere.png"],
        ),
        (
            format!("highlight = \"{star}\"\nhighlight_extent_deg = 45.0"),
            vec!["target.highlight", "extent", "[1, 40]"],
        ),
        (
            format!("highlight = \"{star}\"\nmaterial = \"unobtainium\""),
            vec!["unknown material `unobtainium`"],
        ),
        (
            "brdf = \"beckmann:alpha=0.2\"\nmaterial = \"gold\"".into(),
            vec!["target.material", "goes with `target.highlight`"],
        ),
    ];
    for (target, needles) in cases {
        let e = match Job::load(&job(d, &target)) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("accepted: {target}"),
        };
        for n in needles {
            assert!(e.contains(n), "`{e}` should mention `{n}`");
        }
    }
}

/// `brdfmill ndf --highlight`: the ring drawn with hard edges is, in slope space, exactly the annulus between
/// tan(10°/2) and tan(22°/2): no mass in its hole, none beyond its rim (to within the pixels and cells that
/// straddle an edge).
#[test]
fn ndf_of_a_hard_ring_is_its_slope_annulus() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ndf.json");
    let ring = dir.path().join("ring.png");
    let shape = make_highlights::SHAPES
        .iter()
        .find(|(n, _)| *n == "ring.png")
        .unwrap()
        .1;
    std::fs::write(&ring, make_highlights::png(&make_highlights::draw(shape, 0.0))).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args([
            "ndf",
            "--highlight",
            ring.to_str().unwrap(),
            "--max-angle-deg",
            "30",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let g = brdfmill::stages::ndf::NdfFile::read(&out).unwrap().observed();
    let d = g.domain;
    let (inner, outer) = ((5f64).to_radians().tan(), (11f64).to_radians().tan());
    // an edge pixel is 0.0045 wide on the screen, about 0.0022 in slope; a cell is d.dp() wide
    let slack = d.dp() * std::f64::consts::SQRT_2 + 0.003;
    let (mut inside, mut hole) = (0.0, 0.0);
    for j in 0..d.ny {
        for i in 0..d.nx {
            let s = d.p_at(i).hypot(d.q_at(j));
            let m = g.at(i, j) * d.cell_area();
            if s >= inner - slack && s <= outer + slack {
                inside += m;
            }
            if s < inner - slack {
                hole += m;
            }
        }
    }
    assert!(inside > 0.9999, "mass within the annulus: {inside}");
    assert!(hole < 1e-9, "mass in the ring's hole: {hole}");
    // and a file that is not a PNG is refused with its name
    let bad = dir.path().join("x.png");
    std::fs::write(&bad, "GIF89a").unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(["ndf", "--highlight", bad.to_str().unwrap(), "--out"])
        .arg(dir.path().join("n2.json"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("x.png") && e.contains("not a PNG"),
        "{e}"
    );
}

/// Issue 17's acceptance for the star: `brdfmill run examples/highlight-star.toml` passes its verdict, and
/// the milled surface's highlight correlates at least 0.95 with the image (`metrics.json`
/// `highlight_corr`), which the report shows beside it and the closing summary prints.
#[test]
#[ignore = "slow (the star job end to end): cargo test -- --ignored runs it, and .ci/run"]
fn star_example_casts_its_highlight() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args([
            "run",
            root().join("examples/highlight-star.toml").to_str().unwrap(),
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    let corr = m["highlight_corr"].as_f64().unwrap();
    assert!(corr >= 0.95, "highlight_corr {corr}");
    assert_eq!(m["highlight"]["milled_corr"].as_f64(), Some(corr));
    // the grid holds the image; the design and the cut lose something on the way, not more than the grid
    let grid = m["highlight"]["grid_corr"].as_f64().unwrap();
    assert!(grid > 0.99 && grid >= corr, "grid {grid}");
    // what any slopes under the scallop and polish lobe can draw (the deconvolved target blurred again):
    // neither the design nor the cut draws sharper, to within the deconvolution's own error (on the
    // hard-edged star 0.875 against the design's 0.874 and the cut's 0.867)
    let lobe = m["highlight"]["lobe_corr"].as_f64().unwrap();
    let design = m["highlight"]["design_corr"].as_f64().unwrap();
    assert!(
        lobe < grid && corr <= lobe + 0.01 && design <= lobe + 0.01,
        "lobe {lobe}, design {design}, milled {corr}"
    );
    assert_eq!(m["pass"].as_bool(), Some(true));
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stdout));
    // the closing summary's milled line gives the figure the verdict turned on, as metrics.json has it
    let stdout = String::from_utf8_lossy(&o.stdout);
    let milled = stdout
        .lines()
        .find(|l| l.starts_with("milled "))
        .unwrap_or_else(|| panic!("no milled line in {stdout}"));
    let min = m["tolerances"]["highlight_corr_min"].as_f64().unwrap();
    assert!(
        milled.ends_with(&format!(", highlight corr {corr:.4} (at least {min})")),
        "{milled}"
    );
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains(">Highlight<") && report.contains("the highlight asked for"));
}
