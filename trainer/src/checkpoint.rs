//! A run directory's checkpoint folder: written whole or not at all, and verified file by
//! file before anything is resumed from it.
//!
//! `DIR/checkpoint/` holds `state.toml` (the training loop's counters, generator state and
//! metric windows), the networks and optimiser state that [`Learner::save`] writes (`actor.ot`,
//! `critic.ot`, `target.ot`, `target_actor.ot` for TD3, `optim.ot`), `replay.bin` when the
//! run keeps its replay buffer, `episodes.bin` when the envs' episodes go on through the
//! checkpoint (a stop, the end: `crate::train`), and [`MANIFEST`] (`manifest.json`): every other file's name,
//! length in bytes and CRC-32 (IEEE, `"0x%08x"`).
//!
//! [`save`] writes everything into `DIR/checkpoint.tmp/`, each file's CRC computed as it is
//! written (libtorch serialises the `.ot` files into memory and this module writes them, so
//! that a full disk is an error naming the file, not an abort), each file synced, then the
//! manifest, last. It then swaps the folders: `checkpoint/` to
//! `checkpoint.old/`, `checkpoint.tmp/` to `checkpoint/`, and deletes `checkpoint.old/`. A
//! kill at any moment leaves one whole checkpoint: `checkpoint/`, or, between the two
//! renames, `checkpoint.old/`.
//!
//! [`open`] resumes from `checkpoint/` when it exists, and from `checkpoint.old/` only when
//! `checkpoint/` does not (a save killed between its renames); never from `checkpoint.old/`
//! in place of a damaged `checkpoint/`. Before a single file reaches libtorch, the replay
//! loader or the TOML parser, the folder must match its manifest: a missing manifest (an
//! older vge's checkpoint, or not one of ours), a listed file that is missing, a file of a
//! checkpoint's kind that the manifest does not list, a wrong length (truncation) or a wrong
//! CRC is refused with a [`CheckpointError`] that names the file.

use std::collections::BTreeSet;
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::learner::{ACTOR_FILE, CRITIC_FILE, Learner, OPTIM_FILE, TARGET_ACTOR_FILE, TARGET_FILE};
use crate::replay::{ReplayBuffer, ReplayError};
use vge_run::run_dir::RunDir;
use vge_run::run_dir::atomic_file::sync_dir;

/// The checkpoint folder in a run directory; [`save`] writes to the temporary one first and
/// keeps the previous one while it swaps them (names: [`vge_run::run_dir`]).
pub use vge_run::run_dir::{CHECKPOINT as DIR, CHECKPOINT_OLD as OLD_DIR, CHECKPOINT_TMP as TMP_DIR};
/// The list of the checkpoint's files with their lengths and CRCs, written last.
pub const MANIFEST: &str = "manifest.json";
/// The training loop's state (`crate::train`).
pub use vge_run::run_dir::CHECKPOINT_STATE as STATE_FILE;
/// The replay buffer ([`ReplayBuffer::write_to`]).
pub const REPLAY_FILE: &str = "replay.bin";
/// The envs' episodes in progress, when they go on through the checkpoint (`crate::train`).
pub const EPISODES_FILE: &str = "episodes.bin";
/// Every file a vge checkpoint holds besides its manifest: one of these that the manifest
/// does not list is refused.
pub const KNOWN_FILES: [&str; 8] = [
    STATE_FILE,
    ACTOR_FILE,
    CRITIC_FILE,
    TARGET_FILE,
    TARGET_ACTOR_FILE,
    OPTIM_FILE,
    REPLAY_FILE,
    EPISODES_FILE,
];
/// The manifest's `format`.
pub const MANIFEST_FORMAT: u32 = 1;

