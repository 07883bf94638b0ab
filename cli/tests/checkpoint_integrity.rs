//! Checkpoints carry a manifest (every file's length and CRC-32), and a resume checks the
//! folder against it before reading any file: a flipped byte, a truncated file, a missing or
//! extra file or a missing manifest is refused with the file's name, and the refused resume
//! writes nothing. Real tiny runs, real libtorch files, the library's `train` and the `vge`
//! binary.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};

use vge_run::config::{Config, load_config};
use vge_trainer::checkpoint::{self, CheckpointError};
use vge_trainer::train::{TrainError, train};

/// Where the run stops (with a checkpoint) and where a resume ends.
const STOP_AT: u64 = 120;
const TOTAL: u64 = 140;

/// `configs/cube-fg-vge.toml` with the shared tiny overrides (`algorithm` when given).
fn config(algorithm: Option<&str>) -> Config {
    let mut overrides: Vec<String> = common::TINY.iter().map(|s| (*s).to_owned()).collect();
    // A checkpoint boundary at `STOP_AT`: the stop keeps the periodic checkpoint (no episodes
    // in progress), whose files this test lists.
    overrides.extend(["sac.threads=1".to_owned(), "run.checkpoint_interval=60".to_owned()]);
    if let Some(a) = algorithm {
        overrides.push(format!("algorithm=\"{a}\""));
    }
    let mut c = load_config(&common::config("cube-fg-vge.toml"), &overrides).expect("config");
    c.total_steps = TOTAL;
    c.validate().expect("valid");
    c
}

/// A run stopped at `STOP_AT` with its checkpoint (replay buffer included), in
/// `temp/ckpt-integrity-{name}/run`; its checkpoint verifies and lists every file.
fn run_copy(name: &str, algorithm: &'static str) -> PathBuf {
    let dir = common::temp_dir(&format!("ckpt-integrity-{name}")).join("run");
    let stop = AtomicBool::new(false);
    let summary = train(&config(Some(algorithm)), &dir, false, &stop, &mut |p| {
        if p.step >= STOP_AT {
            stop.store(true, Ordering::SeqCst);
        }
    })
    .expect("tiny run");
    assert!(summary.stopped && summary.steps == STOP_AT);
    let manifest = checkpoint::verify(&dir.join("checkpoint")).expect("a fresh checkpoint verifies");
    let names: Vec<&str> = manifest.files.iter().map(|f| f.name.as_str()).collect();
    let mut expected = vec!["actor.ot", "critic.ot", "target.ot"];
    if algorithm == "td3" {
        expected.push("target_actor.ot");
    }
    expected.extend(["optim.ot", "replay.bin", "state.toml"]);
    assert_eq!(names, expected);
    for f in &manifest.files {
        let len = std::fs::metadata(dir.join("checkpoint").join(&f.name)).expect("file").len();
        assert_eq!(len, f.bytes, "{}", f.name);
    }
    assert!(!dir.join("checkpoint.tmp").exists() && !dir.join("checkpoint.old").exists());
    dir
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read_dir") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("type").is_dir() {
            copy_tree(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

/// Every file under `dir` with its bytes, but `vge.lock`: the lock of the folder, which
/// names the last process that wrote, or tried to write, it.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("read_dir") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().is_some_and(|n| n == vge_run::run_dir::lock::LOCK_FILE) {
                continue;
            } else {
                let bytes = std::fs::read(&path).expect("read");
                files.insert(path, bytes);
            }
        }
    }
    files
}

fn flip_byte(path: &Path, at: usize) {
    let mut bytes = std::fs::read(path).expect("read");
    bytes[at] ^= 0x01;
    std::fs::write(path, bytes).expect("write");
}

fn file_len(path: &Path) -> usize {
    std::fs::metadata(path).expect("metadata").len() as usize
}

/// Resumes `dir` with the library, expects a checkpoint error naming `file`, and checks that
/// the run directory is byte for byte what it was. Returns the message.
fn refused(dir: &Path, algorithm: &'static str, file: &Path) -> String {
    let before = snapshot(dir);
    let never = AtomicBool::new(false);
    let err = train(&config(Some(algorithm)), dir, true, &never, &mut |_| {})
        .expect_err("a damaged checkpoint must not be resumed");
    let msg = err.to_string();
    assert!(matches!(err, TrainError::Checkpoint(_)), "{err:?}");
    assert!(msg.contains(&file.display().to_string()), "the error names {}: {msg}", file.display());
    assert!(msg.contains("refusing to resume"), "{msg}");
    assert!(snapshot(dir) == before, "a refused resume changed the run directory");
    assert!(!dir.join("policy.vgep").exists());
    msg
}

