//! Tests of the X3P reader and writer.

use super::*;

#[test]
fn writes_and_reads_back_within_rounding() {
    let dir = tempfile::tempdir().unwrap();
    let mut hf = Heightfield::flat(7, 5, 0.0025, false, 0.0);
    for (k, v) in hf.z_mm.iter_mut().enumerate() {
        *v = -((k as f64) * 0.1234567).sin().abs() * 1e-3 / 3.0;
    }
    let p = dir.path().join("s.x3p");
    write(&p, &hf).unwrap();
    let r = read(&p).unwrap();
    assert_eq!((r.nx, r.ny), (7, 5));
    assert_eq!(r.invalid_count(), 0);
    assert_eq!(r.data_checksum_ok, Some(true));
    assert!((r.pitch_x_mm - 0.0025).abs() < 1e-15);
    // stored in metres: z·10⁻³·10³ is within two rounding steps of z
    for (a, b) in hf.z_mm.iter().zip(&r.z_mm) {
        assert!((a - b).abs() <= 2.0 * f64::EPSILON * a.abs(), "{a} {b}");
    }
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
}

#[test]
fn refuses_non_finite_heights_and_garbage() {
    let dir = tempfile::tempdir().unwrap();
    let mut hf = Heightfield::flat(3, 3, 0.01, false, 0.0);
    hf.z_mm[4] = f64::NAN;
    let p = dir.path().join("bad.x3p");
    assert!(matches!(write(&p, &hf), Err(X3pError::Invalid { .. })));
    assert!(!p.exists());
    std::fs::write(&p, b"not a zip").unwrap();
    assert!(matches!(read(&p), Err(X3pError::Zip { .. })));
}

#[test]
fn fills_invalid_points_from_neighbours() {
    let s = X3p::from_grid(3, 1, 0.001, vec![1.0, f64::NAN, 3.0], vec![true, false, true]);
    assert_eq!(s.heightfield().unwrap().z_mm, vec![1.0, 2.0, 3.0]);
}

/// A zip of `main.xml` and `bindata/data.bin` as given (no checksum file: the reader does not need it).
fn zip_of(xml: &str, data: &[u8]) -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    {
        let mut zw = zip::ZipWriter::new(&mut buf);
        let opts = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
        zw.start_file("main.xml", opts).unwrap();
        zw.write_all(xml.as_bytes()).unwrap();
        zw.start_file("bindata/data.bin", opts).unwrap();
        zw.write_all(data).unwrap();
        zw.finish().unwrap();
    }
    buf.into_inner()
}

/// `main.xml` of an `nx`×`ny` float64 surface with the given Z increment, creator and MD5.
fn xml(nx: usize, ny: usize, inc: &str, creator: &str, md5: &str) -> String {
    format!(
        "<p:ISO5436_2 xmlns:p=\"http://www.opengps.eu/2008/ISO5436_2\"><Record1><Axes>\
         <CX><AxisType>I</AxisType><DataType>D</DataType><Increment>1e-5</Increment></CX>\
         <CY><AxisType>I</AxisType><DataType>D</DataType><Increment>1e-5</Increment></CY>\
         <CZ><AxisType>A</AxisType><DataType>D</DataType><Increment>{inc}</Increment></CZ></Axes></Record1>\
         <Record2><Creator>{creator}</Creator></Record2>\
         <Record3><MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>\
         <DataLink><PointDataLink>bindata/data.bin</PointDataLink>{md5}</DataLink></Record3></p:ISO5436_2>"
    )
}

fn metres(n: usize) -> Vec<u8> {
    (0..n).flat_map(|k| (1e-6 * (k % 7) as f64).to_le_bytes()).collect()
}

#[test]
fn float_heights_are_metres_whatever_the_increment() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("f.x3p");
    std::fs::write(&p, zip_of(&xml(6, 5, "1e-6", "x3ptools", ""), &metres(30))).unwrap();
    let r = read(&p).unwrap();
    // ISO 25178-72: float values are lengths in m; 1e-6 m · k = k µm
    assert!((r.z_mm[3] - 3e-3).abs() < 1e-15, "{}", r.z_mm[3]);
    assert!(r.warnings.iter().any(|w| w.contains("not applied")), "{:?}", r.warnings);
}