#[derive(Debug, Error)]
pub enum CheckpointError {
    #[error("{out_dir} holds no checkpoint (neither checkpoint/ nor checkpoint.old/)")]
    NoCheckpoint { out_dir: PathBuf },
    #[error("checkpoint {path} is not a folder (refusing to resume; delete it to start over)")]
    NotAFolder { path: PathBuf },
    #[error(
        "checkpoint manifest {path} is missing: the checkpoint was written by a vge without \
         checkpoint integrity checks, or is incomplete (refusing to resume an unverified \
         checkpoint; delete the checkpoint folder to start over)"
    )]
    NoManifest { path: PathBuf },
    #[error(
        "checkpoint manifest {path} is corrupt: {message} (refusing to resume; delete the \
         checkpoint folder to start over)"
    )]
    BadManifest { path: PathBuf, message: String },
    #[error(
        "checkpoint file {path} is missing: {MANIFEST} lists it (refusing to resume; delete \
         the checkpoint folder to start over)"
    )]
    Missing { path: PathBuf },
    #[error(
        "checkpoint file {path} is missing: resuming needs it and {MANIFEST} does not list it \
         (refusing to resume; delete the checkpoint folder to start over)"
    )]
    NotListed { path: PathBuf },
    #[error(
        "checkpoint file {path} is not listed in {MANIFEST}: it was put there after the \
         checkpoint was written (refusing to resume; delete the checkpoint folder to start over)"
    )]
    Unlisted { path: PathBuf },
    #[error(
        "checkpoint file {path} is {what}: {actual} bytes, expected {expected} (refusing to \
         resume; delete the checkpoint folder to start over)"
    )]
    Length { path: PathBuf, what: &'static str, actual: u64, expected: u64 },
    #[error(
        "checkpoint file {path} is corrupt: crc32 {actual:#010x}, expected {expected:#010x} \
         (refusing to resume; delete the checkpoint folder to start over)"
    )]
    Corrupt { path: PathBuf, actual: u32, expected: u32 },
    #[error("reading checkpoint file {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("writing checkpoint {path}: {source}")]
    Write { path: PathBuf, source: std::io::Error },
    #[error("writing the networks into {dir}: libtorch: {source}")]
    SaveNetworks { dir: PathBuf, source: tch::TchError },
    /// libtorch refused verified files: they are whole, but not this configuration's
    /// networks (`message` is libtorch's, without its C++ backtrace).
    #[error(
        "loading the networks from checkpoint {dir} (is the configuration the one it was \
         saved with?): libtorch: {message}"
    )]
    LoadNetworks { dir: PathBuf, message: String },
    #[error(transparent)]
    Replay(#[from] ReplayError),
}

/// What `manifest.json` holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`MANIFEST_FORMAT`].
    pub format: u32,
    /// The vge that wrote the checkpoint (informative).
    pub vge_version: String,
    /// Every file of the checkpoint but the manifest, in the order they were written.
    pub files: Vec<FileEntry>,
}

/// One file of a checkpoint.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Its name in the checkpoint folder (no path).
    pub name: String,
    /// Its length in bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE 802.3, as zlib's `crc32`) of its bytes, as `"0x%08x"`.
    pub crc32: String,
}

impl FileEntry {
    fn new(name: &str, bytes: u64, crc: u32) -> Self {
        Self { name: name.to_owned(), bytes, crc32: format!("{crc:#010x}") }
    }

    fn crc(&self) -> Option<u32> {
        let hex = self.crc32.strip_prefix("0x")?;
        if hex.len() != 8 {
            return None;
        }
        u32::from_str_radix(hex, 16).ok()
    }
}

/// A [`Write`] that passes everything to `inner` and keeps the CRC and length of it.
struct CrcWriter<W> {
    inner: W,
    crc: crc32fast::Hasher,
    bytes: u64,
}

impl<W: Write> Write for CrcWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Buffer size for writing and hashing checkpoint files.
const IO_BUF: usize = 1 << 20;

/// Writes `dir/name` with `fill`, synced to disk, and its manifest entry from the bytes as
/// they were written.
fn write_file(
    dir: &Path,
    name: &str,
    fill: impl FnOnce(&mut CrcWriter<BufWriter<File>>) -> std::io::Result<()>,
) -> Result<FileEntry, CheckpointError> {
    let path = dir.join(name);
    let err = |source| CheckpointError::Write { path: path.clone(), source };
    let file = File::create(&path).map_err(err)?;
    let mut w =
        CrcWriter { inner: BufWriter::with_capacity(IO_BUF, file), crc: crc32fast::Hasher::new(), bytes: 0 };
    fill(&mut w).map_err(err)?;
    let file = w.inner.into_inner().map_err(|e| err(e.into_error()))?;
    // The folder is renamed into place next: its files must be on disk before that.
    file.sync_all().map_err(err)?;
    Ok(FileEntry::new(name, w.bytes, w.crc.finalize()))
}

