//! The job's targets: its one target (`[target]`) or each region's (`[[svbrdf.region]]`), their specs read and
//! checked when the job loads; the label image of a spatially varying target; and the MERL file a job may ask
//! to be written from a model (`target.merl_from`), which the run writes, never the loading.

use super::{resolve_spec, Job, TargetSection};
use crate::base::Invalid;
use crate::stages::brdf::{Brdf, Merl, Model};
use crate::stages::svbrdf::{Labels, SvbrdfSection};
use std::path::{Path, PathBuf};

/// One target of a job, ready to run: the job's own (named `""`, files `ndf.json`, `tile.*`) or a region's
/// (files `ndf-NAME.json`, `tile-NAME.*`).
#[derive(Clone, Debug)]
pub struct RegionTarget {
    /// Its name (empty for a job's single target).
    pub name: String,
    /// Its label colour (regions only).
    pub color: [u8; 3],
    /// The target spec as resolved.
    pub spec: String,
    /// The target.
    pub target: Brdf,
}

impl RegionTarget {
    /// The suffix of its files: `""` for a single target, `-NAME` for a region.
    #[must_use]
    pub fn suffix(&self) -> String {
        if self.name.is_empty() {
            String::new()
        } else {
            format!("-{}", self.name)
        }
    }
}

/// `target.merl_from` for a `merl:` file that does not exist beside the job: the run writes it from `source`
/// into its output folder (generated data never goes into the job's folder, which may be the source tree)
/// before the NDF stage, and reads the target back from it.
#[derive(Clone, Debug)]
pub struct MerlFrom {
    /// The file `target.brdf` names (resolved against the job's folder); only its name is used.
    pub path: PathBuf,
    /// The spec it is written from.
    pub from: String,
    /// That spec's model.
    pub source: Brdf,
}

impl MerlFrom {
    /// Write the file into `out` under its name, and read it back as the target (with the spec's `material=`
    /// and other options): the target, its spec naming the written file, the file and what was done.
    pub fn write(&self, out: &Path, spec: &str) -> Result<(Brdf, String, PathBuf, String), Invalid> {
        let name = self
            .path
            .file_name()
            .ok_or_else(|| Invalid(format!("`target.brdf`: `{}` names no file", self.path.display())))?;
        let file = out.join(name);
        Merl::from_fn(|wi, wo| self.source.eval(wi, wo))
            .write(&file)
            .map_err(|e| Invalid(e.to_string()))?;
        let spec = spec.replacen(&self.path.display().to_string(), &file.display().to_string(), 1);
        let target = Brdf::parse(&spec).map_err(|e| Invalid(format!("`target.brdf`: {e}")))?;
        let said = format!(
            "wrote {} from `{}` (`target.merl_from`; {} does not exist)",
            file.display(),
            self.from,
            self.path.display()
        );
        Ok((target, spec, file, said))
    }
}

/// The job's single target, and the MERL file the run must write first when `target.merl_from` asks for one
/// that does not exist (the target is then the model it is written from until the run has read the file).
pub(super) fn single_target(t: &TargetSection, dir: &Path) -> Result<(RegionTarget, Option<MerlFrom>), String> {
    if let Some(scan) = &t.surface {
        return super::scan_target::single(t, scan, dir).map(|target| (target, None));
    }
    super::scan_target::no_surface_keys(t)?;
    let (key, spec) = target_spec(
        "target",
        (&t.brdf, &t.highlight, t.highlight_extent_deg, &t.material),
        dir,
    )?;
    let merl = match &t.merl_from {
        None => None,
        Some(from) => {
            let Some(rest) = spec.strip_prefix("merl:") else {
                return Err(format!(
                    "`target.merl_from`: only a `merl:` target can be written from a spec; `target.brdf` is `{}`",
                    t.brdf
                ));
            };
            let path = PathBuf::from(rest.split(',').next().unwrap_or(rest).trim());
            let source = Brdf::parse(from).map_err(|e| format!("`target.merl_from`: {e}"))?;
            if matches!(source.model, Model::Merl(_)) {
                return Err(format!(
                    "`target.merl_from`: `{from}` is itself a MERL file: name an analytic or measured model"
                ));
            }
            (!path.exists()).then(|| MerlFrom {
                path,
                from: from.clone(),
                source,
            })
        }
    };
    let target = match &merl {
        Some(m) => m.source.clone(),
        None => Brdf::parse(&spec).map_err(|e| format!("`{key}`: {e}"))?,
    };
    let single = RegionTarget {
        name: String::new(),
        color: [0; 3],
        spec,
        target,
    };
    Ok((single, merl))
}

