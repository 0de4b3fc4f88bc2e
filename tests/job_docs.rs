//! `docs/JOB.md` documents every key of the job format: the keys a job serialises to (every section, every
//! default filled in) must each have a row in its tables, and every row must name a key the format has.

use brdfmill::job::Job;
use std::collections::BTreeSet;
use std::path::Path;

fn keys(prefix: &str, v: &toml::Value, out: &mut BTreeSet<String>) {
    if let toml::Value::Table(t) = v {
        for (k, v) in t {
            let path = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            match v {
                toml::Value::Table(_) => keys(&path, v, out),
                // an array of tables (`[[svbrdf.region]]`): its keys under the array's name
                toml::Value::Array(a) if a.iter().all(|e| e.is_table()) && !a.is_empty() => {
                    for e in a {
                        keys(&path, e, out);
                    }
                }
                _ => {
                    out.insert(path);
                }
            }
        }
    }
}

#[test]
fn every_job_key_is_documented_and_every_documented_key_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut have = BTreeSet::new();
    // the default job, and the svBRDF example for `[svbrdf]` and its regions
    for job in ["examples/default.toml", "examples/svbrdf-logo.toml"] {
        let ready = Job::load(&root.join(job)).unwrap();
        let v = toml::Value::try_from(&ready.job).unwrap();
        keys("", &v, &mut have);
    }
    // the optional keys a job without them does not serialise
    have.insert("target.polish".to_string());
    have.insert("target.merl_from".to_string());
    for k in [
        "target.highlight",
        "target.highlight_extent_deg",
        "target.material",
        "target.surface",
        "target.surface_pitch_um",
        "target.surface_filter_um",
        "target.surface_method",
        "target.surface_wavelength_um",
        "target.surface_sigma_um",
        "svbrdf.region.highlight",
        "svbrdf.region.highlight_extent_deg",
        "svbrdf.region.material",
        "simulate.arc_tolerance_um",
    ] {
        have.insert(k.to_string());
    }
    let doc = std::fs::read_to_string(root.join("docs/JOB.md")).unwrap();
    let documented: BTreeSet<String> = doc
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split_once('`').map(|(k, _)| k.to_string()))
        .collect();
    let missing: Vec<_> = have.difference(&documented).collect();
    let unknown: Vec<_> = documented.difference(&have).collect();
    assert!(missing.is_empty(), "keys without a row in docs/JOB.md: {missing:?}");
    assert!(
        unknown.is_empty(),
        "rows in docs/JOB.md for keys the format does not have: {unknown:?}"
    );
}