#[test]
fn legacy_brdfmill_millimetre_files_still_read_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("old.x3p");
    let x = xml(6, 5, "1.0E-3", "brdfmill 0.1.0", "").replace(
        "</Creator>",
        "</Creator><Comment>Heights stored in mm: z [m] = 1.0E-3 * value.</Comment>",
    );
    let mm: Vec<u8> = (0..30).flat_map(|k| (1e-3 * (k % 7) as f64).to_le_bytes()).collect();
    std::fs::write(&p, zip_of(&x, &mm)).unwrap();
    let r = read(&p).unwrap();
    assert_eq!(r.z_mm[3], 3e-3);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
}

#[test]
fn a_wrong_point_checksum_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.x3p");
    let tag = "<MD5ChecksumPointData>00000000000000000000000000000000</MD5ChecksumPointData>";
    std::fs::write(&p, zip_of(&xml(6, 5, "1", "t", tag), &metres(30))).unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("corrupted") && e.contains("bindata/data.bin"), "{e}");
}

#[test]
fn declared_sizes_are_checked_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    // 2³⁰ points declared: refused from main.xml alone
    let p = dir.path().join("big.x3p");
    std::fs::write(&p, zip_of(&xml(32768, 32768, "1", "t", ""), &metres(4))).unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("MatrixDimension") && e.contains("limit"), "{e}");
    // an entry whose zip header declares 4 GB for a 30-point surface: refused from the header, not by
    // trying to allocate it (the central directory's uncompressed size, 24 bytes into its record, patched)
    let mut z = zip_of(&xml(6, 5, "1", "t", ""), &metres(30));
    let cd = z.windows(4).rposition(|w| w == [0x50, 0x4b, 0x01, 0x02]).unwrap();
    z[cd + 24..cd + 28].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    let p = dir.path().join("bomb.x3p");
    std::fs::write(&p, &z).unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("more than the 240"), "{e}");
}

#[test]
fn an_implausible_height_range_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("flat.x3p");
    let tiny: Vec<u8> = (0..30).flat_map(|k| (1e-15 * (k % 3) as f64).to_le_bytes()).collect();
    std::fs::write(&p, zip_of(&xml(6, 5, "1", "t", ""), &tiny)).unwrap();
    let r = read(&p).unwrap();
    assert!(r.warnings.iter().any(|w| w.contains("Z units")), "{:?}", r.warnings);
}

#[test]
fn a_non_finite_increment_names_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("n.x3p");
    std::fs::write(&p, zip_of(&xml(6, 5, "NaN", "t", ""), &metres(30))).unwrap();
    let e = read(&p).unwrap_err().to_string();
    assert!(e.contains("CZ/Increment") && e.contains("n.x3p"), "{e}");
}

/// The fill as it was first written: every missing point visited each round. The frontier version must give
/// the same heights, bit for bit, on a wide missing border and scattered holes.
#[test]
fn the_frontier_fill_gives_the_first_fills_values() {
    let (nx, ny) = (61, 47);
    let mut state = 9u64;
    let mut u = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let z: Vec<f64> = (0..nx * ny).map(|_| u()).collect();
    // measured: an off-centre block, with holes
    let valid: Vec<bool> = (0..nx * ny)
        .map(|k| {
            let (i, j) = (k % nx, k / nx);
            (8..30).contains(&i) && (20..40).contains(&j) && u() > 0.2
        })
        .collect();
    let s = X3p::from_grid(nx, ny, 0.001, z.clone(), valid.clone());
    let got = s.heightfield().unwrap().z_mm;
    let (mut want, mut known) = (z, valid);
    let mut todo: Vec<usize> = (0..nx * ny).filter(|k| !known[*k]).collect();
    while !todo.is_empty() {
        let mut fills = Vec::new();
        for &k in &todo {
            let (i, j) = ((k % nx) as isize, (k / nx) as isize);
            let (mut s, mut n) = (0.0, 0);
            for dj in -1..=1 {
                for di in -1..=1 {
                    let (a, b) = (i + di, j + dj);
                    if (di, dj) != (0, 0) && a >= 0 && b >= 0 && a < nx as isize && b < ny as isize {
                        let q = b as usize * nx + a as usize;
                        if known[q] {
                            s += want[q];
                            n += 1;
                        }
                    }
                }
            }
            if n > 0 {
                fills.push((k, s / n as f64));
            }
        }
        for (k, v) in &fills {
            want[*k] = *v;
            known[*k] = true;
        }
        todo.retain(|k| !known[*k]);
    }
    assert_eq!(got, want);
}
