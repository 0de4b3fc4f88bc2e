//! Messages that name their source (issue 38): an error in a job says where the user put the mistake, the
//! `--set` option as typed or the file and its line, and names the keys the user set. Each case runs the binary
//! and is refused while the job loads, before any work.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn brdfmill(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `brdfmill run JOB --out OUT` with a `--set` for each of `sets`.
fn run_job(job: &Path, out: &Path, sets: &[&str]) -> Output {
    let mut args = vec!["run", job.to_str().unwrap(), "--out", out.to_str().unwrap()];
    for s in sets {
        args.extend(["--set", s]);
    }
    brdfmill(&args)
}

/// The run was refused (exit 1, nothing written); its message, from stderr.
fn refusal(o: &Output, out: &Path) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(
        o.status.code(),
        Some(1),
        "expected a refusal, got {:?}: {err}",
        o.status
    );
    assert!(!out.exists(), "a refusal made {}", out.display());
    err
}

/// `examples/default.toml` with `edits` (old text → new text) applied, written to `dir/job.toml` with the
/// machine profile's path made absolute.
fn job_with(dir: &Path, edits: &[(&str, &str)]) -> (PathBuf, String) {
    let mut text = std::fs::read_to_string(root().join("examples/default.toml")).unwrap();
    for (a, b) in edits {
        assert!(text.contains(a), "{a}");
        text = text.replacen(a, b, 1);
    }
    let text = text.replace("../machines/", &format!("{}/machines/", root().display()));
    let p = dir.join("job.toml");
    std::fs::write(&p, &text).unwrap();
    (p, text)
}

/// The 1-based line of `text` that contains `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).expect(needle) + 1
}

/// A typo in `--set` is the option's, not the job file's: the message starts with the option as typed and
/// names the bad key and the valid ones. The same typo in the file names the file and its line.
#[test]
fn a_typo_is_reported_where_the_user_typed_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (job, _) = job_with(dir.path(), &[]);
    let typed = "toolpath.scalop_um=1";
    let o = run_job(&job, &out, &["facets.seed=2", typed]);
    let err = refusal(&o, &out);
    assert!(err.starts_with(&format!("error: --set {typed}: ")), "{err}");
    assert!(!err.contains("job.toml"), "the job file is not at fault: {err}");
    assert!(err.contains("unknown field `scalop_um`"), "{err}");
    assert!(
        err.contains("`scallop_um`") && err.contains("`feed_mm_min`"),
        "the valid keys: {err}"
    );
    assert!(err.contains("in `toolpath`"), "{err}");

    // a wrong value is the option's too, with its key
    let typed = "toolpath.scallop_um=abc";
    let o = run_job(&job, &out, &[typed]);
    let err = refusal(&o, &out);
    assert!(err.starts_with(&format!("error: --set {typed}: ")), "{err}");
    assert!(err.contains("`toolpath.scallop_um`"), "{err}");

    // the typo in the file: the file and the line, even with an unrelated override
    let (job, text) = job_with(dir.path(), &[("scallop_um = 1.0", "scalop_um = 1.0")]);
    let line = line_of(&text, "scalop_um");
    for sets in [&[][..], &["facets.seed=2"][..]] {
        let err = refusal(&run_job(&job, &out, sets), &out);
        assert!(
            err.starts_with(&format!("error: {}: ", job.display())),
            "{sets:?}: {err}"
        );
        assert!(err.contains(&format!("line {line}")), "{sets:?}: line {line} in {err}");
        assert!(
            err.contains("unknown field `scalop_um`") && err.contains("`scallop_um`"),
            "{err}"
        );
        assert!(!err.contains("--set"), "{sets:?}: no override is at fault: {err}");
    }

    // an override may give what the file leaves out; a typo in another is still that option's, whichever
    // comes first
    let (job, text) = job_with(dir.path(), &[]);
    let profile = line_of(&text, "profile = ");
    let text: String = text
        .lines()
        .enumerate()
        .filter(|(k, _)| k + 1 != profile)
        .map(|(_, l)| format!("{l}\n"))
        .collect();
    std::fs::write(&job, text).unwrap();
    let given = format!(
        "machine.profile=\"{}\"",
        root().join("machines/grbl-3018.toml").display()
    );
    let typed = "toolpath.stok=\"aluminium\"";
    for sets in [[given.as_str(), typed], [typed, given.as_str()]] {
        let o = run_job(&job, &out, &sets);
        let err = refusal(&o, &out);
        assert!(err.starts_with(&format!("error: --set {typed}: ")), "{sets:?}: {err}");
        assert!(err.contains("unknown field `stok`"), "{err}");
    }
}

