//! NumPy `.npy` arrays (via `npyz`), so any Python user can load grids and heightfields: `f64`, or `f32`
//! for the large heightfields (half the bytes); read back as `f64` from either.

use npyz::WriterBuilder;
use std::path::Path;

/// A `.npy` file that could not be read as a 2D `f64` array.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// A file could not be opened or read.
    #[error(transparent)]
    Io(#[from] crate::base::io::ReadError),
    /// Not a 2D little-endian float64 or float32 C-order array.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Write a row-major `rows × cols` array of `f64` as `.npy` (C order, little-endian), atomically.
pub fn write_f64_2d(path: &Path, rows: usize, cols: usize, data: &[f64]) -> Result<(), crate::base::io::WriteError> {
    write_2d(path, rows, cols, data.iter().copied())
}

/// Write a row-major `rows × cols` array as `.npy` of `f32` (C order, little-endian), atomically: each
/// value rounded to the nearest `f32`, a relative error of at most 2⁻²⁴ (0.06 nm on a height of 1 mm).
pub fn write_f32_2d(path: &Path, rows: usize, cols: usize, data: &[f64]) -> Result<(), crate::base::io::WriteError> {
    write_2d(path, rows, cols, data.iter().map(|&v| v as f32))
}

/// The writer of both: `rows × cols` values of `T`, in the dtype NumPy knows for it.
fn write_2d<T: npyz::AutoSerialize>(
    path: &Path,
    rows: usize,
    cols: usize,
    values: impl ExactSizeIterator<Item = T>,
) -> Result<(), crate::base::io::WriteError> {
    assert_eq!(values.len(), rows * cols, "npy shape does not match the data");
    crate::base::io::write_atomic_with(path, |w| {
        let mut writer = npyz::WriteOptions::<T>::new()
            .default_dtype()
            .shape(&[rows as u64, cols as u64])
            .writer(w)
            .begin_nd()?;
        writer.extend(values)?;
        writer.finish()
    })
}

/// The dimensions written in a .npy header's `'shape': (…)`, as text (`None` for one that is not a plain
/// whole number); `None` when the header cannot be found, which the full reader then reports.
fn header_shape(bytes: &[u8]) -> Option<Vec<Option<String>>> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return None;
    }
    let (start, len): (usize, usize) = match bytes[6] {
        1 => (10, u16::from_le_bytes([bytes[8], bytes[9]]) as usize),
        _ if bytes.len() >= 12 => (
            12,
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
        ),
        _ => return None,
    };
    let header = std::str::from_utf8(bytes.get(start..start.checked_add(len)?)?).ok()?;
    let after = &header[header.find("'shape'")?..];
    let inner = &after[after.find('(')? + 1..after.find(')')?];
    Some(
        inner
            .split(',')
            .map(str::trim)
            .filter(|d| !d.is_empty())
            .map(|d| d.chars().all(|c| c.is_ascii_digit()).then(|| d.to_string()))
            .collect(),
    )
}

/// Read a 2D `f64` or `f32` array (C order) as `f64`; returns `(rows, cols, data)`.
pub fn read_f64_2d(path: &Path) -> Result<(usize, usize, Vec<f64>), NpyError> {
    let bytes = crate::base::io::read(path)?;
    let fmt = |reason: String| NpyError::Format {
        path: path.to_path_buf(),
        reason,
    };
    // npyz multiplies the header's shape unchecked (a panic or a wrap when it overflows): checked first
    if let Some(dims) = header_shape(&bytes) {
        let count = dims.iter().try_fold(1usize, |n, d| {
            d.as_deref()
                .and_then(|d| d.parse::<usize>().ok())
                .and_then(|d| n.checked_mul(d))
        });
        if count.is_none() {
            return Err(fmt(format!(
                "shape ({}) has more values than this machine can address",
                dims.iter()
                    .map(|d| d.as_deref().unwrap_or("?"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    let npy = npyz::NpyFile::new(&bytes[..]).map_err(|e| fmt(format!("not a .npy file: {e}")))?;
    let shape = npy.shape().to_vec();
    if shape.len() != 2 {
        return Err(fmt(format!("expected a 2D array, got shape {shape:?}")));
    }
    if npy.order() != npyz::Order::C {
        return Err(fmt("expected C (row-major) order, got Fortran order".into()));
    }
    // checked: a shape whose product wraps (2^62 × 4 is 0 modulo 2^64) would pass for the data read
    let (rows, cols) = (usize::try_from(shape[0]).ok(), usize::try_from(shape[1]).ok());
    let Some((rows, cols, count)) = rows.zip(cols).and_then(|(r, c)| Some((r, c, r.checked_mul(c)?))) else {
        return Err(fmt(format!(
            "shape ({}, {}) has more values than this machine can address",
            shape[0], shape[1]
        )));
    };
    let single = matches!(npy.dtype(), npyz::DType::Plain(t) if t.to_string() == "<f4");
    let data: Vec<f64> = if single {
        npy.into_vec::<f32>()
            .map_err(|e| fmt(format!("expected float32 values: {e}")))?
            .into_iter()
            .map(f64::from)
            .collect()
    } else {
        npy.into_vec::<f64>()
            .map_err(|e| fmt(format!("expected float64 or float32 values: {e}")))?
    };
    if data.len() != count {
        return Err(fmt(format!(
            "shape ({rows}, {cols}) is {count} values, the file holds {}",
            data.len()
        )));
    }
    Ok((rows, cols, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let data: Vec<f64> = (0..12).map(|k| k as f64 * 0.5 - 1.0).collect();
        write_f64_2d(&p, 3, 4, &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[..6], b"\x93NUMPY");
        let header = String::from_utf8_lossy(&bytes[10..80]);
        assert!(
            header.contains("'<f8'") && header.contains("'shape': (3, 4"),
            "{header}"
        );
        assert_eq!(read_f64_2d(&p).unwrap(), (3, 4, data));
    }

    /// Single precision: the dtype NumPy reads as float32, and every value back within half an f32 ulp.
    #[test]
    fn single_precision_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let data: Vec<f64> = (0..12).map(|k| (k as f64 * 0.1 - 0.7) / 3.0).collect();
        write_f32_2d(&p, 4, 3, &data).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let header = String::from_utf8_lossy(&bytes[10..80]);
        assert!(
            header.contains("'<f4'") && header.contains("'shape': (4, 3"),
            "{header}"
        );
        assert_eq!(bytes.len(), 128 + 12 * 4);
        let (rows, cols, back) = read_f64_2d(&p).unwrap();
        assert_eq!((rows, cols), (4, 3));
        for (a, b) in data.iter().zip(&back) {
            assert!((a - b).abs() <= a.abs() * 2f64.powi(-24), "{a} read back as {b}");
        }
    }

    #[test]
    fn not_npy_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        std::fs::write(&p, b"hello").unwrap();
        assert!(read_f64_2d(&p).unwrap_err().to_string().contains("not a .npy file"));
    }
}