/// The fields that name a target: a BRDF spec, or a highlight with its extent and material.
type TargetFields<'a> = (&'a String, &'a Option<String>, Option<f64>, &'a Option<String>);

/// A target's BRDF spec, from `SECTION.brdf` or from `SECTION.highlight` (with its extent and material), and
/// the key it came from. Exactly one of the two must be given; the highlight's keys only go with it.
fn target_spec(
    section: &str,
    (brdf, highlight, extent, material): TargetFields,
    dir: &Path,
) -> Result<(String, String), String> {
    match (highlight, brdf.trim().is_empty()) {
        (Some(_), false) => Err(format!("give `{section}.brdf` or `{section}.highlight`, not both")),
        (None, true) => Err(format!(
            "missing `{section}.brdf` (a BRDF spec), `{section}.highlight` (a PNG) or `{section}.surface` (a scan)"
        )),
        (None, false) => {
            for (key, given) in [
                ("highlight_extent_deg", extent.is_some()),
                ("material", material.is_some()),
            ] {
                if given {
                    return Err(format!(
                        "`{section}.{key}` goes with `{section}.highlight`; with `{section}.brdf` give the material in the spec (`…,material=NAME`)"
                    ));
                }
            }
            Ok((format!("{section}.brdf"), resolve_spec(brdf, dir)))
        }
        (Some(path), true) => {
            let spec = crate::stages::brdf::highlight::spec(path, extent, material.as_deref())
                .map_err(|e| format!("`{section}.highlight`: {e}"))?;
            Ok((format!("{section}.highlight"), resolve_spec(&spec, dir)))
        }
    }
}

/// `[[svbrdf.region]]` → each region's target, with names and colours checked (valid, distinct). With
/// regions, `[target]` gives no target of its own (only `base` and `polish`).
pub(super) fn region_targets(t: &TargetSection, sv: &SvbrdfSection, dir: &Path) -> Result<Vec<RegionTarget>, String> {
    if !t.brdf.trim().is_empty()
        || t.highlight.is_some()
        || t.surface.is_some()
        || t.material.is_some()
        || t.highlight_extent_deg.is_some()
    {
        return Err(
            "with `[svbrdf]` each `[[svbrdf.region]]` names its own target: leave `target.brdf`, `target.highlight`, `target.surface` and their keys out (`[target]` keeps `base` and `polish`)".into(),
        );
    }
    if t.merl_from.is_some() {
        return Err("`target.merl_from` does not go with `[svbrdf]`".into());
    }
    if sv.region.len() < 2 {
        return Err(format!(
            "`[svbrdf]` needs at least two `[[svbrdf.region]]` (got {}); a single target goes in `[target]`",
            sv.region.len()
        ));
    }
    if sv.region.len() > crate::stages::svbrdf::MAX_REGIONS {
        return Err(format!(
            "`[svbrdf]` has {} regions; at most {}",
            sv.region.len(),
            crate::stages::svbrdf::MAX_REGIONS
        ));
    }
    let mut out: Vec<RegionTarget> = vec![];
    for (k, r) in sv.region.iter().enumerate() {
        let section = format!("svbrdf.region[{}]", k + 1);
        crate::stages::svbrdf::check_name(&r.name).map_err(|e| format!("`{section}.name`: {e}"))?;
        let color = crate::stages::svbrdf::parse_color(&r.color).map_err(|e| format!("`{section}.color`: {e}"))?;
        if let Some(o) = out.iter().find(|o| o.name == r.name) {
            return Err(format!("`{section}.name`: `{}` is already a region's name", o.name));
        }
        if let Some(o) = out.iter().find(|o| o.color == color) {
            return Err(format!(
                "`{section}.color`: {} is already region `{}`'s colour",
                crate::stages::svbrdf::hex(color),
                o.name
            ));
        }
        let (key, spec) = target_spec(
            &section,
            (&r.brdf, &r.highlight, r.highlight_extent_deg, &r.material),
            dir,
        )?;
        let target = Brdf::parse(&spec).map_err(|e| format!("`{key}`: {e}"))?;
        out.push(RegionTarget {
            name: r.name.clone(),
            color,
            spec,
            target,
        });
    }
    Ok(out)
}

