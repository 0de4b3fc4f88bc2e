//! The crate's one model of a cutter's geometry: the end of a ball, flat or bull-nose end mill, shared by
//! the machine profiles (`cut::machine::Tool` holds one), the drop-cutter and the simulator's sweep.
//!
//! The underside of the tool, as a height above its tip at horizontal distance `ρ` from its axis
//! (`0 ≤ ρ ≤ R`, `R` the radius):
//!
//! - ball of radius `R`: `b(ρ) = R − √(R² − ρ²)`;
//! - flat: `b(ρ) = 0`;
//! - bull-nose with corner radius `r_c < R`: `b(ρ) = 0` for `ρ ≤ R − r_c`, else `r_c − √(r_c² − (ρ − R + r_c)²)`.
//!
//! A bull whose corner radius is the tool's radius is a ball ([`Shape::normalized`]).

use serde::{Deserialize, Serialize};
use std::fmt;

/// A tool whose dimensions are not a tool: the field and the value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{field}: expected {expected}, got {value}")]
pub struct ShapeError {
    /// The field (`diameter_mm`, `corner_radius_mm`, or the spec text).
    pub field: String,
    /// What was expected.
    pub expected: String,
    /// What was given.
    pub value: String,
}

/// The cutting end of an end mill. Lengths in mm. Serialised as `{"ball": {"diameter_mm": 1.0}}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// Ball-nose end mill.
    Ball {
        /// Diameter, mm.
        diameter_mm: f64,
    },
    /// Flat end mill.
    Flat {
        /// Diameter, mm.
        diameter_mm: f64,
    },
    /// Bull-nose end mill: a flat end with rounded corners.
    Bull {
        /// Diameter, mm.
        diameter_mm: f64,
        /// Corner radius, mm (in (0, diameter/2]; half the diameter is a ball).
        corner_radius_mm: f64,
    },
}

impl Default for Shape {
    fn default() -> Self {
        Shape::Ball { diameter_mm: 1.0 }
    }
}

impl Shape {
    /// A shape from a profile's fields: `kind` (`ball`, `flat`, `bull`), diameter and corner radius (used by
    /// `bull` only; a ball's, when given, must be its radius). Checked as [`Shape::validate`].
    pub fn from_parts(kind: &str, diameter_mm: f64, corner_radius_mm: Option<f64>) -> Result<Shape, ShapeError> {
        Shape::Flat { diameter_mm }.validate()?;
        let shape = match kind {
            "ball" => {
                if let Some(rc) = corner_radius_mm {
                    if (rc - diameter_mm / 2.0).abs() > 1e-9 {
                        return Err(ShapeError {
                            field: "corner_radius_mm".into(),
                            expected: format!("the ball's radius {} (or left out)", diameter_mm / 2.0),
                            value: rc.to_string(),
                        });
                    }
                }
                Shape::Ball { diameter_mm }
            }
            "flat" => {
                if let Some(rc) = corner_radius_mm.filter(|rc| *rc != 0.0) {
                    return Err(ShapeError {
                        field: "corner_radius_mm".into(),
                        expected: "0 (or left out) for a flat end mill".into(),
                        value: rc.to_string(),
                    });
                }
                Shape::Flat { diameter_mm }
            }
            "bull" => Shape::Bull {
                diameter_mm,
                corner_radius_mm: corner_radius_mm.unwrap_or(f64::NAN),
            },
            other => {
                return Err(ShapeError {
                    field: "kind".into(),
                    expected: "one of ball, flat, bull".into(),
                    value: other.to_string(),
                })
            }
        };
        shape.validate()?;
        Ok(shape)
    }

