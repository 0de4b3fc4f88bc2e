//! The run's artifacts: each written atomically into the output folder as it is made, the state of the run
//! (`run.json`: running until the last stage asked for has written its files), the stages' times, and the
//! report's table of what each file holds.

use super::outcome::{Outcome, Progress, Stage, RUN_STATE};
use super::JobError;
use std::path::{Path, PathBuf};

/// `run.json`: the state of the run in its folder (see [`RUN_STATE`]).
fn write_state(o: &mut Out, job: &str, done: &[(Stage, f64)], state: &str) -> Result<(), JobError> {
    let v = serde_json::json!({
        "format": "brdfmill-run",
        "version": 1,
        "job": job,
        // the folder the job file's paths are read from: `brdfmill compare` reloads `job.toml` in it
        "job_dir": o.job_dir.display().to_string(),
        "state": state,
        "stages_done": done.iter().map(|(s, _)| s.name()).collect::<Vec<_>>(),
    });
    let p = o.dir.join(RUN_STATE);
    crate::base::io::write_atomic(&p, serde_json::to_string_pretty(&v).unwrap_or_default().as_bytes())?;
    Ok(())
}

/// Artifacts written so far, in order, and the stages' times.
pub(super) struct Out<'a> {
    dir: &'a Path,
    written: Vec<PathBuf>,
    job: String,
    job_dir: PathBuf,
    timings: Vec<(Stage, f64)>,
    clock: std::time::Instant,
}

impl<'a> Out<'a> {
    /// Start a run into `dir` of the job named `job` whose file is in `job_dir`: `run.json` says it is
    /// running.
    pub(super) fn new(dir: &'a Path, job: &str, job_dir: &Path) -> Result<Self, JobError> {
        let mut o = Out {
            dir,
            written: vec![],
            job: job.to_string(),
            job_dir: std::path::absolute(job_dir).unwrap_or_else(|_| job_dir.to_path_buf()),
            timings: vec![],
            clock: std::time::Instant::now(),
        };
        o.state("running")?;
        Ok(o)
    }

    pub(super) fn write(&mut self, name: &str, bytes: &[u8]) -> Result<(), JobError> {
        let p = self.dir.join(name);
        crate::base::io::write_atomic(&p, bytes)?;
        // a file rewritten (program.json gains the simulation's figures) is listed once
        if !self.written.contains(&p) {
            self.written.push(p);
        }
        Ok(())
    }

    /// Write a heightfield as `.npy`.
    pub(super) fn npy(&mut self, name: &str, hf: &crate::base::heightfield::Heightfield) -> Result<(), JobError> {
        let p = self.dir.join(name);
        hf.write_npy(&p)?;
        self.written.push(p);
        Ok(())
    }

    /// Write a heightfield as an X3P file (ISO 25178-72, float32 metres), for metrology software.
    pub(super) fn x3p(&mut self, name: &str, hf: &crate::base::heightfield::Heightfield) -> Result<(), JobError> {
        let p = self.dir.join(name);
        crate::base::x3p::write_as(&p, hf, crate::base::x3p::Precision::F32).map_err(|e| match e {
            crate::base::x3p::X3pError::Write(w) => JobError::Write(w),
            other => JobError::Stage {
                stage: "simulate",
                error: super::StageError::Input(other.to_string()),
            },
        })?;
        self.written.push(p);
        Ok(())
    }

    /// The output folder.
    pub(super) fn dir(&self) -> &Path {
        self.dir
    }

    /// A file written into the output folder by other means (a MERL file from `target.merl_from`).
    pub(super) fn written_elsewhere(&mut self, p: PathBuf) {
        if !self.written.contains(&p) {
            self.written.push(p);
        }
    }

    fn state(&mut self, state: &str) -> Result<(), JobError> {
        let (job, done) = (self.job.clone(), std::mem::take(&mut self.timings));
        let r = write_state(self, &job, &done, state);
        self.timings = done;
        r
    }

    /// The report's artifact table of the files written so far.
    pub(super) fn listed(&self) -> Vec<(String, String)> {
        listed(&self.written)
    }