/// Read the label image of `[svbrdf]` against its regions and the work area, and refuse a region too small
/// to hold one tile period.
pub(super) fn read_labels(
    job: &Job,
    sv: &SvbrdfSection,
    regions: &[RegionTarget],
    dir: &Path,
) -> Result<Labels, String> {
    let f = &job.facets;
    let [ax, ay] = job.toolpath.area_mm;
    let pitch_mm = f.pitch_um * 1e-3;
    let cells = (ax / pitch_mm).round() * (ay / pitch_mm).round();
    if cells > crate::stages::svbrdf::MAX_PART_CELLS as f64 {
        return Err(format!(
            "`[svbrdf]`: the composed part would be {cells:.0} cells (`toolpath.area_mm` = [{ax}, {ay}] at `facets.pitch_um` = {}); at most {}",
            f.pitch_um,
            crate::stages::svbrdf::MAX_PART_CELLS
        ));
    }
    let path = dir.join(&sv.labels);
    let names: Vec<String> = regions.iter().map(|r| r.name.clone()).collect();
    let colors: Vec<[u8; 3]> = regions.iter().map(|r| r.color).collect();
    let labels =
        Labels::read(&path, &names, &colors, job.toolpath.area_mm).map_err(|e| format!("`svbrdf.labels`: {e}"))?;
    labels
        .check_period([f.facets_x as f64 * f.facet_mm, f.facets_y as f64 * f.facet_mm])
        .map_err(|e| format!("`svbrdf.region`: {e}"))?;
    Ok(labels)
}

/// The name of a job that gives none: its target in words (`isotropic Beckmann α = 0.2, aluminium`, from the
/// spec as the user wrote it), or with `[svbrdf]` its regions' names; at most 60 characters and no control
/// characters, as a name must be (it is written into the program's header).
pub(super) fn derived_name(t: &TargetSection, sv: Option<&SvbrdfSection>) -> String {
    let words = match (sv, &t.highlight) {
        (Some(sv), _) => format!(
            "svBRDF: {}",
            sv.region.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ")
        ),
        (None, Some(png)) => {
            let mut w = format!("drawn highlight {}", file_name(png));
            if let Some(m) = &t.material {
                w += &format!(", {}", m.trim());
            }
            w
        }
        (None, None) => describe_spec(&t.brdf),
    };
    let clean: String = words.chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
    if clean.chars().count() <= 60 {
        clean
    } else {
        clean.chars().take(59).chain(['…']).collect()
    }
}

/// A BRDF spec in words: `beckmann:alpha=0.2,material=aluminium` → `isotropic Beckmann α = 0.2, aluminium`,
/// `ward:ax=0.08,ay=0.25` → `anisotropic Ward (αx 0.08, αy 0.25)`, `merl:data/gold.binary` → `MERL
/// gold.binary`; the numbers as written. A spec it cannot read is given as it is (loading refuses it).
fn describe_spec(spec: &str) -> String {
    let Some((kind, rest)) = spec.trim().split_once(':') else {
        return spec.trim().to_string();
    };
    let kind = kind.trim().to_ascii_lowercase();
    let mut tokens: Vec<&str> = rest.split(',').map(str::trim).collect();
    let file = match kind.as_str() {
        "merl" | "rgl" | "csv" | "highlight" | "surface" => file_name(tokens.remove(0)),
        _ => String::new(),
    };
    let params: Vec<(String, &str)> = tokens
        .iter()
        .filter_map(|t| t.split_once('='))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim()))
        .collect();
    let get = |key: &str| params.iter().find(|(k, _)| k == key).map(|(_, v)| *v);
    let family = match kind.as_str() {
        "beckmann" => "Beckmann",
        "ggx" => "GGX",
        "ward" => "Ward",
        _ => "",
    };
    let model = match kind.as_str() {
        "beckmann" | "ggx" | "ward" => match (get("alpha"), get("ax"), get("ay")) {
            (Some(a), _, _) => format!("isotropic {family} α = {a}"),
            (None, Some(x), Some(y)) => format!("anisotropic {family} (αx {x}, αy {y})"),
            _ => family.to_string(),
        },
        "blinn" => format!("Blinn–Phong n = {}", get("n").unwrap_or("?")),
        "merl" => format!("MERL {file}"),
        "rgl" => format!("RGL {file}"),
        "csv" => format!("tabulated NDF {file}"),
        "highlight" => format!("drawn highlight {file}"),
        "surface" => format!("measured surface {file}"),
        _ => return spec.trim().to_string(),
    };
    match (get("material"), get("eta"), get("k")) {
        (Some(m), _, _) => format!("{model}, {m}"),
        (None, Some(eta), Some(k)) => format!("{model}, conductor η {eta}, k {k}"),
        _ => model,
    }
}

