//! A tabulated half-angle distribution from a gonioreflectometer, as CSV.
//!
//! Each data line is `theta_h_deg,phi_h_deg,value` (degrees; value proportional to `D(wh)`); blank lines and
//! lines starting with `#` are skipped, and a first line that is not numeric is taken as a header. The samples
//! must form a full tensor grid: every listed θh with every listed φh. A single φh means an isotropic
//! distribution. Values are interpolated bilinearly in `(θh, φh)` (φh periodic when the table covers a full
//! turn) and normalised so that `∫ D cosθ dω = 1`. Beyond the largest θh the distribution is zero.
//!
//! Used as a BRDF, it is the NDF of a microfacet model whose Smith masking is computed from the table itself.

use super::BrdfError;
use crate::base::geometry::{cos_sin_phi, Vec3};
use crate::base::slope::{SlopeDomain, SlopeGrid, SmithTable};
use crate::base::Invalid;
use std::path::Path;

/// A tabulated, normalised NDF with the Smith masking of its own slopes.
#[derive(Clone, Debug)]
pub struct TabulatedNdf {
    table: Table,
    /// Smith Λ of the table, for the masking term.
    smith: SmithTable,
}

/// The raw table and its interpolation.
#[derive(Clone, Debug)]
struct Table {
    /// Sorted polar angles of the table (radians).
    theta: Vec<f64>,
    /// Sorted azimuths (radians); one entry for an isotropic table.
    phi: Vec<f64>,
    /// `values[it * phi.len() + ip]`, normalised.
    values: Vec<f64>,
    /// φ wraps around (the table covers a full turn).
    periodic: bool,
}

impl TabulatedNdf {
    /// Read and validate a CSV table.
    pub fn read(path: &Path) -> Result<Self, BrdfError> {
        let text = crate::base::io::read_to_string(path)?;
        Self::parse(&text).map_err(|reason| BrdfError::Format {
            path: path.to_path_buf(),
            reason: reason.0,
        })
    }