/// The length and CRC-32 of the file at `path`, read through once.
pub fn crc_of_file(path: &Path) -> std::io::Result<(u64, u32)> {
    let mut file = File::open(path)?;
    let mut buf = vec![0u8; IO_BUF];
    let mut crc = crc32fast::Hasher::new();
    let mut bytes = 0u64;
    loop {
        let n = match file.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        crc.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok((bytes, crc.finalize()))
}

/// Saves a checkpoint into `out_dir/checkpoint/`: the networks and optimiser state of `learner`,
/// `replay` when given, `state_toml` as `state.toml`, `episodes` when given, and the manifest
/// (module docs). The
/// previous checkpoint stays whole until the new one is complete; a write that fails (a full
/// disk) is an error naming the file and the OS's error, and removes the incomplete
/// `checkpoint.tmp/` so that the space it took is free again.
pub fn save(
    out_dir: &Path,
    learner: &dyn Learner,
    replay: Option<&ReplayBuffer>,
    state_toml: &str,
    episodes: Option<&[u8]>,
) -> Result<(), CheckpointError> {
    let tmp = out_dir.join(TMP_DIR);
    let written = write_tmp(&tmp, learner, replay, state_toml, episodes);
    if written.is_err() {
        // Best effort: the error that matters is the write's.
        let _ = std::fs::remove_dir_all(&tmp);
    }
    written?;
    swap_into_place(out_dir)
}

/// Writes the whole checkpoint into `tmp` (replacing what a killed save left there).
fn write_tmp(
    tmp: &Path,
    learner: &dyn Learner,
    replay: Option<&ReplayBuffer>,
    state_toml: &str,
    episodes: Option<&[u8]>,
) -> Result<(), CheckpointError> {
    let write_err = |path: &Path| {
        let path = path.to_owned();
        move |source| CheckpointError::Write { path, source }
    };
    if tmp.exists() {
        std::fs::remove_dir_all(tmp).map_err(write_err(tmp))?;
    }
    std::fs::create_dir_all(tmp).map_err(write_err(tmp))?;
    // Serialised in memory and written here, so that a full disk is the OS's error on a named
    // file, not a libtorch abort ([`Learner::save_to_memory`]).
    let networks = learner
        .save_to_memory()
        .map_err(|source| CheckpointError::SaveNetworks { dir: tmp.to_owned(), source })?;
    let mut files = Vec::new();
    for (name, bytes) in &networks {
        files.push(write_file(tmp, name, |w| w.write_all(bytes))?);
    }
    drop(networks);
    if let Some(replay) = replay {
        files.push(write_file(tmp, REPLAY_FILE, |w| replay.write_to(w))?);
    }
    if let Some(bytes) = episodes {
        files.push(write_file(tmp, EPISODES_FILE, |w| w.write_all(bytes))?);
    }
    files.push(write_file(tmp, STATE_FILE, |w| w.write_all(state_toml.as_bytes()))?);
    let manifest =
        Manifest { format: MANIFEST_FORMAT, vge_version: env!("CARGO_PKG_VERSION").to_owned(), files };
    let mut text = serde_json::to_string_pretty(&manifest).map_err(|e| write_err(tmp)(e.into()))?;
    text.push('\n');
    write_file(tmp, MANIFEST, |w| w.write_all(text.as_bytes()))?;
    sync_dir(tmp).map_err(write_err(tmp))
}

/// Swaps the whole `checkpoint.tmp/` in: `checkpoint/` to `checkpoint.old/`, `checkpoint.tmp/`
/// to `checkpoint/`, the run folder synced (the renames on disk), `checkpoint.old/` deleted.
fn swap_into_place(out_dir: &Path) -> Result<(), CheckpointError> {
    let (tmp, dir, old) = (out_dir.join(TMP_DIR), out_dir.join(DIR), out_dir.join(OLD_DIR));
    let write_err = |path: &Path| {
        let path = path.to_owned();
        move |source| CheckpointError::Write { path, source }
    };
    if dir.exists() {
        // A checkpoint.old/ beside a whole checkpoint/ is a save killed after its second rename.
        if old.exists() {
            std::fs::remove_dir_all(&old).map_err(write_err(&old))?;
        }
        std::fs::rename(&dir, &old).map_err(write_err(&dir))?;
    }
    // Without checkpoint/, checkpoint.old/ is the whole one (a save killed between its
    // renames, then resumed from it): it stays until the new one is in place.
    std::fs::rename(&tmp, &dir).map_err(write_err(&tmp))?;
    // The new checkpoint's rename must be on disk before the old one is deleted.
    sync_dir(out_dir).map_err(write_err(out_dir))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(write_err(&old))?;
    }
    Ok(())
}

/// The checkpoint folder a resume of `out_dir` reads ([`RunDir::resume_checkpoint`]).
pub fn resume_dir(out_dir: &Path) -> Option<PathBuf> {
    RunDir::new(out_dir).resume_checkpoint()
}