/// A limit that several keys reach together names every one of them and the values they have, wherever the
/// user set them: 12×12 facets of 1000 mm at 5 µm are 144 × 200 000² = 5.76e12 samples.
#[test]
fn a_derived_limit_names_the_keys_that_drive_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let keys = [
        "`facets.facets_x`",
        "`facets.facets_y`",
        "`facets.facet_mm`",
        "`facets.pitch_um`",
    ];
    let what = "12×12 facets of 1000 mm at 5 µm pitch";
    let samples = "heightfield of 5.760e12 samples (limit 4e8)";

    let (job, _) = job_with(dir.path(), &[]);
    let typed = "facets.facet_mm=1000";
    let o = run_job(&job, &out, &[typed]);
    let err = refusal(&o, &out);
    for want in keys.iter().chain(&[what, samples]) {
        assert!(err.contains(want), "missing {want} in {err}");
    }
    assert!(
        err.contains(&format!("`facets.facet_mm` from `--set {typed}`")),
        "{err}"
    );

    let (job, _) = job_with(dir.path(), &[("facet_mm = 1.0", "facet_mm = 1000.0")]);
    let o = run_job(&job, &out, &[]);
    let err = refusal(&o, &out);
    assert!(err.starts_with(&format!("error: {}: ", job.display())), "{err}");
    for want in keys.iter().chain(&[what, samples]) {
        assert!(err.contains(want), "missing {want} in {err}");
    }
    assert!(!err.contains("--set"), "{err}");

    // the annealing's work: sweeps × facets, each named with its section
    let (job, _) = job_with(
        dir.path(),
        &[("seed = 1", "seed = 1\n[facets.anneal]\nsweeps = 1000000000")],
    );
    let o = run_job(&job, &out, &[]);
    let err = refusal(&o, &out);
    for want in [
        "`facets.anneal.sweeps`",
        "`facets.facets_x`",
        "`facets.facets_y`",
        "1000000000 sweeps of 144 facets",
    ] {
        assert!(err.contains(want), "missing {want} in {err}");
    }
}

/// A misspelt key in a machine profile is reported at its key: the profile's path (found relative to the job
/// file, not to where brdfmill runs), its line, the bad key and the keys a tool has.
#[test]
fn a_typo_in_a_machine_profile_names_the_profile_and_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let shipped = std::fs::read_to_string(root().join("machines/grbl-3018.toml")).unwrap();
    // the last tool's flute length, misspelt
    let at = shipped.rfind("flute_length_mm").unwrap();
    let profile = format!(
        "{}flute_lenght_mm{}",
        &shipped[..at],
        &shipped[at + "flute_length_mm".len()..]
    );
    let line = shipped[..at].lines().count() + 1;
    assert_eq!(line_of(&profile, "flute_lenght_mm"), line);
    std::fs::create_dir(dir.path().join("profiles")).unwrap();
    let profile_path = dir.path().join("profiles/my-3018.toml");
    std::fs::write(&profile_path, &profile).unwrap();
    let (job, _) = job_with(
        dir.path(),
        &[(
            "profile = \"../machines/grbl-3018.toml\"",
            "profile = \"profiles/my-3018.toml\"",
        )],
    );
    assert_ne!(std::env::current_dir().unwrap(), dir.path());
    let o = run_job(&job, &out, &[]);
    let err = refusal(&o, &out);
    assert!(
        err.starts_with(&format!("error: {}: `machine.profile`: ", job.display())),
        "{err}"
    );
    assert!(err.contains(&profile_path.display().to_string()), "{err}");
    assert!(err.contains(&format!("line {line}")), "line {line}: {err}");
    assert!(err.contains("unknown field `flute_lenght_mm`"), "{err}");
    for key in ["`flute_length_mm`", "`diameter_mm`", "`corner_radius_mm`"] {
        assert!(err.contains(key), "the valid key {key}: {err}");
    }
}

/// Run `job` with `sets` until the NDF (a fraction of a second at `ndf.res=32`): the name it prints and the
/// one `run.json` keeps.
fn name_of(job: &Path, sets: &[&str], out: &Path) -> (String, String) {
    let mut args = vec![
        "run",
        job.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--until",
        "ndf",
    ];
    for s in sets.iter().chain(&["ndf.res=32"]) {
        args.extend(["--set", s]);
    }
    let o = brdfmill(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let printed = stdout
        .lines()
        .find_map(|l| l.strip_prefix("job       "))
        .and_then(|l| l.strip_suffix(&format!(" ({})", job.display())))
        .unwrap_or_else(|| panic!("no job line in {stdout}"))
        .to_string();
    let run: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    (printed, run["job"].as_str().unwrap().to_string())
}

/// A job that gives no name is named after its target as written, and a `--set` of the target renames it;
/// a name the file gives stays.
#[test]
fn the_name_follows_the_target_unless_the_file_gives_one() {
    let dir = tempfile::tempdir().unwrap();
    let (job, text) = job_with(dir.path(), &[]);
    assert!(
        !text.contains("\nname"),
        "examples/default.toml names itself after its target"
    );
    let words = "isotropic Beckmann α = 0.2, aluminium";
    assert!(text.contains("brdf = \"beckmann:alpha=0.2,material=aluminium\""));
    let n = name_of(&job, &[], &dir.path().join("a"));
    assert_eq!(n, (words.to_string(), words.to_string()));

    let n = name_of(
        &job,
        &["target.brdf=ggx:alpha=0.8,material=aluminium"],
        &dir.path().join("b"),
    );
    let words = "isotropic GGX α = 0.8, aluminium";
    assert_eq!(n, (words.to_string(), words.to_string()));

    let (job, _) = job_with(dir.path(), &[("version = 1\n", "version = 1\nname = \"coupon 7\"\n")]);
    let n = name_of(
        &job,
        &["target.brdf=ggx:alpha=0.8,material=aluminium"],
        &dir.path().join("c"),
    );
    assert_eq!(n, ("coupon 7".to_string(), "coupon 7".to_string()));
    let n = name_of(&job, &["name=\"coupon 8\""], &dir.path().join("d"));
    assert_eq!(n, ("coupon 8".to_string(), "coupon 8".to_string()));
}
