//! `vge queue build`: `runs/bin/vge-COMMIT`, the `vge` a queue trains with, built once from a
//! git worktree of COMMIT at `runs/src/COMMIT` (which is also where the queue's configs are
//! read from). Building is a step of its own, asked for by name, because it takes minutes
//! and needs the checkout's libtorch (`.deps/libtorch`, which the worktree links to).

use std::fs::File;
use std::path::PathBuf;
use std::process::Command;

use super::{Checkout, QueueError, io_err};

/// Builds the vge of `commit` unless `runs/bin/vge-COMMIT` exists; returns its path. Two
/// lanes asking at once build it once (`runs/bin/.build-COMMIT.lock`). Cargo's output goes
/// to this process's stderr.
pub fn build(checkout: &Checkout, commit: &str, say: &mut dyn FnMut(&str)) -> Result<PathBuf, QueueError> {
    let full = checkout
        .resolve_commit(commit)
        .ok_or_else(|| QueueError::Invalid(format!("no commit {commit} in this repository")))?;
    let bin = checkout.binary(commit);
    if bin.is_file() {
        return Ok(bin);
    }
    let bin_dir = checkout.root().join("runs/bin");
    std::fs::create_dir_all(&bin_dir).map_err(io_err(&bin_dir))?;
    let lock_path = bin_dir.join(format!(".build-{commit}.lock"));
    let lock = File::create(&lock_path).map_err(io_err(&lock_path))?;
    lock.lock().map_err(io_err(&lock_path))?;
    if bin.is_file() {
        return Ok(bin);
    }
    let libtorch = checkout.root().join(".deps/libtorch");
    let libtorch = std::fs::canonicalize(&libtorch).map_err(|_| {
        QueueError::Invalid(format!(
            "{} is missing: run scripts/setup-libtorch.sh first (the built vge links it)",
            libtorch.display()
        ))
    })?;
    let src = checkout.source(commit);
    if !src.exists() {
        say(&format!("adding a git worktree of {commit} at {}", src.display()));
        let src_arg = src.to_string_lossy();
        run(checkout.git(&["worktree", "add", "--detach", &src_arg, &full]), "git worktree add")?;
    }
    let deps = src.join(".deps");
    std::fs::create_dir_all(&deps).map_err(io_err(&deps))?;
    let link = deps.join("libtorch");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&libtorch, &link).map_err(io_err(&link))?;
    say(&format!("building vge at {commit} (once)"));
    let mut cargo = Command::new("cargo");
    cargo.args(["build", "--release", "--bin", "vge"]).current_dir(&src);
    // The worktree's own target folder, and its .cargo/config.toml's libtorch: nothing from
    // the caller's shell that would build another program.
    for var in [
        "CARGO_TARGET_DIR",
        "LIBTORCH",
        "LIBTORCH_USE_PYTORCH",
        "LIBTORCH_INCLUDE",
        "LIBTORCH_LIB",
        "LIBTORCH_BYPASS_VERSION_CHECK",
    ] {
        cargo.env_remove(var);
    }
    let status = cargo.status().map_err(|e| QueueError::Invalid(format!("running cargo: {e}")))?;
    if !status.success() {
        return Err(QueueError::Invalid(format!("cargo build in {} failed ({status})", src.display())));
    }
    let built = src.join("target/release/vge");
    let tmp = bin.with_extension("tmp");
    std::fs::copy(&built, &tmp).map_err(io_err(&built))?;
    std::fs::rename(&tmp, &bin).map_err(io_err(&bin))?;
    Ok(bin)
}

fn run(output: std::io::Result<std::process::Output>, what: &str) -> Result<(), QueueError> {
    let output = output.map_err(|e| QueueError::Invalid(format!("{what}: {e}")))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(QueueError::Invalid(format!(
            "{what} failed ({}): {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        )))
    }
}
