//! Helpers shared by the integration tests of vge-lab, vge-trainer and vge-cli (each crate's
//! `tests/common/mod.rs` includes this file): tiny runs, configs, temp folders, Python.

use std::path::PathBuf;
use std::process::Command;

#[path = "python.rs"]
mod python_env;
#[allow(unused_imports)] // each test binary uses its own subset
pub use python_env::{python, recording_summary};

/// `tag step value` lines for every scalar in `dir`, as TensorBoard reads them.
pub fn tensorboard_scalars(dir: &std::path::Path) -> Vec<(String, u64, f64)> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/support/tb_read.py");
    let out = Command::new(python())
        .arg(script)
        .arg(dir)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with tensorboard)");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "TensorBoard could not read the events: {stderr}");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(' ').collect();
            (f[0].to_owned(), f[1].parse().expect("step"), f[2].parse().expect("value"))
        })
        .collect()
}

/// `--set` overrides that make `configs/cube-fg-vge.toml` a run of seconds: two envs, short
/// episodes, small nets and batches, a short warm-up, a log row every 50 steps and a
/// checkpoint every 200.
pub const TINY: &[&str] = &[
    "num_envs=2",
    "env.episode_length=25",
    "sac.hidden=[32, 32]",
    "sac.batch=32",
    "sac.warmup=40",
    "sac.buffer_size=5000",
    "sac.utd=0.5",
    "vge.horizon=4",
    "run.log_interval=50",
    "run.checkpoint_interval=200",
    "run.eval_interval=0",
    "run.eval_episodes=2",
    "run.eval_episode_s=1.0",
    // Training's held-out score at its end (100 episodes per policy) would cost a tiny run
    // most of its time; cli/tests/score.rs tests it.
    "run.score_episodes=0",
];

/// `dir/config.toml`: the config defaults with [`TINY`], then `own` overrides, for
/// `total_steps`, validated. Its path.
pub fn tiny_config_file(dir: &std::path::Path, own: &[&str], total_steps: u64) -> PathBuf {
    let mut c = vge_run::config::Config::default();
    for o in TINY.iter().chain(own) {
        vge_run::config::apply_override(&mut c, o).expect(o);
    }
    c.total_steps = total_steps;
    c.validate().expect("valid");
    let path = dir.join("config.toml");
    std::fs::write(&path, c.to_toml_string().expect("toml")).expect("write config");
    path
}

/// The repository's `configs/` file `name`.
pub fn config(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs").join(name)
}

/// `TINY` as `--set k=v` arguments.
pub fn tiny_args() -> Vec<String> {
    TINY.iter().flat_map(|o| ["--set".to_owned(), (*o).to_owned()]).collect()
}

/// An empty directory `vge-{name}-{pid}` under the system's temp dir (emptied if it exists).
pub fn temp_dir(name: &str) -> PathBuf {
    let root = std::env::temp_dir().join(format!("vge-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).expect("temp dir");
    root
}

/// A copy of the folder `from` (a run, with its subfolders) at `to`.
pub fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).expect("dir");
    for entry in std::fs::read_dir(from).expect("read_dir") {
        let path = entry.expect("entry").path();
        let target = to.join(path.file_name().expect("name"));
        if path.is_dir() {
            copy_dir(&path, &target);
        } else {
            std::fs::copy(&path, &target).expect("copy");
        }
    }
}
