//! One writer per run folder: `DIR/vge.lock`, held with an advisory lock (`flock`, through
//! [`File::try_lock`]) for as long as a `vge train`, `--resume`, sweep task or
//! `vge eval --run --write` works on the folder, and holding the holder's pid (for the
//! refusal's message).
//!
//! The kernel drops the lock when its process exits, however it exits (a kill included), so
//! a lock left by a dead process is taken over by the next writer with nothing to clean up:
//! the file stays, with the dead process's pid in it, until the new holder writes its own.

use std::fs::{File, TryLockError};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use thiserror::Error;

/// The lock file in a run folder.
pub const LOCK_FILE: &str = super::LOCK;

#[derive(Debug, Error)]
pub enum LockError {
    #[error(
        "{dir} is in use by another vge (pid {pid} holds {lock}): only one process may write a \
         run folder; wait for it to end, or stop it (it checkpoints on SIGTERM) and try again"
    )]
    Held { dir: PathBuf, lock: PathBuf, pid: String },
    #[error("locking {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
}

/// The lock of a run folder, released when dropped (or when the process ends).
#[derive(Debug)]
pub struct RunLock {
    _file: File,
    path: PathBuf,
}

impl RunLock {
    /// Takes the lock of `dir` (which must exist) without waiting: refused, naming the pid
    /// of the holder, when another process holds it.
    pub fn acquire(dir: &Path) -> Result<Self, LockError> {
        let path = dir.join(LOCK_FILE);
        let io = |source| LockError::Io { path: path.clone(), source };
        let mut file =
            File::options().read(true).write(true).create(true).truncate(false).open(&path).map_err(io)?;
        let started = std::time::Instant::now();
        loop {
            match file.try_lock() {
                Ok(()) => break,
                Err(TryLockError::WouldBlock) => {
                    let pid = holder_pid(&mut file);
                    // A lock this process let go of stays held for a moment by a child it is
                    // starting (between fork and exec the child shares the descriptor): when
                    // the file names this process, wait that moment out before refusing.
                    if pid == std::process::id().to_string() && started.elapsed() < SELF_RELEASE_WAIT {
                        std::thread::sleep(std::time::Duration::from_millis(10));
                        continue;
                    }
                    return Err(LockError::Held { dir: dir.to_owned(), lock: path, pid });
                }
                Err(TryLockError::Error(e)) => return Err(io(e)),
            }
        }
        file.set_len(0).map_err(io)?;
        // (Reading a holder's pid above moved the position.)
        std::io::Seek::rewind(&mut file).map_err(io)?;
        file.write_all(format!("{}\n", std::process::id()).as_bytes()).map_err(io)?;
        Ok(Self { _file: file, path })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// How long a lock file naming this very process is waited for before it counts as held.
const SELF_RELEASE_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// The pid the lock file holds ("unknown" before the holder has written it).
fn holder_pid(file: &mut File) -> String {
    use std::io::Seek;
    let mut text = String::new();
    match file.rewind().and_then(|()| file.read_to_string(&mut text)) {
        Ok(_) if !text.trim().is_empty() => text.trim().to_owned(),
        _ => "unknown".to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_is_refused_with_the_holders_pid_and_a_released_one_is_taken_over() {
        let dir = std::env::temp_dir().join(format!("vge-run-lock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let held = RunLock::acquire(&dir).expect("first");
        // flock locks belong to the open file: a second open in this process conflicts as
        // another process's would.
        let err = RunLock::acquire(&dir).expect_err("second").to_string();
        assert!(err.contains(&format!("pid {}", std::process::id())), "{err}");
        assert!(err.contains("vge.lock"), "{err}");
        drop(held);
        let again = RunLock::acquire(&dir).expect("released");
        assert_eq!(again.path(), dir.join(LOCK_FILE));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
