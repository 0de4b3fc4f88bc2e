//! X3P surface files (ISO 25178-72, the XML container of ISO 5436-2): read measured areal topography and
//! write simulated surfaces so that metrology software opens them.
//!
//! An X3P file is a zip archive holding `main.xml` (the record structure: Record1 axes, Record2 provenance,
//! Record3 matrix size and a link to the binary data, Record4 the checksum file), the binary point data
//! (`bindata/data.bin`, little-endian, x fastest then y) and `md5checksum.hex` (the MD5 of `main.xml`).
//!
//! Reading copes with what real files do: `main.xml` in a subfolder of the zip (every link is then resolved
//! relative to that folder), macOS resource-fork entries (`__MACOSX/`, `._*`) ignored, invalid points given
//! as NaN in floating-point data or by a `ValidPointsLink` bit array (1 = valid, least significant bit
//! first), inline `DataList` data with empty `Datum` for invalid points, and data types D (f64), F (f32),
//! L (i32) and I (i16). Axes are in metres in the file; brdfmill's heightfields are in mm.
//!
//! Heights, as ISO 25178-72 and its reference implementation (openGPS) define them: for integer data (L, I)
//! the stored value `v` gives `z = Offset + Increment · v` in metres; for floating-point data (D, F) the
//! value is already a length in metres, `z = Offset + v`, and `Increment` is not applied (the schema: the
//! increment is "needed for incremental axis and integer data types"). Some writers multiply float data by
//! the increment too; a float file whose `CZ/Increment` is not 1 is read by the standard's rule with a
//! warning that says so ([`X3p::warnings`]). The one exception is brdfmill's own files before this rule
//! (Creator `brdfmill`, `CZ/Increment = 1.0E-3`, a comment that heights are stored in mm), read as written.
//! The writer stores metres as the standard says.
//!
//! Sizes declared in the file are checked against the real data before anything is allocated: an entry
//! larger than the surface it belongs to, or a surface beyond [`MAX_POINTS`], is refused; a point-data MD5
//! that does not match is refused as a corrupted file.
//!
//! Invalid points: [`X3p::valid`] marks them; [`X3p::heightfield`] fills them by iterated averaging of
//! their valid neighbours (an inpainting that keeps the surface smooth and continuous, used for wave optics)
//! and [`X3p::masked_slopes`] gives central-difference slopes only where all four neighbours are valid.

use crate::base::heightfield::Heightfield;
use md5::{Digest, Md5};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The most points a surface may have (2²⁶ = 8192², 512 MiB of f64 heights): past it the reader refuses
/// before allocating, naming the declared size.
pub const MAX_POINTS: usize = 1 << 26;

/// The largest `main.xml` read, bytes.
const MAX_XML_BYTES: u64 = 64 << 20;