    /// Parse `ball:D`, `flat:D` or `bull:D:R` (diameter and corner radius in mm).
    pub fn parse(s: &str) -> Result<Shape, ShapeError> {
        let parts: Vec<&str> = s.split(':').map(str::trim).collect();
        let bad = |expected: &str| ShapeError {
            field: format!("tool `{s}`"),
            expected: expected.into(),
            value: s.to_string(),
        };
        let num = |k: usize, what: &str| -> Result<f64, ShapeError> {
            let t = parts.get(k).ok_or_else(|| bad(&format!("given with its {what}")))?;
            t.parse::<f64>()
                .map_err(|_| bad(&format!("a number for the {what}, not `{t}`,")))
        };
        let shape = match (parts[0].to_ascii_lowercase().as_str(), parts.len()) {
            ("ball", 2) => Shape::Ball {
                diameter_mm: num(1, "diameter (mm)")?,
            },
            ("flat", 2) => Shape::Flat {
                diameter_mm: num(1, "diameter (mm)")?,
            },
            ("bull", 3) => Shape::Bull {
                diameter_mm: num(1, "diameter (mm)")?,
                corner_radius_mm: num(2, "corner radius (mm)")?,
            },
            _ => return Err(bad("ball:D, flat:D or bull:D:R (mm)")),
        };
        shape.validate()?;
        Ok(shape)
    }

    /// Check the dimensions: a finite positive diameter (at most 1 m), a bull's corner radius in
    /// (0, diameter/2]. The error names the field.
    pub fn validate(&self) -> Result<(), ShapeError> {
        let d = self.diameter_mm();
        if !(d.is_finite() && d > 0.0 && d <= 1000.0) {
            return Err(ShapeError {
                field: "diameter_mm".into(),
                expected: "a positive number of mm, at most 1000".into(),
                value: d.to_string(),
            });
        }
        if let Shape::Bull {
            corner_radius_mm: rc, ..
        } = *self
        {
            if !(rc.is_finite() && rc > 0.0 && rc <= d / 2.0) {
                return Err(ShapeError {
                    field: "corner_radius_mm".into(),
                    expected: format!("in (0, diameter/2 = {}] for a bull-nose", d / 2.0),
                    value: rc.to_string(),
                });
            }
        }
        Ok(())
    }

    /// Diameter, mm.
    #[must_use]
    pub fn diameter_mm(&self) -> f64 {
        match *self {
            Shape::Ball { diameter_mm } | Shape::Flat { diameter_mm } | Shape::Bull { diameter_mm, .. } => diameter_mm,
        }
    }

    /// Radius, mm.
    #[must_use]
    pub fn radius_mm(&self) -> f64 {
        self.diameter_mm() / 2.0
    }

    /// The same geometry in its simplest form: a bull whose corner radius is the tool's radius is a ball.
    #[must_use]
    pub fn normalized(self) -> Shape {
        match self {
            Shape::Bull {
                diameter_mm,
                corner_radius_mm,
            } if corner_radius_mm >= diameter_mm / 2.0 => Shape::Ball { diameter_mm },
            s => s,
        }
    }

    /// The corner radius, mm: the radius for a ball, 0 for a flat.
    #[must_use]
    pub fn corner_radius_mm(&self) -> f64 {
        match *self {
            Shape::Ball { diameter_mm } => diameter_mm / 2.0,
            Shape::Flat { .. } => 0.0,
            Shape::Bull { corner_radius_mm, .. } => corner_radius_mm,
        }
    }