/// Reads `dir`'s manifest and checks every file against it (module docs): the manifest, or
/// the first problem found, cheap checks (presence, lengths) before CRCs.
pub fn verify(dir: &Path) -> Result<Manifest, CheckpointError> {
    let meta = dir.metadata().map_err(|source| CheckpointError::Read { path: dir.to_owned(), source })?;
    if !meta.is_dir() {
        return Err(CheckpointError::NotAFolder { path: dir.to_owned() });
    }
    let path = dir.join(MANIFEST);
    let text = match vge_run::read_limits::read_bounded(&path, vge_run::read_limits::MAX_RECORD_FILE_LEN) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(CheckpointError::NoManifest { path });
        }
        Err(source) => return Err(CheckpointError::Read { path, source }),
    };
    let bad = |message: String| CheckpointError::BadManifest { path: path.clone(), message };
    let manifest: Manifest = serde_json::from_slice(&text).map_err(|e| bad(e.to_string()))?;
    if manifest.format != MANIFEST_FORMAT {
        return Err(bad(format!(
            "format {} (this vge reads format {MANIFEST_FORMAT}; a newer vge wrote it?)",
            manifest.format
        )));
    }
    let mut names = BTreeSet::new();
    let mut crcs = Vec::with_capacity(manifest.files.len());
    for f in &manifest.files {
        let plain = !f.name.is_empty()
            && f.name != "."
            && f.name != ".."
            && f.name != MANIFEST
            && !f.name.contains(['/', '\\', '\0']);
        if !plain {
            return Err(bad(format!("lists {:?}, which is not a checkpoint file name", f.name)));
        }
        if !names.insert(f.name.as_str()) {
            return Err(bad(format!("lists {} twice", f.name)));
        }
        crcs.push(
            f.crc().ok_or_else(|| {
                bad(format!("crc32 {:?} of {} is not 0x and 8 hex digits", f.crc32, f.name))
            })?,
        );
    }
    for name in KNOWN_FILES {
        let path = dir.join(name);
        if !names.contains(name) && path.symlink_metadata().is_ok() {
            return Err(CheckpointError::Unlisted { path });
        }
    }
    let length = |path: PathBuf, actual: u64, expected: u64| CheckpointError::Length {
        what: if actual < expected { "truncated" } else { "longer than written" },
        path,
        actual,
        expected,
    };
    for f in &manifest.files {
        let path = dir.join(&f.name);
        let actual = match path.metadata() {
            Ok(m) => m.len(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(CheckpointError::Missing { path });
            }
            Err(source) => return Err(CheckpointError::Read { path, source }),
        };
        if actual != f.bytes {
            return Err(length(path, actual, f.bytes));
        }
    }
    for (f, &expected) in manifest.files.iter().zip(&crcs) {
        let path = dir.join(&f.name);
        let (bytes, actual) =
            crc_of_file(&path).map_err(|source| CheckpointError::Read { path: path.clone(), source })?;
        if bytes != f.bytes {
            return Err(length(path, bytes, f.bytes));
        }
        if actual != expected {
            return Err(CheckpointError::Corrupt { path, actual, expected });
        }
    }
    Ok(manifest)
}

/// A checkpoint folder whose files all match its manifest.
#[derive(Debug)]
pub struct Verified {
    dir: PathBuf,
    manifest: Manifest,
    state_toml: String,
}

/// Picks the checkpoint folder of `out_dir` ([`resume_dir`]) and [`verify`]s it; reads its
/// `state.toml`.
pub fn open(out_dir: &Path) -> Result<Verified, CheckpointError> {
    let dir =
        resume_dir(out_dir).ok_or_else(|| CheckpointError::NoCheckpoint { out_dir: out_dir.to_owned() })?;
    let manifest = verify(&dir)?;
    let mut checkpoint = Verified { dir, manifest, state_toml: String::new() };
    let path = checkpoint.require(STATE_FILE)?;
    checkpoint.state_toml =
        vge_run::read_limits::read_to_string_bounded(&path, vge_run::read_limits::MAX_RECORD_FILE_LEN)
            .map_err(|source| CheckpointError::Read { path, source })?;
    Ok(checkpoint)
}

impl Verified {
    /// The folder: `checkpoint/` or `checkpoint.old/`.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The text of `state.toml`.
    pub fn state_toml(&self) -> &str {
        &self.state_toml
    }

    /// The path of `name`, which the manifest must list (verified files only are read).
    fn require(&self, name: &str) -> Result<PathBuf, CheckpointError> {
        let path = self.dir.join(name);
        if self.manifest.files.iter().any(|f| f.name == name) {
            Ok(path)
        } else {
            Err(CheckpointError::NotListed { path })
        }
    }