    /// Parse CSV text; the error names the line and what was expected.
    pub fn parse(text: &str) -> Result<Self, Invalid> {
        let mut rows: Vec<(f64, f64, f64)> = Vec::new();
        let mut seen_data = false;
        for (n, line) in text.lines().enumerate() {
            let lineno = n + 1;
            let l = line.trim();
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = l.split(',').map(str::trim).collect();
            let nums: Result<Vec<f64>, _> = fields.iter().map(|f| f.parse::<f64>()).collect();
            let nums = match nums {
                Ok(v) => v,
                Err(_) if !seen_data => {
                    seen_data = true; // a header line
                    continue;
                }
                Err(_) => {
                    return Err(Invalid(format!(
                        "line {lineno}: expected three numbers theta_h_deg,phi_h_deg,value, got `{l}`"
                    )))
                }
            };
            seen_data = true;
            if nums.len() != 3 {
                return Err(Invalid(format!(
                    "line {lineno}: expected 3 fields theta_h_deg,phi_h_deg,value, got {}",
                    nums.len()
                )));
            }
            let names = ["theta_h_deg", "phi_h_deg", "value"];
            if let Some(k) = nums.iter().position(|v| !v.is_finite()) {
                return Err(Invalid(format!(
                    "line {lineno}: {} is `{}`, expected a finite number",
                    names[k], fields[k]
                )));
            }
            if !(0.0..=90.0).contains(&nums[0]) {
                return Err(Invalid(format!(
                    "line {lineno}: theta_h_deg = {} outside [0, 90]",
                    nums[0]
                )));
            }
            if nums[2] < 0.0 {
                return Err(Invalid(format!("line {lineno}: value = {} is negative", nums[2])));
            }
            rows.push((
                nums[0].to_radians(),
                nums[1].to_radians().rem_euclid(std::f64::consts::TAU),
                nums[2],
            ));
        }
        let uniq = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            v
        };
        let theta = uniq(rows.iter().map(|r| r.0).collect());
        let phi = uniq(rows.iter().map(|r| r.1).collect());
        if theta.len() < 2 {
            return Err(Invalid(format!(
                "need at least 2 distinct theta_h values, got {}",
                theta.len()
            )));
        }
        if rows.len() != theta.len() * phi.len() {
            return Err(Invalid(format!(
                "the samples must form a full grid: {} theta_h × {} phi_h values = {} samples, but the file has {}",
                theta.len(),
                phi.len(),
                theta.len() * phi.len(),
                rows.len()
            )));
        }
        let find = |v: &[f64], x: f64| v.iter().position(|a| (a - x).abs() < 1e-9).unwrap();
        let mut values = vec![f64::NAN; rows.len()];
        for r in &rows {
            let k = find(&theta, r.0) * phi.len() + find(&phi, r.1);
            if !values[k].is_nan() {
                return Err(Invalid(format!(
                    "sample theta_h={:.4}°, phi_h={:.4}° is given twice",
                    r.0.to_degrees(),
                    r.1.to_degrees()
                )));
            }
            values[k] = r.2;
        }
        // A table covers a full turn when its φ spacing is uniform and the next step wraps to the first value.
        let periodic = phi.len() > 2 && {
            let step = phi[1] - phi[0];
            (std::f64::consts::TAU - (phi[phi.len() - 1] - phi[0]) - step).abs() < 1e-6
        };
        let mut table = Table {
            theta,
            phi,
            values,
            periodic,
        };
        let mass = table.projected_mass();
        if !mass.is_finite() {
            return Err(Invalid(format!(
                "the values are too large: their projected mass is {mass} (each value must keep the integral finite)"
            )));
        }
        if mass <= 0.0 {
            return Err(Invalid("all values are zero: the distribution has no mass".to_string()));
        }
        table.values.iter_mut().for_each(|v| *v /= mass);
        let grid = slope_grid_of(&table, SlopeDomain::square(256, 80f64.to_radians().tan()));
        let smith = SmithTable::new(&grid, 48, 48);
        Ok(Self { table, smith })
    }

    /// The normalised NDF `D(wm)`.
    pub fn d(&self, wm: &Vec3) -> f64 {
        self.table.d(wm)
    }

    /// The slope density of the table on a grid.
    pub fn slope_grid(&self, domain: SlopeDomain) -> SlopeGrid {
        slope_grid_of(&self.table, domain)
    }

    /// Separable Smith masking from the table's own Λ.
    pub fn g(&self, wi: &Vec3, wo: &Vec3, wm: &Vec3) -> f64 {
        self.smith.g2(wi, wo, wm)
    }
}

fn slope_grid_of(t: &Table, domain: SlopeDomain) -> SlopeGrid {
    SlopeGrid::from_fn(domain, |p, q| {
        let wm = crate::base::geometry::slope_to_normal(p, q);
        t.d(&wm) * wm.z.powi(4)
    })
}

impl Table {
    /// `∫ D cosθ dω` of the raw table, by quadrature in (θ, φ).
    fn projected_mass(&self) -> f64 {
        let (nt, np) = (720, 360);
        let tmax = *self.theta.last().unwrap();
        let mut acc = 0.0;
        for it in 0..nt {
            let th = (it as f64 + 0.5) / nt as f64 * tmax;
            for ip in 0..np {
                let ph = (ip as f64 + 0.5) / np as f64 * std::f64::consts::TAU;
                acc += self.lookup(th, ph) * th.cos() * th.sin();
            }
        }
        acc * (tmax / nt as f64) * (std::f64::consts::TAU / np as f64)
    }

    fn lookup(&self, theta: f64, phi: f64) -> f64 {
        let (t0, t1, ft) = bracket(&self.theta, theta, false);
        if theta > *self.theta.last().unwrap() + 1e-12 {
            return 0.0;
        }
        let (p0, p1, fp) = if self.phi.len() == 1 {
            (0, 0, 0.0)
        } else {
            bracket(&self.phi, phi.rem_euclid(std::f64::consts::TAU), self.periodic)
        };
        let np = self.phi.len();
        let v = |a: usize, b: usize| self.values[a * np + b];
        (1.0 - ft) * ((1.0 - fp) * v(t0, p0) + fp * v(t0, p1)) + ft * ((1.0 - fp) * v(t1, p0) + fp * v(t1, p1))
    }

