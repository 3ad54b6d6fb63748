//! Runs the Python cv2 baseline (`bench/vision/cv2_baseline.py`) on a JSON spec and reads its samples back.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};
use serde::Deserialize;

use crate::stats::Samples;

#[derive(Debug, Deserialize)]
struct CaseOut {
    wall_ms: Vec<f64>,
    cpu_ms: Vec<f64>,
}

/// What the baseline measured, by case name, and the cv2 version it ran.
#[derive(Debug)]
pub struct BaselineRun {
    pub cv2_version: String,
    pub cases: BTreeMap<String, Samples>,
}

/// The interpreter: `$VISION_PYTHON`, else the venv the Makefile creates, else `python3`.
pub fn python(repo: &Path) -> PathBuf {
    if let Some(python) = std::env::var_os("VISION_PYTHON") {
        return PathBuf::from(python);
    }
    let venv = repo.join("bench/vision/.venv/bin/python");
    if venv.is_file() {
        venv
    } else {
        PathBuf::from("python3")
    }
}

/// Runs the script with `spec` and returns its samples.
pub fn run(python: &Path, script: &Path, spec: &serde_json::Value) -> anyhow::Result<BaselineRun> {
    let spec_path =
        std::env::temp_dir().join(format!("vision-bench-spec-{}.json", std::process::id()));
    std::fs::write(&spec_path, serde_json::to_vec(spec)?).context("writing the baseline spec")?;
    let output = Command::new(python)
        .arg(script)
        .arg(&spec_path)
        .output()
        .with_context(|| format!("running {} {}", python.display(), script.display()))?;
    let _ = std::fs::remove_file(&spec_path);
    if !output.status.success() {
        bail!(
            "the cv2 baseline failed ({}); install it with `python3 -m venv bench/vision/.venv && \
             bench/vision/.venv/bin/pip install 'opencv-python-headless<5'` or set VISION_PYTHON:\n{}",
            output.status,
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let mut raw: BTreeMap<String, serde_json::Value> =
        serde_json::from_slice(&output.stdout).context("parsing the baseline's JSON")?;
    let cv2_version = raw
        .remove("cv2_version")
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default();
    let mut cases = BTreeMap::new();
    for (name, value) in raw {
        let case: CaseOut =
            serde_json::from_value(value).with_context(|| format!("baseline case {name}"))?;
        cases.insert(
            name,
            Samples {
                wall_ms: case.wall_ms,
                cpu_ms: case.cpu_ms,
            },
        );
    }
    Ok(BaselineRun { cv2_version, cases })
}
