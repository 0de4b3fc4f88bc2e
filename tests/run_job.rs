//! `brdfmill run` end to end on the default job (issue "Closing the loop"): every artifact, the metrics
//! contract, the report rendered by a real browser, and job files refused before any work.

use brdfmill::job::Job;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn brdfmill(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(args)
        .output()
        .expect("run brdfmill")
}

/// Chromium, when installed (CI installs it and sets BRDFMILL_REQUIRE_EXTERNAL=1, making it mandatory).
fn chromium() -> Option<&'static str> {
    for c in ["chromium", "chromium-browser", "google-chrome"] {
        if Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
        {
            return Some(c);
        }
    }
    if std::env::var("BRDFMILL_REQUIRE_EXTERNAL").is_ok() {
        panic!("chromium is required here but not installed (Debian package chromium)");
    }
    eprintln!("note: chromium not installed; the report was not rendered in a browser");
    None
}

/// Pixels that only the report's images contain: viridis' dark purple end and the rendered spheres' greys
/// are not used by the page's text, tables or backgrounds.
fn image_pixels(png_bytes: &[u8]) -> usize {
    let dec = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    buf[..info.buffer_size()]
        .chunks(ch)
        .filter(|p| {
            let (r, g, b) = (p[0] as i32, p[1] as i32, p[2] as i32);
            // viridis dark purple (68, 1, 84) ± a little
            (r - 68).abs() < 20 && g < 40 && (b - 84).abs() < 25
        })
        .count()
}

#[test]
fn default_job_produces_every_artifact_and_a_rendered_report() {
    let out = tempfile::tempdir().unwrap();
    let job = root().join("examples/default.toml");
    let t = std::time::Instant::now();
    let o = brdfmill(&["run", job.to_str().unwrap(), "--out", out.path().to_str().unwrap()]);
    let secs = t.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    println!("{stdout}\nwall {secs:.1} s");
    for f in [
        "ndf.json",
        "ndf.png",
        "tile.json",
        "tile.npy",
        "tile.png",
        "tile.stl",
        "program.nc",
        "program.json",
        "sim.npy",
        "sim.png",
        "deviation.png",
        "sim.json",
        "wave.png",
        "metrics.json",
        "report.html",
    ] {
        let p = out.path().join(f);
        assert!(p.exists() && std::fs::metadata(&p).unwrap().len() > 0, "{f} missing");
    }
    assert!(
        stdout.contains("report") && stdout.contains("report.html"),
        "closing summary names the report"
    );
    // the metrics contract
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.path().join("metrics.json")).unwrap()).unwrap();
    for side in ["design", "milled"] {
        for key in ["ndf_l1", "ndf_corr"] {
            assert!(m[side][key].is_number(), "{side}.{key}");
        }
        assert_eq!(m[side]["cov_ratio"].as_array().unwrap().len(), 2);
    }
    assert!(m["pass"].is_boolean());
    assert!(
        m.get("diffraction").is_some(),
        "the diffraction check is recorded (null when there is none)"
    );
    // the design tile against its target: only the facet discretisation separates them
    let d = &m["design"];
    assert!(
        d["ndf_corr"].as_f64().unwrap() >= 0.99 && d["ndf_l1"].as_f64().unwrap() <= 0.1,
        "{d}"
    );
    // the milled surface: the correlation target is reached; the verdict and the notes agree
    let ml = &m["milled"];
    assert!(ml["ndf_corr"].as_f64().unwrap() >= 0.95, "{ml}");
    let all_pass = ml["checks"]
        .as_array()
        .unwrap()
        .iter()
        .all(|c| c["pass"].as_bool().unwrap());
    assert_eq!(m["pass"].as_bool().unwrap(), all_pass);
    let html = std::fs::read_to_string(out.path().join("report.html")).unwrap();
    if !all_pass {
        assert!(
            !m["notes"].as_array().unwrap().is_empty() && html.contains("<h2>Why</h2>"),
            "a shortfall is explained"
        );
    }
    // one page, offline: images embedded, nothing fetched
    assert!(html.matches("src=\"data:image/png;base64,").count() >= 7);
    assert!(!html.contains("http://") && !html.contains("https://") && !html.contains("<script"));
    // rendered by a real browser: its images show
    if let Some(chrome) = chromium() {
        let shot = out.path().join("shot.png");
        let profile = tempfile::tempdir().unwrap();
        let r = Command::new(chrome)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--hide-scrollbars",
                "--window-size=1280,3000",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg(format!("--screenshot={}", shot.display()))
            .arg(format!("file://{}", out.path().join("report.html").display()))
            .output()
            .unwrap();
        assert!(shot.exists(), "no screenshot: {}", String::from_utf8_lossy(&r.stderr));
        let n = image_pixels(&std::fs::read(&shot).unwrap());
        assert!(
            n > 5_000,
            "the rendered page shows only {n} image pixels: images did not render"
        );
    }
}