/// The last part of a path as written.
fn file_name(path: &str) -> String {
    let path = path.trim();
    Path::new(path)
        .file_name()
        .map_or_else(|| path.to_string(), |n| n.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each spec form in words, with the numbers and names exactly as written in the spec.
    #[test]
    fn a_spec_reads_as_words() {
        for (spec, words) in [
            (
                "beckmann:alpha=0.2,material=aluminium",
                "isotropic Beckmann α = 0.2, aluminium",
            ),
            (
                "GGX: alpha = 0.8 , material = aluminium",
                "isotropic GGX α = 0.8, aluminium",
            ),
            ("ward:ax=0.08,ay=0.25", "anisotropic Ward (αx 0.08, αy 0.25)"),
            (
                "ggx:ax=0.1,ay=0.3,eta=1.35,k=7.47",
                "anisotropic GGX (αx 0.1, αy 0.3), conductor η 1.35, k 7.47",
            ),
            ("blinn:n=200", "Blinn–Phong n = 200"),
            ("merl:data/gold.binary,material=gold", "MERL gold.binary, gold"),
            ("rgl:../rgl/vinyl.bsdf", "RGL vinyl.bsdf"),
            ("csv:ndf.csv", "tabulated NDF ndf.csv"),
            ("highlight:ring.png,extent_deg=20", "drawn highlight ring.png"),
            ("phong:n=3", "phong:n=3"),
        ] {
            assert_eq!(describe_spec(spec), words, "{spec}");
        }
    }

    /// The job's name, and the program header's, follow a `--set` of the target when the file gives no name,
    /// and stay what the file says when it gives one.
    #[test]
    fn a_derived_name_follows_the_target_and_a_given_one_stays() {
        let default = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/examples/default.toml"));
        let set = ["target.brdf=ggx:alpha=0.8,material=aluminium".to_string()];
        let ready = Job::load_with(default, &set).unwrap();
        assert_eq!(ready.job.name, "isotropic GGX α = 0.8, aluminium");
        assert_eq!(ready.toolpath.cfg.job, ready.job.name, "the program's header");
        let dir = tempfile::tempdir().unwrap();
        let text = std::fs::read_to_string(default)
            .unwrap()
            .replace("version = 1\n", "version = 1\nname = \"sample A\"\n")
            .replace("../machines/grbl-3018.toml", "grbl-3018");
        let named = dir.path().join("job.toml");
        std::fs::write(&named, text).unwrap();
        let ready = Job::load_with(&named, &set).unwrap();
        assert_eq!(ready.job.name, "sample A");
        assert_eq!(ready.toolpath.cfg.job, "sample A");
    }

    /// A derived name is what a job's `name` may be: no control characters, at most 60 characters.
    #[test]
    fn a_derived_name_is_a_valid_name() {
        let t = TargetSection {
            brdf: format!("merl:{}\n.binary,material=gold", "x".repeat(80)),
            ..Default::default()
        };
        let name = derived_name(&t, None);
        assert!(crate::cut::machine::program_text("name", &name).is_ok(), "{name}");
        assert!(name.starts_with("MERL xxx") && name.ends_with('…'), "{name}");
        let t = TargetSection {
            highlight: Some("drawings/star.png".into()),
            material: Some("aluminium".into()),
            ..Default::default()
        };
        assert_eq!(derived_name(&t, None), "drawn highlight star.png, aluminium");
    }
}
