//! The `tensor_file` container of the RGL material database (Dupuy & Jakob 2018) and of Mitsuba's
//! `TensorFile`: named, typed, C-ordered arrays.
//!
//! **Layout** (little-endian): the 12 bytes `"tensor_file\0"`, `u8` major and minor version (1, 0), `u32`
//! field count, then per field `u16` name length, the name, `u16` rank, `u8` dtype (1 u8, 2 i8, 3 u16,
//! 4 i16, 5 u32, 6 i32, 7 u64, 8 i64, 9 f16, 10 f32, 11 f64), `u64` absolute byte offset and `u64` shape per
//! axis; then the data, each field's at its offset.

use crate::base::Invalid;
use std::collections::BTreeMap;

/// One field of a tensor file, converted to `f64`.
#[derive(Clone, Debug)]
pub struct Field {
    /// Shape, outermost axis first.
    pub shape: Vec<usize>,
    /// Values in C order.
    pub data: Vec<f64>,
    /// The raw dtype code.
    pub dtype: u8,
}

/// A parsed `tensor_file`: named fields.
#[derive(Clone, Debug)]
pub struct TensorFile {
    /// Format version `(major, minor)`.
    pub version: (u8, u8),
    /// Fields by name.
    pub fields: BTreeMap<String, Field>,
}

fn dtype_size(code: u8) -> Option<usize> {
    Some(match code {
        1 | 2 => 1,
        3 | 4 | 9 => 2,
        5 | 6 | 10 => 4,
        7 | 8 | 11 => 8,
        _ => return None,
    })
}

fn decode(code: u8, b: &[u8]) -> f64 {
    match code {
        1 => b[0] as f64,
        2 => b[0] as i8 as f64,
        3 => u16::from_le_bytes([b[0], b[1]]) as f64,
        4 => i16::from_le_bytes([b[0], b[1]]) as f64,
        5 => u32::from_le_bytes(b.try_into().unwrap()) as f64,
        6 => i32::from_le_bytes(b.try_into().unwrap()) as f64,
        7 => u64::from_le_bytes(b.try_into().unwrap()) as f64,
        8 => i64::from_le_bytes(b.try_into().unwrap()) as f64,
        9 => f16_to_f64(u16::from_le_bytes([b[0], b[1]])),
        10 => f32::from_le_bytes(b.try_into().unwrap()) as f64,
        _ => f64::from_le_bytes(b.try_into().unwrap()),
    }
}

fn f16_to_f64(h: u16) -> f64 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let man = (h & 0x3ff) as f64;
    sign * match exp {
        0 => man * 2f64.powi(-24),
        31 if man == 0.0 => f64::INFINITY,
        31 => f64::NAN,
        e => (1.0 + man / 1024.0) * 2f64.powi(e - 15),
    }
}

impl TensorFile {
    /// Parse a tensor file from bytes; errors say which field or byte offset is wrong.
    pub fn parse(bytes: &[u8]) -> Result<Self, Invalid> {
        let mut pos = 0usize;
        let take = |pos: &mut usize, n: usize, what: &str| -> Result<&[u8], String> {
            let end = pos.checked_add(n).filter(|e| *e <= bytes.len()).ok_or_else(|| {
                format!(
                    "truncated: {what} at byte {} needs {n} bytes, file has {}",
                    *pos,
                    bytes.len()
                )
            })?;
            let s = &bytes[*pos..end];
            *pos = end;
            Ok(s)
        };
        if take(&mut pos, 12, "magic")? != b"tensor_file\0" {
            return Err(Invalid(
                "not a tensor file: the first 12 bytes are not \"tensor_file\\0\"".into(),
            ));
        }
        let v = take(&mut pos, 2, "version")?;
        let version = (v[0], v[1]);
        if version.0 != 1 {
            return Err(Invalid(format!(
                "tensor_file version {}.{} is not supported (expected 1.x)",
                v[0], v[1]
            )));
        }
        let n = u32::from_le_bytes(take(&mut pos, 4, "field count")?.try_into().unwrap()) as usize;
        let mut fields = BTreeMap::new();
        for _ in 0..n {
            let len = u16::from_le_bytes(take(&mut pos, 2, "name length")?.try_into().unwrap()) as usize;
            let name = String::from_utf8_lossy(take(&mut pos, len, "field name")?).into_owned();
            let rank = u16::from_le_bytes(take(&mut pos, 2, "rank")?.try_into().unwrap()) as usize;
            let dtype = take(&mut pos, 1, "dtype")?[0];
            let offset = u64::from_le_bytes(take(&mut pos, 8, "offset")?.try_into().unwrap()) as usize;
            let mut shape = Vec::with_capacity(rank);
            for _ in 0..rank {
                shape.push(u64::from_le_bytes(take(&mut pos, 8, "shape")?.try_into().unwrap()) as usize);
            }
            let size = dtype_size(dtype).ok_or_else(|| format!("field `{name}`: unknown dtype code {dtype}"))?;
            let count = shape
                .iter()
                .try_fold(1usize, |a, s| a.checked_mul(*s))
                .ok_or_else(|| format!("field `{name}`: shape {shape:?} overflows"))?;
            let end = count
                .checked_mul(size)
                .and_then(|b| b.checked_add(offset))
                .filter(|e| *e <= bytes.len())
                .ok_or_else(|| {
                    format!(
                        "field `{name}`: {count} values of {size} bytes at offset {offset} run past the end of the file ({} bytes)",
                        bytes.len()
                    )
                })?;
            let data = bytes[offset..end]
                .chunks_exact(size)
                .map(|b| decode(dtype, b))
                .collect();
            fields.insert(name, Field { shape, data, dtype });
        }
        Ok(Self { version, fields })
    }