/// An X3P file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum X3pError {
    /// The file could not be opened or read.
    #[error(transparent)]
    Io(#[from] crate::base::io::ReadError),
    /// The zip container is unreadable.
    #[error("{path} is not a readable zip archive: {message}")]
    Zip {
        /// The file.
        path: PathBuf,
        /// What the zip reader said.
        message: String,
    },
    /// A required entry is missing from the archive.
    #[error("{path}: the archive has no {entry}")]
    MissingEntry {
        /// The file.
        path: PathBuf,
        /// The missing entry.
        entry: String,
    },
    /// `main.xml` is not well-formed XML.
    #[error("{path}: main.xml is not well-formed XML: {message}")]
    Xml {
        /// The file.
        path: PathBuf,
        /// What the XML parser said.
        message: String,
    },
    /// A field of `main.xml` is missing or has an unusable value.
    #[error("{path}: main.xml field {field}: {message}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field's path in the record structure, e.g. `Record3/MatrixDimension/SizeX`.
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// The binary data does not match the declared size or checksum.
    #[error("{path}: {entry}: {message}")]
    Data {
        /// The file.
        path: PathBuf,
        /// The archive entry.
        entry: String,
        /// What is wrong.
        message: String,
    },
    /// The heightfield to write is invalid.
    #[error("cannot write {path}: {message}")]
    Invalid {
        /// The destination.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// The output could not be written.
    #[error(transparent)]
    Write(#[from] crate::base::io::WriteError),
    /// The surface read cannot be a heightfield.
    #[error("{0}")]
    Surface(&'static str),
    /// The x and y spacings differ (a heightfield has one pitch).
    #[error("x and y spacing differ ({x_mm} and {y_mm} mm)")]
    Anisotropic {
        /// x spacing, mm.
        x_mm: f64,
        /// y spacing, mm.
        y_mm: f64,
    },
}

/// A surface read from an X3P file.
#[derive(Clone, Debug)]
pub struct X3p {
    /// Points along x (`Record3/MatrixDimension/SizeX`).
    pub nx: usize,
    /// Points along y.
    pub ny: usize,
    /// Point spacing in x, mm (`CX/Increment` × 1000).
    pub pitch_x_mm: f64,
    /// Point spacing in y, mm.
    pub pitch_y_mm: f64,
    /// Heights in mm, row-major (x fastest); NaN where the point is invalid.
    pub z_mm: Vec<f64>,
    /// `true` where the point is valid.
    pub valid: Vec<bool>,
    /// The data type letter of the Z axis (`D`, `F`, `L`, `I`).
    pub data_type: char,
    /// Where `main.xml` sits in the archive.
    pub main_xml: String,
    /// `Record2/Creator`, when present.
    pub creator: Option<String>,
    /// `Record2/Instrument` manufacturer and model, when present.
    pub instrument: Option<String>,
    /// Whether the point data's MD5 matched `MD5ChecksumPointData` (`None`: no checksum given; a mismatch
    /// is refused when reading).
    pub data_checksum_ok: Option<bool>,
    /// What the reader noticed but read anyway (an increment on float data, an implausible height range).
    pub warnings: Vec<String>,
}

impl X3p {
    /// A surface that was not read from a file (no archive metadata): heights in mm on one pitch, with a
    /// validity mask. Used to treat a `.npy` heightfield or a masked copy like a scan.
    pub fn from_grid(nx: usize, ny: usize, pitch_mm: f64, z_mm: Vec<f64>, valid: Vec<bool>) -> Self {
        Self {
            nx,
            ny,
            pitch_x_mm: pitch_mm,
            pitch_y_mm: pitch_mm,
            z_mm,
            valid,
            data_type: 'D',
            main_xml: String::new(),
            creator: None,
            instrument: None,
            data_checksum_ok: None,
            warnings: Vec::new(),
        }
    }

    /// Number of invalid points.
    pub fn invalid_count(&self) -> usize {
        self.valid.iter().filter(|v| !**v).count()
    }

    /// The surface as a heightfield (mm, not periodic), invalid points filled by iterated averaging of
    /// their valid (or already filled) 8-neighbours, innermost first. Errors when no point is valid or the
    /// spacing differs between x and y (brdfmill's heightfields have one pitch).
    pub fn heightfield(&self) -> Result<Heightfield, X3pError> {
        if !self.valid.iter().any(|v| *v) {
            return Err(X3pError::Surface("the surface has no valid point"));
        }
        if (self.pitch_x_mm - self.pitch_y_mm).abs() > 1e-9 * self.pitch_x_mm {
            return Err(X3pError::Anisotropic {
                x_mm: self.pitch_x_mm,
                y_mm: self.pitch_y_mm,
            });
        }
        let (nx, ny) = (self.nx, self.ny);
        let mut z = self.z_mm.clone();
        let mut known = self.valid.clone();
        let neighbours = |k: usize| {
            let (i, j) = ((k % nx) as isize, (k / nx) as isize);
            (-1..=1isize)
                .flat_map(move |dj| (-1..=1isize).map(move |di| (i + di, j + dj, di, dj)))
                .filter(move |&(a, b, di, dj)| {
                    (di, dj) != (0, 0) && a >= 0 && b >= 0 && a < nx as isize && b < ny as isize
                })
                .map(move |(a, b, _, _)| b as usize * nx + a as usize)
        };
        // each round fills the missing points next to a known one, from the values known at its start; only
        // that frontier is visited, so a wide missing border costs its area, not its area times its depth
        let mut queued = vec![false; nx * ny];
        let mut frontier: Vec<usize> = (0..nx * ny)
            .filter(|&k| !known[k] && neighbours(k).any(|q| known[q]))
            .collect();
        frontier.iter().for_each(|&k| queued[k] = true);
        while !frontier.is_empty() {
            let fills: Vec<(usize, f64)> = frontier
                .iter()
                .map(|&k| {
                    let (s, n) = neighbours(k)
                        .filter(|&q| known[q])
                        .fold((0.0, 0usize), |(s, n), q| (s + z[q], n + 1));
                    (k, s / n as f64)
                })
                .collect();
            for (k, v) in &fills {
                z[*k] = *v;
                known[*k] = true;
            }
            let mut next = Vec::new();
            for (k, _) in &fills {
                for q in neighbours(*k) {
                    if !known[q] && !queued[q] {
                        queued[q] = true;
                        next.push(q);
                    }
                }
            }
            frontier = next;
        }
        Ok(Heightfield {
            nx,
            ny,
            pitch_mm: self.pitch_x_mm,
            periodic: false,
            z_mm: z,
        })
    }

    /// Central-difference slopes `(∂z/∂x, ∂z/∂y)` at every point whose four neighbours and itself are valid
    /// (pairs touching an invalid point are skipped); a border of `margin` (at least 1) points is left out.
    pub fn masked_slopes(&self, margin: usize) -> Vec<(f64, f64)> {
        masked_slopes(
            &self.z_mm,
            &self.valid,
            self.nx,
            [self.pitch_x_mm, self.pitch_y_mm],
            margin,
        )
    }
}

/// [`X3p::masked_slopes`] of any grid of heights `z_mm` (`nx` per row) with its validity mask and pitches
/// `[x, y]` in mm.
pub fn masked_slopes(z_mm: &[f64], valid: &[bool], nx: usize, pitch_mm: [f64; 2], margin: usize) -> Vec<(f64, f64)> {
    let ny = z_mm.len() / nx.max(1);
    let m = margin.max(1);
    let mut out = Vec::new();
    if nx <= 2 * m || ny <= 2 * m {
        return out;
    }
    for j in m..ny - m {
        for i in m..nx - m {
            let k = j * nx + i;
            if [k, k - 1, k + 1, k - nx, k + nx].iter().all(|q| valid[*q]) {
                out.push((
                    (z_mm[k + 1] - z_mm[k - 1]) / (2.0 * pitch_mm[0]),
                    (z_mm[k + nx] - z_mm[k - nx]) / (2.0 * pitch_mm[1]),
                ));
            }
        }
    }
    out
}

fn is_junk(name: &str) -> bool {
    name.starts_with("__MACOSX/") || name.rsplit('/').next().is_some_and(|f| f.starts_with("._"))
}

fn hex(d: &[u8]) -> String {
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// Read an X3P file (see the module notes for what is supported).
pub fn read(path: &Path) -> Result<X3p, X3pError> {
    let mut ar = Archive::open(path)?;
    let xml_bytes = ar.entry(&ar.main_xml.clone(), MAX_XML_BYTES)?;
    let xml = String::from_utf8_lossy(&xml_bytes);
    let xml = xml.trim_start_matches('\u{feff}');
    let doc = roxmltree::Document::parse(xml).map_err(|e| X3pError::Xml {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let m = MainXml { doc: &doc, path };
    let l = Layout::read(&m)?;
    let (mut z, checksum_ok) = point_values(&mut ar, &m, &l)?;
    if checksum_ok == Some(false) {
        return Err(X3pError::Data {
            path: path.to_path_buf(),
            entry: ar.linked(&m.text("Record3/DataLink/PointDataLink").unwrap_or_default()),
            message: "its MD5 differs from Record3/DataLink/MD5ChecksumPointData: the file is corrupted".into(),
        });
    }
    let valid = validity(&mut ar, &m, &z)?;
    for (v, ok) in z.iter_mut().zip(&valid) {
        // (no `+ 0.0` when there is no offset: it would turn −0.0 into +0.0)
        *v = match (*ok, l.offset_mm == 0.0) {
            (false, _) => f64::NAN,
            (true, true) => *v * l.scale,
            (true, false) => *v * l.scale + l.offset_mm,
        };
    }
    let instrument = match (
        m.text("Record2/Instrument/Manufacturer"),
        m.text("Record2/Instrument/Model"),
    ) {
        (Some(a), Some(b)) => Some(format!("{a} {b}")),
        (a, b) => a.or(b),
    };
    let mut warnings = l.warnings.clone();
    warnings.extend(plausibility(&z, &valid, &l));
    Ok(X3p {
        nx: l.nx,
        ny: l.ny,
        pitch_x_mm: l.pitch_mm[0],
        pitch_y_mm: l.pitch_mm[1],
        z_mm: z,
        valid,
        data_type: l.data_type,
        main_xml: ar.main_xml,
        creator: m.text("Record2/Creator"),
        instrument,
        data_checksum_ok: checksum_ok,
        warnings,
    })
}

/// A warning when the height range is implausible for the lateral size: steeper on average than 10:1 over
/// the whole surface, or flatter than 1 nm over it (a unit slip by 10³ or 10⁶ looks like one of these).
fn plausibility(z: &[f64], valid: &[bool], l: &Layout) -> Option<String> {
    let (lo, hi) = z
        .iter()
        .zip(valid)
        .filter(|(_, v)| **v)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (z, _)| {
            (a.min(*z), b.max(*z))
        });
    let range = hi - lo;
    let side = (l.nx as f64 * l.pitch_mm[0]).max(l.ny as f64 * l.pitch_mm[1]);
    if !(range.is_finite() && side > 0.0) {
        return None;
    }
    (range > 10.0 * side || (range > 0.0 && range < 1e-6)).then(|| {
        format!(
            "the heights span {range:.3e} mm over a {side:.3e} mm surface: check the file's Z units (CZ/Increment, CZ/DataType)"
        )
    })
}

/// An open X3P archive and where its `main.xml` sits (links resolve relative to that folder).
struct Archive<'p> {
    path: &'p Path,
    zip: zip::ZipArchive<std::io::BufReader<std::fs::File>>,
    main_xml: String,
}

impl<'p> Archive<'p> {
    /// Open the zip and find `main.xml`: the shortest path ending in it, macOS resource forks ignored.
    fn open(path: &'p Path) -> Result<Self, X3pError> {
        let file = std::fs::File::open(path).map_err(|source| crate::base::io::ReadError {
            path: path.to_path_buf(),
            source,
        })?;
        let zip = zip::ZipArchive::new(std::io::BufReader::new(file)).map_err(|e| X3pError::Zip {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let main_xml = zip
            .file_names()
            .filter(|n| !is_junk(n) && (*n == "main.xml" || n.ends_with("/main.xml")))
            .min_by_key(|n| n.len())
            .map(str::to_string)
            .ok_or_else(|| X3pError::MissingEntry {
                path: path.to_path_buf(),
                entry: "main.xml".into(),
            })?;
        Ok(Self { path, zip, main_xml })
    }

    /// The archive entry a link in `main.xml` names.
    fn linked(&self, link: &str) -> String {
        let base = &self.main_xml[..self.main_xml.len() - "main.xml".len()];
        format!("{base}{}", link.trim_start_matches("./"))
    }

    /// The bytes of one entry, refused before anything is allocated when it declares more than `max` bytes,
    /// and refused when it holds more than it declares (the declared size is the zip's, not the truth).
    fn entry(&mut self, name: &str, max: u64) -> Result<Vec<u8>, X3pError> {
        let f = self.zip.by_name(name).map_err(|_| X3pError::MissingEntry {
            path: self.path.to_path_buf(),
            entry: name.to_string(),
        })?;
        let too_big = |size: u64| X3pError::Data {
            path: self.path.to_path_buf(),
            entry: name.to_string(),
            message: format!("{size} bytes, more than the {max} it may hold"),
        };
        let declared = f.size();
        if declared > max {
            return Err(too_big(declared));
        }
        let mut v = Vec::with_capacity(declared as usize);
        f.take(max + 1)
            .read_to_end(&mut v)
            .map_err(|source| crate::base::io::ReadError {
                path: self.path.to_path_buf(),
                source,
            })?;
        if v.len() as u64 > max {
            return Err(too_big(v.len() as u64));
        }
        Ok(v)
    }
}

/// The fields of a parsed `main.xml`, by their path in the record structure (`Record3/MatrixDimension/SizeX`).
struct MainXml<'a, 'input> {
    doc: &'a roxmltree::Document<'input>,
    path: &'a Path,
}

impl<'a, 'input> MainXml<'a, 'input> {
    fn err(&self, field: &str, message: String) -> X3pError {
        X3pError::Field {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            message,
        }
    }

    fn find(&self, route: &str) -> Option<roxmltree::Node<'a, 'input>> {
        let mut node = self.doc.root_element();
        for part in route.split('/') {
            node = node
                .children()
                .find(|c| c.is_element() && c.tag_name().name() == part)?;
        }
        Some(node)
    }

    /// The trimmed text of a field, None when it is absent or has no text.
    fn text(&self, route: &str) -> Option<String> {
        self.find(route).and_then(|n| n.text()).map(|t| t.trim().to_string())
    }

    fn num(&self, route: &str) -> Result<f64, X3pError> {
        let t = self.text(route).ok_or_else(|| self.err(route, "missing".into()))?;
        t.parse::<f64>()
            .map_err(|_| self.err(route, format!("`{t}` is not a number")))
    }

    fn size(&self, route: &str) -> Result<usize, X3pError> {
        let t = self.text(route).ok_or_else(|| self.err(route, "missing".into()))?;
        t.parse::<usize>()
            .map_err(|_| self.err(route, format!("`{t}` is not a count")))
    }

    /// A number that may be absent or empty (then `default`).
    fn num_or(&self, route: &str, default: f64) -> Result<f64, X3pError> {
        match self.text(route).filter(|t| !t.is_empty()) {
            Some(_) => self.num(route),
            None => Ok(default),
        }
    }
}

/// The matrix size, spacing and Z encoding declared in Records 1 and 3.
struct Layout {
    nx: usize,
    ny: usize,
    /// `CX`, `CY` increments, mm.
    pitch_mm: [f64; 2],
    data_type: char,
    /// `CZ/Increment`, scaled to mm.
    scale: f64,
    /// `CZ/Offset`, mm.
    offset_mm: f64,
    /// What was read by a rule the file may not have meant.
    warnings: Vec<String>,
}

impl Layout {
    fn read(m: &MainXml) -> Result<Self, X3pError> {
        let nx = m.size("Record3/MatrixDimension/SizeX")?;
        let ny = m.size("Record3/MatrixDimension/SizeY")?;
        let nz = m.size("Record3/MatrixDimension/SizeZ")?;
        if nx == 0 || ny == 0 || nz != 1 {
            return Err(m.err(
                "Record3/MatrixDimension",
                format!("unsupported size {nx}×{ny}×{nz} (an areal surface has SizeZ 1)"),
            ));
        }
        if nx.checked_mul(ny).is_none_or(|n| n > MAX_POINTS) {
            return Err(m.err(
                "Record3/MatrixDimension",
                format!("{nx}×{ny} points is more than this reader's limit of {MAX_POINTS}"),
            ));
        }
        let mut pitch_mm = [0.0; 2];
        for (p, ax) in pitch_mm.iter_mut().zip(["CX", "CY"]) {
            let route = format!("Record1/Axes/{ax}/Increment");
            let v = m.num(&route)?;
            if !(v.is_finite() && v > 0.0) {
                return Err(m.err(&route, format!("spacing must be positive, got {v}")));
            }
            *p = v * 1000.0;
        }
        let data_type = m
            .text("Record1/Axes/CZ/DataType")
            .and_then(|t| t.chars().next())
            .ok_or_else(|| m.err("Record1/Axes/CZ/DataType", "missing".into()))?;
        let inc_route = "Record1/Axes/CZ/Increment";
        let inc = m.num_or(inc_route, 1.0)?;
        let offset = m.num_or("Record1/Axes/CZ/Offset", 0.0)?;
        if !offset.is_finite() {
            return Err(m.err(
                "Record1/Axes/CZ/Offset",
                format!("must be a finite length in m, got {offset}"),
            ));
        }
        if !(inc.is_finite() && inc != 0.0) {
            return Err(m.err(inc_route, format!("must be a finite, non-zero length in m, got {inc}")));
        }
        let mut warnings = Vec::new();
        let float = matches!(data_type, 'D' | 'F');
        let legacy = float
            && inc == 1.0e-3
            && m.text("Record2/Creator").is_some_and(|c| c.starts_with("brdfmill"))
            && m.text("Record2/Comment").is_some_and(|c| c.contains("stored in mm"));
        let scale = if float && !legacy {
            if inc != 1.0 {
                warnings.push(format!(
                    "{inc_route} = {inc} is not applied to floating-point heights (ISO 25178-72: the values are metres); a writer that meant it produced heights {inc} times these"
                ));
            }
            1000.0
        } else {
            if !(inc.is_finite() && inc > 0.0) {
                return Err(m.err(
                    inc_route,
                    format!("must be a positive length in m for data type {data_type}, got {inc}"),
                ));
            }
            inc * 1000.0
        };
        Ok(Self {
            nx,
            ny,
            pitch_mm,
            data_type,
            scale,
            offset_mm: offset * 1000.0,
            warnings,
        })
    }
}

/// The stored Z values (unscaled, NaN for an empty `Datum`) from the binary point data or the inline
/// `DataList`, and whether the binary data matched `MD5ChecksumPointData` (None: no checksum given).
fn point_values(ar: &mut Archive, m: &MainXml, l: &Layout) -> Result<(Vec<f64>, Option<bool>), X3pError> {
    if let Some(link) = m.text("Record3/DataLink/PointDataLink") {
        binary_values(ar, m, l, &link)
    } else if let Some(list) = m.find("Record3/DataList") {
        Ok((listed_values(m, l, list)?, None))
    } else {
        Err(m.err("Record3/DataLink/PointDataLink", "missing (and no DataList)".into()))
    }
}

/// Point data from the binary entry `link` names (little-endian, of the declared data type).
fn binary_values(ar: &mut Archive, m: &MainXml, l: &Layout, link: &str) -> Result<(Vec<f64>, Option<bool>), X3pError> {
    let (nx, ny, data_type) = (l.nx, l.ny, l.data_type);
    let n = nx * ny;
    let entry = ar.linked(link);
    let width = match data_type {
        'D' => 8,
        'F' | 'L' => 4,
        'I' => 2,
        c => {
            return Err(m.err(
                "Record1/Axes/CZ/DataType",
                format!("unknown data type `{c}` (D, F, L or I)"),
            ))
        }
    };
    let bytes = ar.entry(&entry, (n * width) as u64)?;
    let checksum_ok = m
        .text("Record3/DataLink/MD5ChecksumPointData")
        .map(|want| hex(&Md5::digest(&bytes)).eq_ignore_ascii_case(want.trim()));
    if bytes.len() != n * width {
        return Err(X3pError::Data {
            path: m.path.to_path_buf(),
            entry,
            message: format!(
                "{} bytes for {nx}×{ny} points of type {data_type} ({} expected)",
                bytes.len(),
                n * width
            ),
        });
    }
    let z = bytes
        .chunks_exact(width)
        .map(|c| match data_type {
            'D' => f64::from_le_bytes(c.try_into().unwrap_or([0; 8])),
            'F' => f32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            'L' => i32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            _ => i16::from_le_bytes(c.try_into().unwrap_or([0; 2])) as f64,
        })
        .collect();
    Ok((z, checksum_ok))
}

/// Point data from an inline `DataList`: one `Datum` per point, empty for an invalid one.
fn listed_values(m: &MainXml, l: &Layout, list: roxmltree::Node) -> Result<Vec<f64>, X3pError> {
    let (nx, ny) = (l.nx, l.ny);
    let data: Vec<_> = list
        .children()
        .filter(|c| c.is_element() && c.tag_name().name() == "Datum")
        .collect();
    if data.len() != nx * ny {
        return Err(m.err(
            "Record3/DataList",
            format!("{} Datum elements for {nx}×{ny} points", data.len()),
        ));
    }
    let mut z = vec![f64::NAN; nx * ny];
    for (k, d) in data.iter().enumerate() {
        let t = d.text().map(str::trim).unwrap_or("");
        if !t.is_empty() {
            z[k] = t
                .parse::<f64>()
                .map_err(|_| m.err("Record3/DataList/Datum", format!("`{t}` at point {k}")))?;
        }
    }
    Ok(z)
}

/// Which points are valid: finite values, and set in the `ValidPointsLink` bit array when there is one.
fn validity(ar: &mut Archive, m: &MainXml, z: &[f64]) -> Result<Vec<bool>, X3pError> {
    let n = z.len();
    let mut valid: Vec<bool> = z.iter().map(|v| v.is_finite()).collect();
    // The schema puts it in the DataLink record; some writers put it beside it.
    let link = m
        .text("Record3/DataLink/ValidPointsLink")
        .or_else(|| m.text("Record3/ValidPointsLink"));
    if let Some(link) = link {
        let entry = ar.linked(&link);
        let bits = ar.entry(&entry, n.div_ceil(8) as u64 + 64)?;
        if bits.len() * 8 < n {
            return Err(X3pError::Data {
                path: m.path.to_path_buf(),
                entry,
                message: format!("{} bytes of validity bits for {n} points", bits.len()),
            });
        }
        for (k, v) in valid.iter_mut().enumerate() {
            *v &= bits[k / 8] >> (k % 8) & 1 == 1;
        }
    }
    Ok(valid)
}

/// The floating-point type of the heights an X3P file is written with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// `D`: IEEE float64, metres.
    F64,
    /// `F`: IEEE float32, metres (about 7 significant digits: 0.1 nm on a millimetre of relief).
    F32,
}

fn main_xml(hf: &Heightfield, data_md5: &str, precision: Precision) -> String {
    let pitch_m = hf.pitch_mm * 1e-3;
    format!(
        r#"<?xml version="1.0" encoding="UTF-8" standalone="no" ?>
<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="http://www.opengps.eu/2008/ISO5436_2 http://www.opengps.eu/2008/ISO5436_2/ISO5436_2.xsd">
  <Record1>
    <Revision>ISO5436 - 2000</Revision>
    <FeatureType>SUR</FeatureType>
    <Axes>
      <CX>
        <AxisType>I</AxisType>
        <DataType>D</DataType>
        <Increment>{pitch_m:e}</Increment>
        <Offset>0</Offset>
      </CX>
      <CY>
        <AxisType>I</AxisType>
        <DataType>D</DataType>
        <Increment>{pitch_m:e}</Increment>
        <Offset>0</Offset>
      </CY>
      <CZ>
        <AxisType>A</AxisType>
        <DataType>{z_type}</DataType>
        <Increment>1</Increment>
        <Offset>0</Offset>
      </CZ>
    </Axes>
  </Record1>
  <Record2>
    <Date>1970-01-01T00:00:00+00:00</Date>
    <Creator>brdfmill {version}</Creator>
    <Instrument>
      <Manufacturer>brdfmill</Manufacturer>
      <Model>simulated surface ({periodic})</Model>
      <Serial>not available</Serial>
      <Version>{version}</Version>
    </Instrument>
    <CalibrationDate>1970-01-01T00:00:00+00:00</CalibrationDate>
    <ProbingSystem>
      <Type>Software</Type>
      <Identification>brdfmill</Identification>
    </ProbingSystem>
    <Comment>Heights in metres ({z_name}), as ISO 25178-72 defines floating-point data.</Comment>
  </Record2>
  <Record3>
    <MatrixDimension>
      <SizeX>{nx}</SizeX>
      <SizeY>{ny}</SizeY>
      <SizeZ>1</SizeZ>
    </MatrixDimension>
    <DataLink>
      <PointDataLink>bindata/data.bin</PointDataLink>
      <MD5ChecksumPointData>{data_md5}</MD5ChecksumPointData>
    </DataLink>
  </Record3>
  <Record4>
    <ChecksumFile>md5checksum.hex</ChecksumFile>
  </Record4>
</p:ISO5436_2>
"#,
        version = env!("CARGO_PKG_VERSION"),
        periodic = if hf.periodic { "periodic" } else { "not periodic" },
        z_type = match precision {
            Precision::F64 => 'D',
            Precision::F32 => 'F',
        },
        z_name = match precision {
            Precision::F64 => "float64",
            Precision::F32 => "float32",
        },
        nx = hf.nx,
        ny = hf.ny,
    )
}

/// Write a heightfield as an X3P file, atomically: `main.xml` (Records 1–4), `bindata/data.bin` (f64
/// little-endian, heights in metres, see the module notes) with its MD5 in
/// `MD5ChecksumPointData`, and `md5checksum.hex` (the MD5 of `main.xml`).
pub fn write(path: &Path, hf: &Heightfield) -> Result<(), X3pError> {
    write_as(path, hf, Precision::F64)
}

/// [`write()`] with the heights' type chosen: float32 halves a large simulated cut (`sim.x3p`), and its
/// 24-bit mantissa still resolves 0.1 nm on a millimetre of relief.
pub fn write_as(path: &Path, hf: &Heightfield, precision: Precision) -> Result<(), X3pError> {
    hf.check_invariants().map_err(|message| X3pError::Invalid {
        path: path.to_path_buf(),
        message: message.to_string(),
    })?;
    let data: Vec<u8> = match precision {
        Precision::F64 => hf.z_mm.iter().flat_map(|v| (v * 1e-3).to_le_bytes()).collect(),
        Precision::F32 => hf.z_mm.iter().flat_map(|v| ((v * 1e-3) as f32).to_le_bytes()).collect(),
    };
    let xml = main_xml(hf, &hex(&Md5::digest(&data)), precision);
    let sum = format!("{} *main.xml\n", hex(&Md5::digest(xml.as_bytes())));
    crate::base::io::write_atomic_with(path, |w| {
        let mut buf = std::io::Cursor::new(Vec::new());
        {
            let mut zw = zip::ZipWriter::new(&mut buf);
            // the fastest deflate level: a simulated cut's tens of megabytes in a fraction of a second
            let opts = zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Deflated)
                .compression_level(Some(1))
                .last_modified_time(zip::DateTime::default());
            let ze = |e: zip::result::ZipError| std::io::Error::other(e.to_string());
            zw.start_file("main.xml", opts).map_err(ze)?;
            zw.write_all(xml.as_bytes())?;
            zw.add_directory("bindata/", opts).map_err(ze)?;
            zw.start_file("bindata/data.bin", opts).map_err(ze)?;
            zw.write_all(&data)?;
            zw.start_file("md5checksum.hex", opts).map_err(ze)?;
            zw.write_all(sum.as_bytes())?;
            zw.finish().map_err(ze)?;
        }
        w.write_all(buf.get_ref())
    })?;
    Ok(())
}

#[cfg(test)]
mod tests;
