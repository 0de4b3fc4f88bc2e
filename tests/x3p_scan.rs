//! The real confocal scan in `examples/data/` (copied from `shared/data/x3p/`): it loads with its invalid
//! points, and a surface written by brdfmill reads back within two rounding steps.

use brdfmill::base::heightfield::Heightfield;
use std::path::Path;

fn scan() -> brdfmill::base::x3p::X3p {
    brdfmill::base::x3p::read(Path::new("examples/data/sample-land.x3p")).expect("the scan reads")
}

#[test]
fn the_real_scan_loads_with_its_missing_points() {
    let s = scan();
    assert_eq!((s.nx, s.ny), (918, 256));
    assert!((s.pitch_x_mm - 2.58e-3).abs() < 1e-12 && (s.pitch_y_mm - 2.58e-3).abs() < 1e-12);
    assert_eq!(s.invalid_count(), 25_292);
    assert_eq!(s.data_type, 'D');
    assert_eq!(s.main_xml, "sample-land/main.xml");
    assert_eq!(s.data_checksum_ok, Some(true));
    let hf = s.heightfield().unwrap();
    hf.check_invariants().unwrap();
    // filled points stay within the valid range
    let (lo, hi) = s
        .z_mm
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
    assert!(hf.z_mm.iter().all(|v| *v >= lo && *v <= hi));
    let slopes = s.masked_slopes(1);
    assert!(slopes.len() > 150_000 && slopes.len() < 918 * 256 - 25_292);
    assert!(slopes.iter().all(|(p, q)| p.is_finite() && q.is_finite()));
}

#[test]
fn an_x3p_written_by_brdfmill_reads_back_within_rounding() {
    let dir = tempfile::tempdir().unwrap();
    // the scan's own (filled) heights through .npy, then X3P
    let hf = scan().heightfield().unwrap();
    let npy = dir.path().join("h.npy");
    hf.write_npy(&npy).unwrap();
    let (ny, nx, z) = brdfmill::base::npy::read_f64_2d(&npy).unwrap();
    let from_npy = Heightfield {
        nx,
        ny,
        pitch_mm: hf.pitch_mm,
        periodic: false,
        z_mm: z,
    };
    let x3p = dir.path().join("h.x3p");
    brdfmill::base::x3p::write(&x3p, &from_npy).unwrap();
    let back = brdfmill::base::x3p::read(&x3p).unwrap();
    assert_eq!((back.nx, back.ny), (nx, ny));
    assert_eq!(back.invalid_count(), 0);
    assert_eq!(back.data_checksum_ok, Some(true));
    // heights are stored in metres (ISO 25178-72's float data): z·10⁻³·10³ is within two rounding steps of z
    assert!(from_npy
        .z_mm
        .iter()
        .zip(&back.z_mm)
        .all(|(a, b)| (a - b).abs() <= 2.0 * f64::EPSILON * a.abs()));
    // and md5checksum.hex is the MD5 of main.xml, as ISO 25178-72 requires
    let f = std::fs::File::open(&x3p).unwrap();
    let mut zip = zip::ZipArchive::new(f).unwrap();
    let mut xml = Vec::new();
    std::io::Read::read_to_end(&mut zip.by_name("main.xml").unwrap(), &mut xml).unwrap();
    let mut sum = String::new();
    std::io::Read::read_to_string(&mut zip.by_name("md5checksum.hex").unwrap(), &mut sum).unwrap();
    use md5::Digest;
    let want: String = md5::Md5::digest(&xml).iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(sum, format!("{want} *main.xml\n"));
}
