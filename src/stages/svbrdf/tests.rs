use super::*;
use crate::base::heightfield::Heightfield;

/// Write an RGB PNG of `w × h` whose pixel `(col, row)` (row 0 at the top) is `f(col, row)`.
fn png_file(dir: &Path, name: &str, w: usize, h: usize, f: impl Fn(usize, usize) -> [u8; 3]) -> PathBuf {
    let mut data = vec![];
    for row in 0..h {
        for col in 0..w {
            data.extend_from_slice(&f(col, row));
        }
    }
    let path = dir.join(name);
    let file = std::fs::File::create(&path).unwrap();
    let mut e = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    e.set_color(png::ColorType::Rgb);
    e.set_depth(png::BitDepth::Eight);
    e.write_header().unwrap().write_image_data(&data).unwrap();
    path
}

const BLACK: [u8; 3] = [0, 0, 0];
const WHITE: [u8; 3] = [255, 255, 255];

fn names() -> Vec<String> {
    vec!["logo".into(), "field".into()]
}

#[test]
fn colours_and_names() {
    assert_eq!(parse_color("#1a2B3c").unwrap(), [0x1a, 0x2b, 0x3c]);
    assert_eq!(parse_color("ffffff").unwrap(), WHITE);
    assert!(parse_color("#fff").unwrap_err().contains("#rrggbb"));
    assert!(parse_color("#gg0000").is_err());
    assert_eq!(hex([0x1a, 0x2b, 0x3c]), "#1a2b3c");
    assert!(check_name("logo_2-a").is_ok());
    for bad in ["", "Logo", "a/b", "../x", &"x".repeat(33)] {
        assert!(check_name(bad).is_err(), "{bad}");
    }
}

#[test]
fn the_image_spans_the_area_with_up_as_plus_y() {
    let dir = tempfile::tempdir().unwrap();
    // 20 × 10 px over 40 × 20 mm: the top-left 5 × 5 px (10 × 10 mm) is the logo
    let p = png_file(
        dir.path(),
        "l.png",
        20,
        10,
        |c, r| if c < 5 && r < 5 { BLACK } else { WHITE },
    );
    let l = Labels::read(&p, &names(), &[BLACK, WHITE], [40.0, 20.0]).unwrap();
    assert_eq!(l.at(1.0, 19.0), 0, "top left of the image is high y, low x");
    assert_eq!(l.at(1.0, 1.0), 1);
    assert_eq!(l.at(11.0, 19.0), 1);
    assert_eq!(l.at(-5.0, 100.0), 0, "clamped");
    let f = l.fractions();
    assert!((f[0] - 25.0 / 200.0).abs() < 1e-12 && (f[0] + f[1] - 1.0).abs() < 1e-12);
    // the logo holds a 10 mm square but no 10.5 mm one
    assert!(l.check_period([10.0, 10.0]).is_ok());
    let e = l.check_period([10.5, 4.0]).unwrap_err().to_string();
    assert!(
        e.contains("`logo`") && e.contains("#000000") && e.contains("10.50"),
        "{e}"
    );
}

