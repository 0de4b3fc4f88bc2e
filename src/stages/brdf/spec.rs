//! Parsing of BRDF spec strings (`ggx:ax=0.1,ay=0.3,material=gold`, `merl:PATH`, …).

use super::{BlinnPhong, Brdf, BrdfError, ConductorIor, Family, Microfacet, Model, Ward, PRESETS};
use std::collections::BTreeMap;
use std::path::Path;

fn err(spec: &str, reason: impl Into<String>) -> BrdfError {
    BrdfError::Spec {
        spec: spec.to_string(),
        reason: reason.into(),
    }
}

const KINDS: &str = "beckmann, ggx, ward, blinn, merl, rgl, csv, highlight, surface";

/// The default `extent_deg` of a `highlight:` spec: the angle of reflection at the middle of the image's
/// longer axis (the middles of its shorter edges), degrees.
pub const DEFAULT_EXTENT_DEG: f64 = 30.0;

/// Parse `kind:key=value,…` (analytic) or `kind:PATH,key=value,…` (measured).
pub(super) fn parse(spec: &str) -> Result<Brdf, BrdfError> {
    let spec_t = spec.trim();
    let (kind, rest) = spec_t
        .split_once(':')
        .ok_or_else(|| err(spec, format!("expected KIND:PARAMS with KIND one of {KINDS}")))?;
    let kind = kind.trim().to_ascii_lowercase();
    let mut tokens: Vec<&str> = rest.split(',').map(str::trim).collect();
    let path = match kind.as_str() {
        "merl" | "rgl" | "csv" | "highlight" | "surface" => {
            let p = tokens.remove(0);
            if p.is_empty() {
                return Err(err(spec, format!("`{kind}:` needs a file path")));
            }
            Some(p)
        }
        _ => None,
    };
    let mut params: BTreeMap<String, f64> = BTreeMap::new();
    let mut material_name: Option<String> = None;
    for t in tokens.iter().filter(|t| !t.is_empty()) {
        let (k, v) = t
            .split_once('=')
            .ok_or_else(|| err(spec, format!("`{t}` is not of the form key=value")))?;
        let k = k.trim().to_ascii_lowercase();
        if k == "material" {
            material_name = Some(v.trim().to_string());
            continue;
        }
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| err(spec, format!("`{k}` = `{v}` is not a number")))?;
        if !x.is_finite() {
            return Err(err(spec, format!("`{k}` = `{v}` must be finite")));
        }
        if params.insert(k.clone(), x).is_some() {
            return Err(err(spec, format!("`{k}` is given twice")));
        }
    }
    let material = take_material(spec, &mut params, material_name)?;
    let positive = |params: &mut BTreeMap<String, f64>, key: &str| -> Result<Option<f64>, BrdfError> {
        match params.remove(key) {
            Some(v) if v > 0.0 => Ok(Some(v)),
            Some(v) => Err(err(spec, format!("`{key}` must be > 0, got {v}"))),
            None => Ok(None),
        }
    };
    let model = match kind.as_str() {
        "beckmann" | "ggx" | "ward" => {
            let shape = if kind == "ggx" { Family::Ggx } else { Family::Beckmann };
            let alpha = positive(&mut params, "alpha")?;
            let ax = positive(&mut params, "ax")?;
            let ay = positive(&mut params, "ay")?;
            let (ax, ay) = match (alpha, ax, ay) {
                (Some(a), None, None) => (a, a),
                (None, Some(x), Some(y)) => (x, y),
                _ => return Err(err(spec, "give either alpha=A, or both ax=A and ay=B (each > 0)")),
            };
            if kind == "ward" {
                Model::Ward(Ward {
                    alpha_x: ax,
                    alpha_y: ay,
                })
            } else {
                Model::Microfacet(Microfacet::new(shape, ax, ay).expect("validated above"))
            }
        }
        "blinn" => {
            let n = positive(&mut params, "n")?.ok_or_else(|| err(spec, "blinn needs n=EXPONENT (> 0)"))?;
            Model::BlinnPhong(BlinnPhong { exponent: n })
        }
        "merl" => Model::Merl(Box::new(super::Merl::read(Path::new(path.unwrap()))?)),
        "rgl" => Model::Rgl(Box::new(super::RglBsdf::read(Path::new(path.unwrap()))?)),
        "csv" => Model::Tabulated(Box::new(super::TabulatedNdf::read(Path::new(path.unwrap()))?)),
        "highlight" => {
            let extent = positive(&mut params, "extent_deg")?.unwrap_or(DEFAULT_EXTENT_DEG);
            Model::Highlight(Box::new(super::Highlight::read(Path::new(path.unwrap()), extent)?))
        }
        "surface" => {
            let filter = match params.remove("filter_um") {
                Some(v) if v >= 0.0 => v,
                Some(v) => return Err(err(spec, format!("`filter_um` must be >= 0, got {v}"))),
                None => 0.0,
            };
            let pitch = positive(&mut params, "pitch_um")?;
            Model::Surface(Box::new(super::SurfaceNdf::read(
                Path::new(path.unwrap()),
                pitch,
                filter,
            )?))
        }
        other => return Err(err(spec, format!("unknown model `{other}`; expected one of {KINDS}"))),
    };
    if let Some(k) = params.keys().next() {
        return Err(err(spec, format!("unknown parameter `{k}` for `{kind}`")));
    }
    Ok(Brdf {
        model,
        material,
        spec: spec_t.to_string(),
    })
}