fn write_job(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("job.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn job_text(extra_toolpath: &str, facets: &str, machine: &str) -> String {
    format!(
        "version = 1\nname = \"t\"\n[target]\nbrdf = \"beckmann:alpha=0.2\"\n[machine]\nprofile = \"{machine}\"\n[facets]\n{facets}\n[toolpath]\ntool = \"ball05\"\n{extra_toolpath}\n"
    )
}

#[test]
fn bad_jobs_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let machine = root().join("machines/grbl-3018.toml").display().to_string();
    let cases = [
        (
            job_text("area_mm = [10.0, 10.0]\nspeed = 3", "facet_mm = 1.0", &machine),
            vec!["speed"],
        ),
        (
            job_text("area_mm = [10.0, 10.0]", "facet_mm = 1.0", "/no/such/machine.toml"),
            vec!["machine.profile", "/no/such/machine.toml"],
        ),
        (
            job_text("area_mm = [10.0, 10.0]", "facet_mm = 0.3", &machine),
            vec!["impossible combination", "facet_mm", "ball05"],
        ),
        (
            job_text("area_mm = [400.0, 10.0]", "facet_mm = 1.0", &machine),
            vec!["impossible combination", "area_mm", "travel"],
        ),
        (
            job_text("area_mm = [10.0, 10.0]\ntool = \"ball9\"", "facet_mm = 1.0", &machine)
                .replace("tool = \"ball05\"\n", ""),
            vec!["toolpath.tool", "ball9"],
        ),
        (
            job_text("area_mm = [10.0, 10.0]", "facet_mm = 1.0", &machine).replace("version = 1", "version = 7"),
            vec!["version"],
        ),
    ];
    for (text, needles) in cases {
        let p = write_job(dir.path(), &text);
        let e = match Job::load(&p) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("accepted:\n{text}"),
        };
        for n in needles {
            assert!(e.contains(n), "`{e}` should mention `{n}`");
        }
    }
    // through the binary: a non-zero exit and no output folder
    let p = write_job(
        dir.path(),
        &job_text("area_mm = [400.0, 10.0]", "facet_mm = 1.0", &machine),
    );
    let out = dir.path().join("out");
    let o = brdfmill(&["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("travel"));
    assert!(!out.exists(), "work started before the job was checked");
}

#[test]
fn every_example_job_loads() {
    let dir = root().join("examples");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&p).unwrap();
        let result = if text.contains("merl:") {
            // the MERL example needs its generated file: make it beside a copy of the job
            let tmp = tempfile::tempdir().unwrap();
            std::fs::create_dir_all(tmp.path().join("data")).unwrap();
            let brdf = brdfmill::brdf::Brdf::parse("beckmann:alpha=0.18,material=gold").unwrap();
            brdfmill::brdf::Merl::from_fn(|a, b| brdf.eval(a, b))
                .write(&tmp.path().join("data/beckmann-0.18-gold.binary"))
                .unwrap();
            let fixed = text.replace("../machines/", &format!("{}/", root().join("machines").display()));
            Job::load(&write_job(tmp.path(), &fixed)).map(|_| ())
        } else {
            Job::load(&p).map(|_| ())
        };
        result.unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        n += 1;
    }
    assert!(n >= 5, "{n} example jobs");
}
