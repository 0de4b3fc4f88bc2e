//! Generated example data goes into the run's output folder, never into the source tree: `examples/merl-gold.toml`
//! asks for a 35 MB MERL file written from a model (`target.merl_from`), and a run leaves `examples/data` as it
//! was.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Each file in `dir`: its size and modification time.
fn listing(dir: &Path) -> BTreeMap<PathBuf, (u64, std::time::SystemTime)> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            let m = e.metadata().unwrap();
            (e.path(), (m.len(), m.modified().unwrap()))
        })
        .collect()
}

#[test]
fn the_merl_example_writes_its_file_into_the_output_folder() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let job = root.join("examples/merl-gold.toml");
    let text = std::fs::read_to_string(&job).unwrap();
    let named = "data/beckmann-0.18-gold.binary";
    assert!(
        text.contains(&format!("merl:{named}")) && text.contains("merl_from"),
        "{text}"
    );
    let data = root.join("examples/data");
    let before = listing(&data);
    let out = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_brdfmill"))
        .args(["run", job.to_str().unwrap(), "--out", out.path().to_str().unwrap()])
        .args(["--until", "ndf", "--set", "ndf.res=32"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(listing(&data), before, "the run changed examples/data");
    // unless a file from an older build is still beside the job (then it is read), the run wrote its own
    if !root.join("examples").join(named).exists() {
        let file = out.path().join("beckmann-0.18-gold.binary");
        assert!(file.exists(), "no {}", file.display());
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains(&format!("wrote {}", file.display())), "{stdout}");
    }
}