    /// The envs' episodes in progress (`episodes.bin`), when the manifest lists them: a
    /// checkpoint whose episodes go on through it. Verified, so read whole.
    pub fn episodes(&self) -> Result<Option<Vec<u8>>, CheckpointError> {
        if !self.manifest.files.iter().any(|f| f.name == EPISODES_FILE) {
            return Ok(None);
        }
        let path = self.require(EPISODES_FILE)?;
        std::fs::read(&path).map(Some).map_err(|source| CheckpointError::Read { path, source })
    }

    /// Restores the networks and optimiser state into `learner` (same configuration as the one
    /// that saved them) and, when given, the replay buffer.
    pub fn load(
        &self,
        learner: &mut dyn Learner,
        replay: Option<&mut ReplayBuffer>,
    ) -> Result<(), CheckpointError> {
        for name in learner.checkpoint_files() {
            self.require(name)?;
        }
        let replay_path = replay.as_ref().map(|_| self.require(REPLAY_FILE)).transpose()?;
        learner.load(&self.dir).map_err(|e| CheckpointError::LoadNetworks {
            dir: self.dir.clone(),
            message: without_backtrace(&e.to_string()).to_owned(),
        })?;
        if let (Some(replay), Some(path)) = (replay, replay_path) {
            replay.load(&path)?;
        }
        Ok(())
    }

    /// Restores only the networks into `learner` ([`Learner::load_networks`]): the start of a run
    /// that continues from another run's networks with fresh optimiser state and data.
    pub fn load_networks(&self, learner: &mut dyn Learner) -> Result<(), CheckpointError> {
        for name in learner.checkpoint_files().into_iter().filter(|n| *n != crate::learner::OPTIM_FILE) {
            self.require(name)?;
        }
        learner.load_networks(&self.dir).map_err(|e| CheckpointError::LoadNetworks {
            dir: self.dir.clone(),
            message: without_backtrace(&e.to_string()).to_owned(),
        })
    }
}

/// A libtorch error message up to the C++ backtrace that follows it.
fn without_backtrace(message: &str) -> &str {
    let end = ["\nframe #", "\nException raised from"].iter().filter_map(|m| message.find(m)).min();
    message[..end.unwrap_or(message.len())].trim_end()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("vge-checkpoint-unit-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    fn write_manifest(dir: &Path, files: Vec<FileEntry>) {
        let m = Manifest { format: MANIFEST_FORMAT, vge_version: "test".to_owned(), files };
        std::fs::write(dir.join(MANIFEST), serde_json::to_string(&m).expect("json")).expect("manifest");
    }

    #[test]
    fn libtorch_backtraces_are_cut() {
        let m = "Internal torch error: shape mismatch for actor.l0.weight\nException raised from load at x.cpp:1\nframe #0: c10";
        assert_eq!(without_backtrace(m), "Internal torch error: shape mismatch for actor.l0.weight");
        assert_eq!(without_backtrace("plain"), "plain");
    }

    #[test]
    fn the_crc_is_zlibs_and_a_written_file_verifies() {
        let dir = folder("crc");
        let entry = write_file(&dir, STATE_FILE, |w| w.write_all(b"123456789")).expect("write");
        // The CRC-32 check value of "123456789".
        assert_eq!(entry, FileEntry::new(STATE_FILE, 9, 0xcbf4_3926));
        assert_eq!(crc_of_file(&dir.join(STATE_FILE)).expect("crc"), (9, 0xcbf4_3926));
        write_manifest(&dir, vec![entry]);
        assert_eq!(verify(&dir).expect("verifies").files.len(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn manifests_naming_paths_twice_listed_files_or_bad_crcs_are_refused() {
        let dir = folder("names");
        let entry = write_file(&dir, STATE_FILE, |w| w.write_all(b"step = 1\n")).expect("write");
        for (files, expect) in [
            (vec![FileEntry { name: "../x".to_owned(), ..entry.clone() }], "not a checkpoint file name"),
            (vec![FileEntry { name: MANIFEST.to_owned(), ..entry.clone() }], "not a checkpoint file name"),
            (vec![entry.clone(), entry.clone()], "twice"),
            (vec![FileEntry { crc32: "12".to_owned(), ..entry.clone() }], "8 hex digits"),
        ] {
            write_manifest(&dir, files);
            let err = verify(&dir).expect_err(expect).to_string();
            assert!(err.contains(expect) && err.contains(&dir.join(MANIFEST).display().to_string()), "{err}");
        }
        std::fs::write(dir.join(MANIFEST), "{\"format\": 1,").expect("write");
        assert!(matches!(verify(&dir), Err(CheckpointError::BadManifest { .. })));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