/// `vge train --resume dir`: exit status and stderr.
fn vge_resume(dir: &Path) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["train", "--resume"])
        .arg(dir)
        .output()
        .expect("vge runs");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn a_flipped_byte_in_the_replay_buffer_is_refused() {
    let dir = run_copy("replay", "sac");
    let file = dir.join("checkpoint/replay.bin");
    // In the stored transitions, past the 48-byte header: the loader alone would accept it.
    flip_byte(&file, file_len(&file) / 2);
    let msg = refused(&dir, "sac", &file);
    assert!(msg.contains("is corrupt: crc32 0x"), "{msg}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn a_flipped_byte_in_the_critic_is_refused_by_train_and_by_the_cli() {
    let dir = run_copy("critic", "sac");
    let file = dir.join("checkpoint/critic.ot");
    flip_byte(&file, file_len(&file) / 2);
    let msg = refused(&dir, "sac", &file);
    assert!(msg.contains("is corrupt: crc32 0x"), "{msg}");

    let before = snapshot(&dir);
    let (ok, stderr) = vge_resume(&dir);
    assert!(!ok, "vge train --resume exits non-zero\n{stderr}");
    assert!(stderr.contains(&format!("checkpoint file {} is corrupt", file.display())), "{stderr}");
    assert!(snapshot(&dir) == before, "the refused CLI resume changed the run directory");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn a_truncated_actor_is_refused_with_its_name_not_a_libtorch_backtrace() {
    let dir = run_copy("actor", "sac");
    let file = dir.join("checkpoint/actor.ot");
    let bytes = std::fs::read(&file).expect("read");
    std::fs::write(&file, &bytes[..bytes.len() / 2]).expect("truncate");
    let msg = refused(&dir, "sac", &file);
    assert!(
        msg.contains(&format!("is truncated: {} bytes, expected {}", bytes.len() / 2, bytes.len())),
        "{msg}"
    );

    let (ok, stderr) = vge_resume(&dir);
    assert!(!ok, "vge train --resume exits non-zero\n{stderr}");
    assert!(stderr.contains(&format!("checkpoint file {} is truncated", file.display())), "{stderr}");
    assert!(!stderr.contains("libtorch") && !stderr.contains("frame #"), "{stderr}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn a_checkpoint_without_a_manifest_is_refused_as_unverified() {
    let dir = run_copy("manifest", "sac");
    let file = dir.join("checkpoint/manifest.json");
    std::fs::remove_file(&file).expect("rm");
    let msg = refused(&dir, "sac", &file);
    assert!(msg.contains("without checkpoint integrity checks"), "{msg}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn a_missing_file_and_an_unlisted_file_are_refused() {
    // TD3: a listed network deleted.
    let dir = run_copy("missing", "td3");
    let file = dir.join("checkpoint/target_actor.ot");
    std::fs::remove_file(&file).expect("rm");
    let msg = refused(&dir, "td3", &file);
    assert!(msg.contains("is missing"), "{msg}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));

    // SAC: a file of a checkpoint's kind the manifest does not list.
    let dir = run_copy("unlisted", "sac");
    let file = dir.join("checkpoint/target_actor.ot");
    std::fs::copy(dir.join("checkpoint/actor.ot"), &file).expect("copy");
    let msg = refused(&dir, "sac", &file);
    assert!(msg.contains("is not listed in manifest.json"), "{msg}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn a_damaged_checkpoint_is_refused_even_with_a_whole_checkpoint_old_beside_it() {
    let dir = run_copy("no-fallback", "sac");
    copy_tree(&dir.join("checkpoint"), &dir.join("checkpoint.old"));
    let file = dir.join("checkpoint/state.toml");
    flip_byte(&file, file_len(&file) / 2);
    let msg = refused(&dir, "sac", &file);
    assert!(msg.contains("is corrupt"), "{msg}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn an_interrupted_swap_resumes_from_checkpoint_old_after_verifying_it() {
    // Killed between the two renames of a save: only checkpoint.old/ (and checkpoint.tmp/).
    let dir = run_copy("old", "sac");
    std::fs::rename(dir.join("checkpoint"), dir.join("checkpoint.old")).expect("rename");
    let file = dir.join("checkpoint.old/replay.bin");
    let clean = std::fs::read(&file).expect("read");
    flip_byte(&file, clean.len() - 1);
    let msg = refused(&dir, "sac", &file);
    assert!(msg.contains("is corrupt"), "{msg}");

    std::fs::write(&file, clean).expect("restore");
    let never = AtomicBool::new(false);
    let resumed =
        train(&config(Some("sac")), &dir, true, &never, &mut |_| {}).expect("resumes from checkpoint.old");
    assert_eq!(resumed.steps, TOTAL);
    assert!(dir.join("policy.vgep").exists());
    checkpoint::verify(&dir.join("checkpoint")).expect("the final checkpoint verifies");
    assert!(!dir.join("checkpoint.old").exists() && !dir.join("checkpoint.tmp").exists());
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn an_untouched_checkpoint_resumes_to_the_uninterrupted_runs_policy() {
    let dir = run_copy("untouched", "sac");
    let never = AtomicBool::new(false);
    let resumed = train(&config(Some("sac")), &dir, true, &never, &mut |_| {}).expect("resume");
    assert_eq!(resumed.steps, TOTAL);
    assert!(!resumed.stopped);
    let policy = std::fs::read(dir.join("policy.vgep")).expect("policy");

    let full_dir = common::temp_dir("ckpt-integrity-full");
    let full = train(&config(Some("sac")), &full_dir, false, &never, &mut |_| {}).expect("uninterrupted run");
    assert_eq!(full.updates, resumed.updates);
    assert!(
        std::fs::read(full_dir.join("policy.vgep")).expect("policy") == policy,
        "resume changed the policy"
    );
    let _ = std::fs::remove_dir_all(&full_dir);
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

#[test]
fn a_run_without_a_checkpoint_is_refused_with_a_typed_error() {
    let dir = run_copy("typed", "sac");
    std::fs::remove_dir_all(dir.join("checkpoint")).expect("rm");
    let never = AtomicBool::new(false);
    let err = train(&config(Some("sac")), &dir, true, &never, &mut |_| {}).expect_err("no checkpoint");
    assert!(matches!(err, TrainError::Checkpoint(CheckpointError::NoCheckpoint { .. })), "{err:?}");
    let _ = std::fs::remove_dir_all(dir.parent().expect("root"));
}

/// Timing of a checkpoint with a full default-sized replay buffer (1M transitions, 656 MB)
/// and the default networks: `cargo test --release -p vge-trainer --test
/// checkpoint_integrity -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement: writes about 1.3 GB"]
fn measure_save_and_verify_with_a_full_replay_buffer() {
    use std::time::Instant;
    use vge_trainer::learner;
    use vge_trainer::replay::{ReplayBuffer, Source};

    let c = Config::default();
    let n = c.sac.buffer_size;
    let learner_config = vge_trainer::learner::LearnerConfig::for_hand(&c).expect("sizes");
    let (obs_dim, act_dim) = (learner_config.columns.row_dim() as usize, learner_config.net.act_dim as usize);
    let sac = learner::build_seeded(learner_config.clone(), tch::Device::Cpu, 0).expect("sac");
    let mut replay = ReplayBuffer::new(n, obs_dim, act_dim).expect("replay");
    let mut obs = vec![0.0f32; obs_dim];
    let action = vec![0.1f32; act_dim];
    for k in 0..n {
        obs[k % obs_dim] = k as f32;
        replay.push(&obs, &action, 0.5, &obs, false, Source::Learner, Some(&action)).expect("push");
    }
    let root = common::temp_dir("ckpt-measure");
    let state = "step = 1\n";

    let t = Instant::now();
    replay.save(&root.join("replay-alone.bin")).expect("save");
    let replay_alone = t.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(root.join("replay-alone.bin"));

    let mut saves = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        checkpoint::save(&root, sac.as_ref(), Some(&replay), state, None).expect("checkpoint");
        saves.push(t.elapsed().as_secs_f64());
    }
    let dir = root.join("checkpoint");
    let mut verifies = Vec::new();
    let mut manifest = None;
    for _ in 0..3 {
        let t = Instant::now();
        manifest = Some(checkpoint::verify(&dir).expect("verify"));
        verifies.push(t.elapsed().as_secs_f64());
    }
    let bytes: u64 = manifest.expect("manifest").files.iter().map(|f| f.bytes).sum();
    let t = Instant::now();
    let mut sac2 = learner::build_seeded(learner_config, tch::Device::Cpu, 1).expect("sac");
    let mut replay2 = ReplayBuffer::new(n, obs_dim, act_dim).expect("replay");
    let ckpt = checkpoint::open(&root).expect("open");
    let open_s = t.elapsed().as_secs_f64();
    ckpt.load(sac2.as_mut(), Some(&mut replay2)).expect("load");
    let load_s = t.elapsed().as_secs_f64() - open_s;
    assert_eq!(replay2.len(), n);
    println!(
        "checkpoint of {n} transitions, {:.1} MB in all: replay.save alone {replay_alone:.3} s; \
         checkpoint::save (networks, replay, state, CRCs, manifest, swap) {saves:.3?} s; \
         verify (warm page cache) {verifies:.3?} s = {:.2} GB/s; resume: open (verify) {open_s:.3} s + load {load_s:.3} s",
        bytes as f64 / 1e6,
        bytes as f64 / 1e9 / verifies.iter().copied().fold(f64::INFINITY, f64::min),
    );
    let _ = std::fs::remove_dir_all(&root);
}
