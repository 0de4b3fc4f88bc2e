//! Spatially varying targets: a label image says which target each point of the part takes, each region is
//! filled with its own periodic tile, and [`compose`] puts the tiles together into one part heightfield that
//! the toolpath cuts in one program (DESIGN.md §3.3).
//!
//! ```toml
//! [svbrdf]
//! labels = "logo.png"                 # spans toolpath.area_mm; image right = +x, up = +y
//! [[svbrdf.region]]
//! name = "logo"
//! color = "#000000"                   # the label colour of its pixels
//! brdf = "beckmann:alpha=0.1,material=aluminium"   # or highlight = "star.png" (+ highlight_extent_deg, material)
//! [[svbrdf.region]]
//! name = "field"
//! color = "#ffffff"
//! brdf = "beckmann:alpha=0.25,material=aluminium"
//! ```
//!
//! Every region's tile has the same period (the job's `facets`), laid from the work origin, so the facet
//! lattices of all regions coincide and a border only switches which tile's heights are cut.

use crate::base::Invalid;
mod compose;
mod edt;

pub use compose::{compose, Alignment, Part, MAX_PART_CELLS};
pub use edt::distance_to_outside;

use crate::base::plot::Canvas;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// `[svbrdf]`: the label image and its regions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SvbrdfSection {
    /// The label image (PNG, relative to the job file). It spans the work area (`toolpath.area_mm`) with
    /// square pixels; each pixel's colour names its region.
    pub labels: String,
    /// The regions, one per label colour.
    #[serde(default)]
    pub region: Vec<RegionSection>,
}

/// `[[svbrdf.region]]`: one label colour and its target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSection {
    /// A name for files and the report: 1–32 of `a–z`, `0–9`, `-`, `_`.
    pub name: String,
    /// The label colour, `#rrggbb`.
    pub color: String,
    /// The region's target BRDF spec (or give `highlight`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub brdf: String,
    /// A drawn highlight (PNG) as the region's target instead of a BRDF.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight: Option<String>,
    /// The highlight image's extent, degrees (with `highlight`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlight_extent_deg: Option<f64>,
    /// The part's material (with `highlight`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
}

/// What is wrong with a label image or its regions.
#[derive(Debug, thiserror::Error)]
pub enum SvbrdfError {
    /// The image cannot be used.
    #[error("{path}: {reason}")]
    Image {
        /// The label image.
        path: String,
        /// Why.
        reason: String,
    },
    /// A colour in the image that no region names.
    #[error("{path}: label colour {color} ({count} pixels, the first at column {col}, row {row} from the top) has no [[svbrdf.region]]; add a region with `color = \"{color}\"` or repaint those pixels")]
    Unlabelled {
        /// The label image.
        path: String,
        /// `#rrggbb`.
        color: String,
        /// Pixels of that colour.
        count: usize,
        /// First pixel's column.
        col: usize,
        /// … and row.
        row: usize,
    },
    /// A region whose colour is nowhere in the image.
    #[error("{path}: region `{name}` (color = \"{color}\") has no pixels in the label image")]
    Absent {
        /// The label image.
        path: String,
        /// Region name.
        name: String,
        /// `#rrggbb`.
        color: String,
    },
    /// A region too small to hold one tile period.
    #[error("region `{name}` (color = \"{color}\") holds no {px:.2} × {py:.2} mm square (one tile period, `facets.facets_x/facets_y × facet_mm`): a region smaller than its tile cannot show the tile's distribution; enlarge it or make the tiles smaller")]
    TooSmall {
        /// Region name.
        name: String,
        /// `#rrggbb`.
        color: String,
        /// Period along x, mm.
        px: f64,
        /// Period along y, mm.
        py: f64,
    },
    /// The regions or the composition cannot be made as asked.
    #[error("{0}")]
    Config(String),
}

/// A colour `#rrggbb` (the `#` optional, case-insensitive).
pub fn parse_color(s: &str) -> Result<[u8; 3], Invalid> {
    let h = s.trim().trim_start_matches('#');
    if h.len() != 6 || !h.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(Invalid(format!(
            "`{s}` is not a colour: expected #rrggbb, e.g. \"#000000\""
        )));
    }
    let v = |k: usize| u8::from_str_radix(&h[k..k + 2], 16).map_err(|e| e.to_string());
    Ok([v(0)?, v(2)?, v(4)?])
}