#[test]
fn bad_label_images_are_refused_with_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let cols = [BLACK, WHITE];
    // a colour no region names: named with its count and first pixel
    let p = png_file(dir.path(), "stray.png", 10, 10, |c, r| match (c, r) {
        (7, 2) | (8, 2) => [200, 10, 10],
        _ if c < 5 => BLACK,
        _ => WHITE,
    });
    let e = Labels::read(&p, &names(), &cols, [10.0, 10.0]).unwrap_err().to_string();
    assert!(
        e.contains("#c80a0a") && e.contains("2 pixels") && e.contains("column 7, row 2"),
        "{e}"
    );
    // a region with no pixels
    let p = png_file(dir.path(), "white.png", 10, 10, |_, _| WHITE);
    let e = Labels::read(&p, &names(), &cols, [10.0, 10.0]).unwrap_err().to_string();
    assert!(e.contains("region `logo`") && e.contains("no pixels"), "{e}");
    // pixels that would not be square on the part
    let p = png_file(dir.path(), "half.png", 10, 10, |c, _| if c < 5 { BLACK } else { WHITE });
    let e = Labels::read(&p, &names(), &cols, [20.0, 10.0]).unwrap_err().to_string();
    assert!(e.contains("not square"), "{e}");
    // not a PNG, and a missing file
    std::fs::write(dir.path().join("x.png"), b"GIF89a").unwrap();
    let e = Labels::read(&dir.path().join("x.png"), &names(), &cols, [10.0, 10.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a PNG"), "{e}");
    assert!(Labels::read(&dir.path().join("none.png"), &names(), &cols, [10.0, 10.0]).is_err());
}

/// A periodic tile `n × n` at `pitch` with heights `f(i, j)`.
fn tile(n: usize, pitch: f64, f: impl Fn(usize, usize) -> f64) -> Heightfield {
    let mut hf = Heightfield::flat(n, n, pitch, true, 0.0);
    for j in 0..n {
        for i in 0..n {
            hf.z_mm[j * n + i] = f(i, j);
        }
    }
    hf
}

#[test]
fn the_part_takes_each_cell_from_its_regions_tile() {
    let dir = tempfile::tempdir().unwrap();
    // 8 × 8 mm, left half logo; tiles of 4 × 4 cells at 0.5 mm (2 mm period)
    let p = png_file(dir.path(), "l.png", 8, 8, |c, _| if c < 4 { BLACK } else { WHITE });
    let l = Labels::read(&p, &names(), &[BLACK, WHITE], [8.0, 8.0]).unwrap();
    let a = tile(4, 0.5, |i, j| -0.01 * (i + 4 * j) as f64); // mean −0.075, top 0, bottom −0.15
    let b = tile(4, 0.5, |i, _| -0.2 - 0.1 * (i % 2) as f64); // mean −0.25, top −0.2, bottom −0.3
    let part = compose(&[&a, &b], &l, 1.0).unwrap();
    assert_eq!(part.alignment, Alignment::Mean);
    let hf = &part.heightfield;
    assert_eq!((hf.nx, hf.ny), (16, 16));
    for j in 0..16 {
        for i in 0..16 {
            let (t, k) = if i < 8 { (&a, 0) } else { (&b, 1) };
            let want = t.z_mm[(j % 4) * 4 + i % 4] + part.offsets_mm[k];
            assert!((hf.at(i, j) - want).abs() < 1e-12, "({i}, {j})");
        }
    }
    // the tiles' means meet at one level and the top is the stock top
    let mean = |k: usize| -> f64 {
        let cells: Vec<f64> = (0..256)
            .filter(|c| (c % 16 < 8) == (k == 0))
            .map(|c| hf.z_mm[c])
            .collect();
        cells.iter().sum::<f64>() / cells.len() as f64
    };
    assert!((mean(0) - mean(1)).abs() < 1e-12);
    assert!(hf.range().1.abs() < 1e-12);
    assert!((part.relief_mm - (0.075 + 0.075)).abs() < 1e-12, "{}", part.relief_mm);
    // a budget below what mean alignment needs: every top at the stock top, relief the deepest tile's
    let part = compose(&[&a, &b], &l, 0.12).unwrap();
    assert_eq!(part.alignment, Alignment::Top);
    assert!((part.relief_mm - 0.15).abs() < 1e-12 && part.heightfield.range().1.abs() < 1e-12);
    // no budget (0, as `facets.max_relief_mm`) never forces the tops together
    assert_eq!(compose(&[&a, &b], &l, 0.0).unwrap().alignment, Alignment::Mean);
    // tiles of different sizes are refused
    let c = tile(6, 0.5, |_, _| 0.0);
    assert!(compose(&[&a, &c], &l, 1.0).is_err());
}

#[test]
fn a_transparent_pixel_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.png");
    let mut data = vec![];
    for k in 0..16 {
        data.extend_from_slice(&[0, 0, 0, if k == 5 { 128 } else { 255 }]);
    }
    let file = std::fs::File::create(&path).unwrap();
    let mut e = png::Encoder::new(std::io::BufWriter::new(file), 4, 4);
    e.set_color(png::ColorType::Rgba);
    e.write_header().unwrap().write_image_data(&data).unwrap();
    let e = Labels::read(&path, &names(), &[BLACK, WHITE], [4.0, 4.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("not opaque") && e.contains("column 1, row 1"), "{e}");
}
