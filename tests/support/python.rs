//! The Python interpreter the tests that read vge's outputs back with real Python packages
//! (rerun-sdk, MuJoCo, TensorBoard's reader) run: VGE_PYTHON, else the venv that
//! scripts/test.sh fills in `.deps/py`, else `python3`. Included by path
//! (`#[path = ".../tests/support/python.rs"] mod python_env;`) from every crate's tests, since
//! no test-support crate is shared across the workspace; so `CARGO_MANIFEST_DIR` below is
//! the including crate's (every crate sits one level below the workspace root).

use std::path::{Path, PathBuf};

/// VGE_PYTHON, else `<workspace>/.deps/py/bin/python`, else `python3`.
pub fn python() -> PathBuf {
    if let Ok(p) = std::env::var("VGE_PYTHON") {
        return p.into();
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.deps/py/bin/python");
    if venv.exists() { venv } else { "python3".into() }
}

/// A recording (`vge eval --record`, `vge-bridge run --record`) drawn into the Rerun file
/// `rrd` by the Python package's converter (python/vge/recording.py, run as a script: it
/// needs rerun-sdk, not the package's Rust extension), then read back by Rerun's own SDK
/// (sim/tests/rrd_summary.py): that summary's JSON.
#[allow(dead_code)] // not every including test reads recordings
pub fn recording_summary(recording: &Path, rrd: &Path) -> serde_json::Value {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let draw = std::process::Command::new(python())
        .arg(root.join("python/vge/recording.py"))
        .arg(recording)
        .arg("-o")
        .arg(rrd)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with rerun-sdk)");
    assert!(
        draw.status.success(),
        "python/vge/recording.py could not draw {}: {}",
        recording.display(),
        String::from_utf8_lossy(&draw.stderr)
    );
    let read = std::process::Command::new(python())
        .arg(root.join("sim/tests/rrd_summary.py"))
        .arg(rrd)
        .output()
        .expect("python runs");
    assert!(
        read.status.success(),
        "rerun-sdk could not read {}: {}",
        rrd.display(),
        String::from_utf8_lossy(&read.stderr)
    );
    serde_json::from_slice(&read.stdout).expect("one JSON object")
}