/// `#rrggbb` of a colour.
pub fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// A region name usable in file names: 1–32 of `a–z`, `0–9`, `-`, `_`.
pub fn check_name(name: &str) -> Result<(), Invalid> {
    let ok = (1..=32).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_');
    if ok {
        Ok(())
    } else {
        Err(Invalid(format!(
            "`{name}` is not a region name: 1–32 of a–z, 0–9, `-` and `_` (it names the region's files)"
        )))
    }
}

/// The most regions a label image may have.
pub const MAX_REGIONS: usize = 16;

/// The largest label image file read, bytes.
pub const MAX_FILE_BYTES: u64 = 64 << 20;

/// A label image read and checked against its regions: each pixel's region index.
#[derive(Clone, Debug)]
pub struct Labels {
    /// The image file.
    pub path: PathBuf,
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Region index per pixel, rows top first.
    pub index: Vec<u8>,
    /// The work area the image spans, mm.
    pub area_mm: [f64; 2],
    /// The regions' colours, in region order.
    pub colors: Vec<[u8; 3]>,
    /// The regions' names.
    pub names: Vec<String>,
}

impl Labels {
    /// Read `path` for regions of `colors` (named `names`) spanning `area_mm`. Every pixel must be one of
    /// the colours, every colour must have pixels, and the pixels must be square on the part (within 2%).
    pub fn read(path: &Path, names: &[String], colors: &[[u8; 3]], area_mm: [f64; 2]) -> Result<Labels, SvbrdfError> {
        let shown = path.display().to_string();
        let bad = |reason: String| SvbrdfError::Image {
            path: shown.clone(),
            reason,
        };
        let meta = std::fs::metadata(path).map_err(|e| bad(format!("cannot read the label image: {e}")))?;
        if meta.len() > MAX_FILE_BYTES {
            return Err(bad(format!(
                "the file is {} bytes; at most {MAX_FILE_BYTES} are read",
                meta.len()
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| bad(format!("cannot read the label image: {e}")))?;
        let img = crate::base::image::decode_png(&bytes).map_err(|e| bad(e.0))?;
        let (w, h) = (img.width, img.height);
        if w < 2 || h < 2 {
            return Err(bad(format!(
                "the image is {w} × {h} pixels; a label map needs at least 2 × 2"
            )));
        }
        let [ax, ay] = area_mm;
        let aspect = (ax / w as f64) / (ay / h as f64);
        if (aspect - 1.0).abs() > 0.02 {
            return Err(bad(format!(
                "the image is {w} × {h} pixels but `toolpath.area_mm` is {ax} × {ay} mm: its pixels would be {:.4} × {:.4} mm, not square; make the image's aspect ratio the area's",
                ax / w as f64,
                ay / h as f64
            )));
        }
        if colors.len() > MAX_REGIONS {
            return Err(SvbrdfError::Config(format!(
                "{} regions; at most {MAX_REGIONS}",
                colors.len()
            )));
        }
        let mut index = Vec::with_capacity(w * h);
        // colours no region names: (first column, first row, count), for the message
        let mut strays: std::collections::HashMap<[u8; 3], (usize, usize, usize)> = Default::default();
        for row in 0..h {
            for col in 0..w {
                let px = img.pixel(col, row);
                if matches!(img.channels, 2 | 4) && px[img.channels - 1] != 255 {
                    return Err(bad(format!(
                        "pixel (column {col}, row {row} from the top) is not opaque (alpha {}): a label image is exact colours, every pixel one region's",
                        px[img.channels - 1]
                    )));
                }
                let c = img.rgb(col, row);
                match colors.iter().position(|k| *k == c) {
                    Some(k) => index.push(k as u8),
                    None => {
                        strays.entry(c).or_insert((col, row, 0)).2 += 1;
                        index.push(0);
                    }
                }
            }
        }
        // the most common stray colour, ties to the first seen
        let worst = strays
            .iter()
            .max_by(|a, b| a.1 .2.cmp(&b.1 .2).then((b.1 .1, b.1 .0).cmp(&(a.1 .1, a.1 .0))))
            .map(|(c, &(col, row, count))| (*c, col, row, count));
        if let Some((c, col, row, count)) = worst {
            return Err(SvbrdfError::Unlabelled {
                path: shown,
                color: hex(c),
                count,
                col,
                row,
            });
        }
        let labels = Labels {
            path: path.to_path_buf(),
            width: w,
            height: h,
            index,
            area_mm,
            colors: colors.to_vec(),
            names: names.to_vec(),
        };
        for (k, f) in labels.fractions().iter().enumerate() {
            if *f == 0.0 {
                return Err(SvbrdfError::Absent {
                    path: shown,
                    name: names[k].clone(),
                    color: hex(colors[k]),
                });
            }
        }
        Ok(labels)
    }

    /// The region at work point `(x, y)` mm (clamped to the image).
    #[inline]
    pub fn at(&self, x_mm: f64, y_mm: f64) -> usize {
        let [ax, ay] = self.area_mm;
        let col = ((x_mm / ax * self.width as f64).floor().max(0.0) as usize).min(self.width - 1);
        let up = ((y_mm / ay * self.height as f64).floor().max(0.0) as usize).min(self.height - 1);
        self.index[(self.height - 1 - up) * self.width + col] as usize
    }

    /// Each region's share of the image.
    pub fn fractions(&self) -> Vec<f64> {
        let mut n = vec![0usize; self.colors.len()];
        for &k in &self.index {
            n[k as usize] += 1;
        }
        n.iter().map(|&c| c as f64 / self.index.len() as f64).collect()
    }

    /// Refuse a region that holds no square of one tile period (`period_mm`), tested on the image's
    /// pixels with a summed-area table.
    pub fn check_period(&self, period_mm: [f64; 2]) -> Result<(), SvbrdfError> {
        let (w, h) = (self.width, self.height);
        let sx = (period_mm[0] / self.area_mm[0] * w as f64).ceil() as usize;
        let sy = (period_mm[1] / self.area_mm[1] * h as f64).ceil() as usize;
        for k in 0..self.colors.len() {
            let fits = sx <= w && sy <= h && {
                let mut sat = vec![0u32; (w + 1) * (h + 1)];
                for r in 0..h {
                    let mut run = 0u32;
                    for c in 0..w {
                        run += (self.index[r * w + c] as usize == k) as u32;
                        sat[(r + 1) * (w + 1) + c + 1] = sat[r * (w + 1) + c + 1] + run;
                    }
                }
                let need = (sx * sy) as u32;
                (0..=h - sy).any(|r| {
                    (0..=w - sx).any(|c| {
                        let s = |rr: usize, cc: usize| sat[rr * (w + 1) + cc];
                        s(r + sy, c + sx) + s(r, c) - s(r, c + sx) - s(r + sy, c) == need
                    })
                })
            };
            if !fits {
                return Err(SvbrdfError::TooSmall {
                    name: self.names[k].clone(),
                    color: hex(self.colors[k]),
                    px: period_mm[0],
                    py: period_mm[1],
                });
            }
        }
        Ok(())
    }

    /// The label map as a picture: each region in its own label colour (a dark or light outline keeps a
    /// white or black region visible), with the work axes.
    pub fn figure(&self, max_px: usize) -> Canvas {
        let s = (max_px as f64 / self.width.max(self.height) as f64).clamp(0.05, 4.0);
        let (cw, ch) = (
            ((self.width as f64 * s).round() as usize).max(1),
            ((self.height as f64 * s).round() as usize).max(1),
        );
        let mut c = Canvas::new(cw as u32 + 2, ch as u32 + 2);
        for y in 0..ch {
            for x in 0..cw {
                let col = ((x as f64 / s) as usize).min(self.width - 1);
                let row = ((y as f64 / s) as usize).min(self.height - 1);
                let k = self.index[row * self.width + col] as usize;
                c.put(x as i64 + 1, y as i64 + 1, self.colors[k]);
            }
        }
        c.frame(0, 0, cw as u32 + 2, ch as u32 + 2);
        c
    }
}

#[cfg(test)]
mod tests;