fn take_material(
    spec: &str,
    params: &mut BTreeMap<String, f64>,
    name: Option<String>,
) -> Result<Option<ConductorIor>, BrdfError> {
    let eta = params.remove("eta");
    let k = params.remove("k");
    match (name, eta, k) {
        (None, None, None) => Ok(None),
        (Some(n), None, None) => ConductorIor::preset(&n).map(Some).ok_or_else(|| {
            let names: Vec<_> = PRESETS.iter().map(|m| m.name).collect();
            err(spec, format!("unknown material `{n}`; known: {}", names.join(", ")))
        }),
        (None, Some(e), Some(k)) if e > 0.0 && k >= 0.0 => Ok(Some(ConductorIor::grey(e, k))),
        (None, Some(_), Some(_)) => Err(err(spec, "need eta > 0 and k >= 0")),
        (Some(_), _, _) => Err(err(spec, "give material=NAME or eta=E,k=K, not both")),
        _ => Err(err(spec, "give both eta=E and k=K")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_analytic_form() {
        for s in [
            "beckmann:alpha=0.3",
            "ggx:alpha=0.2",
            "ggx:ax=0.1,ay=0.3",
            "ward:ax=0.1,ay=0.3",
            "blinn:n=200",
            "GGX: alpha = 0.2 , material = Gold",
            "beckmann:alpha=0.3,eta=1.35,k=7.47",
        ] {
            Brdf::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
        }
    }

    #[test]
    fn material_sets_fresnel() {
        let b = Brdf::parse("ggx:alpha=0.2,eta=1.35,k=7.47").unwrap();
        assert_eq!(b.material, Some(ConductorIor::grey(1.35, 7.47)));
        assert!(Brdf::parse("ggx:alpha=0.2").unwrap().material.is_none());
    }

    #[test]
    fn bad_specs_are_refused_with_the_reason() {
        for (s, needle) in [
            ("beckmann:alpha=0", "must be > 0"),
            ("beckmann:alpha=-1", "must be > 0"),
            ("ggx:alpha=abc", "not a number"),
            ("ggx:alpha=NaN", "finite"),
            ("ggx:ax=0.1", "both ax"),
            ("ggx:alpha=0.1,ax=0.2,ay=0.3", "either alpha"),
            ("phong:n=3", "unknown model"),
            ("ggx", "KIND:PARAMS"),
            ("ggx:alpha=0.1,beta=2", "unknown parameter `beta`"),
            ("ggx:alpha=0.1,material=unobtainium", "unknown material"),
            ("ggx:alpha=0.1,eta=1.3", "both eta"),
            ("ggx:alpha=0.1,alpha=0.2", "twice"),
            ("blinn:", "needs n"),
            ("merl:", "needs a file path"),
        ] {
            let e = Brdf::parse(s).expect_err(s).to_string();
            assert!(e.contains(needle), "{s}: `{e}` should mention `{needle}`");
            assert!(e.contains(s.trim()), "{s}: `{e}` should name the spec");
        }
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = Brdf::parse("merl:/nonexistent/file.binary").unwrap_err().to_string();
        assert!(e.contains("/nonexistent/file.binary"), "{e}");
    }
}