    /// The field `name`, which must have rank `rank` and finite values.
    pub(super) fn field(&self, name: &str, rank: usize) -> Result<&Field, String> {
        let f = self.fields.get(name).ok_or_else(|| format!("missing field `{name}`"))?;
        if f.shape.len() != rank {
            return Err(format!(
                "field `{name}` has rank {} (shape {:?}), expected {rank}",
                f.shape.len(),
                f.shape
            ));
        }
        if let Some(k) = f.data.iter().position(|v| !v.is_finite()) {
            return Err(format!("field `{name}`: value {k} is not finite"));
        }
        Ok(f)
    }
}

/// The values of a field to write, in the dtype they are stored as.
#[derive(Clone, Debug)]
pub enum Values {
    /// dtype 1.
    U8(Vec<u8>),
    /// dtype 5.
    U32(Vec<u32>),
    /// dtype 10.
    F32(Vec<f32>),
}

impl Values {
    fn dtype(&self) -> u8 {
        match self {
            Values::U8(_) => 1,
            Values::U32(_) => 5,
            Values::F32(_) => 10,
        }
    }

    fn len(&self) -> usize {
        match self {
            Values::U8(v) => v.len(),
            Values::U32(v) => v.len(),
            Values::F32(v) => v.len(),
        }
    }

    fn bytes(&self, out: &mut Vec<u8>) {
        match self {
            Values::U8(v) => out.extend_from_slice(v),
            Values::U32(v) => v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Values::F32(v) => v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        }
    }
}

/// Serialise fields, in the order given, as a version 1.0 tensor file. Each field's data starts on an 8-byte
/// boundary, as in the published files. Panics if a shape does not hold its values (a programming error:
/// callers build both).
pub fn encode(fields: &[(&str, Vec<usize>, Values)]) -> Vec<u8> {
    let align = |n: usize| n.div_ceil(8) * 8;
    let header = 12
        + 2
        + 4
        + fields
            .iter()
            .map(|(name, shape, _)| 2 + name.len() + 2 + 1 + 8 + 8 * shape.len())
            .sum::<usize>();
    let mut offsets = Vec::with_capacity(fields.len());
    let mut at = align(header);
    for (name, shape, values) in fields {
        assert_eq!(
            shape.iter().product::<usize>(),
            values.len(),
            "field `{name}`: shape {shape:?}"
        );
        offsets.push(at);
        let size = dtype_size(values.dtype()).unwrap_or(1);
        at = align(at + values.len() * size);
    }
    let mut out = Vec::with_capacity(at);
    out.extend_from_slice(b"tensor_file\0");
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(fields.len() as u32).to_le_bytes());
    for ((name, shape, values), offset) in fields.iter().zip(&offsets) {
        out.extend_from_slice(&(name.len() as u16).to_le_bytes());
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(&(shape.len() as u16).to_le_bytes());
        out.push(values.dtype());
        out.extend_from_slice(&(*offset as u64).to_le_bytes());
        for s in shape {
            out.extend_from_slice(&(*s as u64).to_le_bytes());
        }
    }
    for ((_, _, values), offset) in fields.iter().zip(&offsets) {
        out.resize(*offset, 0);
        values.bytes(&mut out);
    }
    out.resize(at, 0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoded_fields_parse_back() {
        let bytes = encode(&[
            ("description", vec![3], Values::U8(b"abc".to_vec())),
            ("version", vec![2], Values::U32(vec![1, 0])),
            ("grid", vec![2, 3], Values::F32(vec![0.5, -1.0, 2.0, 3.25, 1e-3, 7.0])),
        ]);
        let tf = TensorFile::parse(&bytes).unwrap();
        assert_eq!(tf.version, (1, 0));
        let g = &tf.fields["grid"];
        assert_eq!((g.shape.clone(), g.dtype), (vec![2, 3], 10));
        assert_eq!(g.data, [0.5, -1.0, 2.0, 3.25, 1e-3f32 as f64, 7.0]);
        assert_eq!(tf.fields["description"].data, [97.0, 98.0, 99.0]);
        assert_eq!(tf.fields["version"].data, [1.0, 0.0]);
        // data on 8-byte boundaries, as in the published files
        let offset = |name: &str| {
            let at = bytes.windows(name.len()).position(|w| w == name.as_bytes()).unwrap() + name.len();
            u64::from_le_bytes(bytes[at + 3..at + 11].try_into().unwrap())
        };
        assert!(["description", "version", "grid"].iter().all(|n| offset(n) % 8 == 0));
    }

    #[test]
    fn f16_decodes() {
        assert_eq!(f16_to_f64(0x3c00), 1.0);
        assert_eq!(f16_to_f64(0xc000), -2.0);
        assert_eq!(f16_to_f64(0x7bff), 65504.0);
    }

    #[test]
    fn header_errors_are_reported() {
        assert!(TensorFile::parse(b"tensor_fil").unwrap_err().contains("truncated"));
        assert!(TensorFile::parse(b"not_a_tensor_file_at_all")
            .unwrap_err()
            .contains("not a tensor file"));
        let mut b = b"tensor_file\0".to_vec();
        b.extend_from_slice(&[1, 0, 1, 0, 0, 0]);
        b.extend_from_slice(&3u16.to_le_bytes());
        b.extend_from_slice(b"ndf");
        b.extend_from_slice(&1u16.to_le_bytes());
        b.push(10);
        b.extend_from_slice(&1000u64.to_le_bytes());
        b.extend_from_slice(&4u64.to_le_bytes());
        let e = TensorFile::parse(&b).unwrap_err();
        assert!(e.contains("`ndf`") && e.contains("past the end"), "{e}");
    }
}