    /// `ball`, `flat` or `bull`.
    #[must_use]
    pub fn kind(&self) -> &'static str {
        match self {
            Shape::Ball { .. } => "ball",
            Shape::Flat { .. } => "flat",
            Shape::Bull { .. } => "bull",
        }
    }

    /// Height of the underside above the tip at horizontal distance `rho` (≤ radius), mm: `b(ρ)` above.
    #[inline]
    #[must_use]
    pub fn profile(&self, rho: f64) -> f64 {
        let r = self.radius_mm();
        match *self {
            Shape::Ball { .. } => r - (r * r - rho * rho).max(0.0).sqrt(),
            Shape::Flat { .. } => 0.0,
            Shape::Bull {
                corner_radius_mm: rc, ..
            } => {
                let s = rho - (r - rc);
                if s <= 0.0 {
                    0.0
                } else {
                    rc - (rc * rc - s * s).max(0.0).sqrt()
                }
            }
        }
    }

    /// `b(ρ)` from `ρ²` (≤ radius²), mm: the same as [`Shape::profile`] without a square root for the ball
    /// (the drop-cutter's inner loop).
    #[inline]
    #[must_use]
    pub fn profile_sq(&self, rho2: f64) -> f64 {
        match *self {
            Shape::Ball { diameter_mm } => {
                let r = diameter_mm / 2.0;
                r - (r * r - rho2).max(0.0).sqrt()
            }
            Shape::Flat { .. } => 0.0,
            Shape::Bull { .. } => self.profile(rho2.max(0.0).sqrt()),
        }
    }

    /// `db/dρ`, infinite at the rim of a ball or a bull's corner.
    #[inline]
    #[must_use]
    pub fn profile_slope(&self, rho: f64) -> f64 {
        let r = self.radius_mm();
        let (s, rc) = match *self {
            Shape::Ball { .. } => (rho, r),
            Shape::Flat { .. } => return 0.0,
            Shape::Bull {
                corner_radius_mm: rc, ..
            } => (rho - (r - rc), rc),
        };
        if s <= 0.0 {
            return 0.0;
        }
        let d = rc * rc - s * s;
        if d <= 0.0 {
            f64::INFINITY
        } else {
            s / d.sqrt()
        }
    }
}

impl fmt::Display for Shape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Shape::Ball { diameter_mm } => write!(f, "ball:{diameter_mm}"),
            Shape::Flat { diameter_mm } => write!(f, "flat:{diameter_mm}"),
            Shape::Bull {
                diameter_mm,
                corner_radius_mm,
            } => write!(f, "bull:{diameter_mm}:{corner_radius_mm}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_print_round_trip() {
        assert_eq!(Shape::parse("ball:1.0").unwrap(), Shape::Ball { diameter_mm: 1.0 });
        assert_eq!(Shape::parse("flat:3").unwrap(), Shape::Flat { diameter_mm: 3.0 });
        let b = Shape::parse("bull:6:0.5").unwrap();
        assert_eq!(
            b,
            Shape::Bull {
                diameter_mm: 6.0,
                corner_radius_mm: 0.5
            }
        );
        assert_eq!(Shape::parse(&b.to_string()).unwrap(), b);
        for bad in [
            "ball",
            "ball:x",
            "ball:-1",
            "bull:1:0.8",
            "bull:1:-1",
            "cone:1",
            "ball:1e9",
            "ball:NaN",
        ] {
            assert!(Shape::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn profiles_meet_their_closed_forms() {
        let ball = Shape::Ball { diameter_mm: 2.0 };
        // b(ρ) = R − √(R² − ρ²): at ρ = R·sin 30°, 1 − cos 30°
        let rho = 0.5;
        assert!((ball.profile(rho) - (1.0 - (30f64).to_radians().cos())).abs() < 1e-15);
        assert!((ball.profile_slope(rho) - (30f64).to_radians().tan()).abs() < 1e-15);
        let bull = Shape::Bull {
            diameter_mm: 2.0,
            corner_radius_mm: 0.5,
        };
        assert_eq!(bull.profile(0.4), 0.0);
        assert!(
            (bull.profile(1.0) - 0.5).abs() < 1e-15,
            "the corner ends a corner radius up"
        );
        assert_eq!(
            Shape::Bull {
                diameter_mm: 2.0,
                corner_radius_mm: 1.0
            }
            .normalized(),
            ball
        );
    }

    #[test]
    fn profile_fields_are_checked() {
        assert!(Shape::from_parts("ball", 1.0, Some(0.5)).is_ok());
        assert_eq!(
            Shape::from_parts("ball", 1.0, Some(-1.0)).unwrap_err().field,
            "corner_radius_mm"
        );
        assert_eq!(
            Shape::from_parts("bull", 1.0, None).unwrap_err().field,
            "corner_radius_mm"
        );
        assert_eq!(Shape::from_parts("flat", 1e9, None).unwrap_err().field, "diameter_mm");
        assert_eq!(Shape::from_parts("cone", 1.0, None).unwrap_err().field, "kind");
    }
}