    /// A stage starts.
    pub(super) fn start(&mut self, progress: &mut dyn FnMut(Progress), stage: Stage) {
        progress(Progress::Started(stage));
        self.clock = std::time::Instant::now();
    }

    /// A stage has written its artifacts: its time is kept and `run.json` lists it.
    pub(super) fn done(&mut self, progress: &mut dyn FnMut(Progress), stage: Stage) -> Result<(), JobError> {
        progress(Progress::Finished(stage));
        self.timings.push((stage, self.clock.elapsed().as_secs_f64()));
        self.state("running")
    }

    /// The run is complete: `run.json` says so, and the outcome gets the files, their bytes and the times.
    pub(super) fn finish(mut self, mut outcome: Outcome) -> Result<Outcome, JobError> {
        self.state("complete")?;
        outcome.bytes_written = self
            .written
            .iter()
            .filter_map(|p| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum();
        outcome.artifacts = self.written;
        outcome.timings = self.timings;
        Ok(outcome)
    }
}

/// The artifact table of the report.
fn listed(written: &[PathBuf]) -> Vec<(String, String)> {
    let mut listed: Vec<(String, String)> = written
        .iter()
        .map(|p| {
            (
                p.file_name()
                    .map(|n| n.to_string_lossy().to_string())
                    .unwrap_or_default(),
                describe(p),
            )
        })
        .collect();
    listed.push(("report.html".into(), describe(Path::new("report.html"))));
    listed
}

fn describe(p: &Path) -> String {
    let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
    // a region's own files (`ndf-NAME.json`, `tile-NAME.npy`): what the single target's are, for that region
    if let Some((stem, ext)) = name.split_once('.') {
        if let Some((kind, region)) = stem.split_once('-') {
            if matches!(kind, "ndf" | "tile") {
                let what = describe(Path::new(&format!("{kind}.{ext}")));
                return format!("region `{region}`: {what}");
            }
            if kind == "program" && ext == "nc" {
                return format!("G-code, program {region} of the job's programs (one per tool, run in order)");
            }
        }
    }
    match name {
        "part.npy" => "the composed part's design heightfield, mm (NumPy)",
        "part.png" => "the composed part, shaded relief",
        "labels.png" => "the label map as read, in the regions' colours",
        "light.png" => "the simulated part under a moving light",
        "ndf.json" => "target NDF and observed distribution (versioned JSON)",
        "ndf.png" => "observed and target NDF",
        "ndf-design.json" => "the design tile's NDF the verdict measured, beside the target's (ndf.json's format)",
        "ndf-milled.json" => "the milled surface's NDF the verdict measured, beside the target's (ndf.json's format)",
        "tile.json" => "facet tile: slopes, heights, stats",
        "tile.npy" => "tile heightfield, mm (NumPy)",
        "tile.png" => "tile shaded relief",
        "tile.stl" => "faceted solid of one tile (binary STL, mm)",
        "program.nc" => "G-code",
        crate::gcode::TOOL_TABLE_FILE => "LinuxCNC tool table for the program (lengths 0: set on the machine)",
        "program.json" => "G-code summary",
        "sim.npy" => "simulated milled heightfield, mm (NumPy)",
        "sim.x3p" => "simulated milled heightfield, ISO 25178-72 X3P (float32 metres) for metrology software and `brdfmill analyze`",
        "sim.png" => "simulated surface shaded relief",
        "deviation.png" => "simulated minus design",
        "design-vs-cut.png" => "the design and the simulated cut side by side, and along one line",
        "sim.json" => "simulation and deviation statistics",
        "metrics.json" => "verification metrics and verdict",
        "wave.png" => "wave (Kirchhoff) and geometric BRDF of a milled patch",
        "report.html" => "this report",
        "job.toml" => "the job as it ran (overrides applied, budgets derived): `brdfmill compare` measures a scan of the part with it",
        _ if name.ends_with(".binary") => "MERL file written from `target.merl_from`, read back as the target",
        _ => "",
    }
    .to_string()
}