    fn d(&self, wm: &Vec3) -> f64 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        let (c, s) = cos_sin_phi(wm);
        self.lookup(wm.z.min(1.0).acos(), s.atan2(c))
    }
}

/// Indices and weight of the two table entries around `x` (clamped at the ends, or wrapping around a turn).
fn bracket(v: &[f64], x: f64, periodic: bool) -> (usize, usize, f64) {
    let n = v.len();
    if periodic {
        let k = v.iter().rposition(|a| *a <= x);
        return match k {
            Some(k) if k + 1 < n => (k, k + 1, (x - v[k]) / (v[k + 1] - v[k])),
            Some(k) => (k, 0, (x - v[k]) / (v[0] + std::f64::consts::TAU - v[k])),
            None => (
                n - 1,
                0,
                (x + std::f64::consts::TAU - v[n - 1]) / (v[0] + std::f64::consts::TAU - v[n - 1]),
            ),
        };
    }
    if x <= v[0] {
        return (0, 0, 0.0);
    }
    if x >= v[n - 1] {
        return (n - 1, n - 1, 0.0);
    }
    let k = v.iter().rposition(|a| *a <= x).unwrap();
    (k, k + 1, (x - v[k]) / (v[k + 1] - v[k]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::geometry::spherical;
    use crate::stages::brdf::Microfacet;

    fn beckmann_csv(alpha: f64, nphi: usize) -> String {
        let m = Microfacet::new(crate::stages::brdf::Family::Beckmann, alpha, alpha).unwrap();
        let mut s = String::from("theta_h_deg,phi_h_deg,value\n");
        for it in 0..=180 {
            let th = it as f64 * 0.5;
            for ip in 0..nphi {
                let ph = ip as f64 * 360.0 / nphi as f64;
                // an arbitrary scale: the reader normalises
                let v = 7.0 * m.d(&spherical(th.to_radians(), ph.to_radians()));
                s.push_str(&format!("{th},{ph},{v}\n"));
            }
        }
        s
    }

    #[test]
    fn isotropic_table_reproduces_the_normalised_ndf() {
        let t = TabulatedNdf::parse(&beckmann_csv(0.3, 1)).unwrap();
        let m = Microfacet::new(crate::stages::brdf::Family::Beckmann, 0.3, 0.3).unwrap();
        for th in [0.0f64, 0.1, 0.3, 0.6] {
            let w = spherical(th, 1.0);
            let (a, b) = (t.d(&w), m.d(&w));
            assert!((a - b).abs() < 1e-2 * b, "θ={th}: {a} vs {b}");
        }
    }

    #[test]
    fn periodic_table_wraps_in_phi() {
        let t = TabulatedNdf::parse(&beckmann_csv(0.3, 8)).unwrap();
        assert!(t.table.periodic);
        let a = t.d(&spherical(0.3, -0.1));
        let b = t.d(&spherical(0.3, 0.1));
        assert!((a - b).abs() < 1e-6 * a);
    }

    #[test]
    fn bad_tables_name_the_line() {
        let nan = "theta_h_deg,phi_h_deg,value\n0,0,1\n1,0,NaN\n";
        let e = TabulatedNdf::parse(nan).unwrap_err();
        assert!(e.contains("line 3") && e.contains("value"), "{e}");
        let e = TabulatedNdf::parse("0,0,1\n1,0\n").unwrap_err();
        assert!(e.contains("line 2"), "{e}");
        let e = TabulatedNdf::parse("0,0,1\n1,0,1\n1,90,1\n").unwrap_err();
        assert!(e.contains("full grid"), "{e}");
        let e = TabulatedNdf::parse("0,0,0\n1,0,0\n").unwrap_err();
        assert!(e.contains("no mass"), "{e}");
        let e = TabulatedNdf::parse("0,0,1\n100,0,1\n").unwrap_err();
        assert!(e.contains("outside [0, 90]"), "{e}");
    }
}
