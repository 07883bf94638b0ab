//! The `vge-bridge` command line where it refuses before touching a bus: bad hand files, and
//! the simulator asked of a build without it.

use std::path::PathBuf;
use std::process::{Command, Output};

fn bridge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge-bridge")).args(args).output().expect("runs vge-bridge")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A hand file in the temp dir, unique to this test, removed when dropped.
struct HandFile(PathBuf);

impl HandFile {
    fn new(name: &str, text: &str) -> Self {
        let path = std::env::temp_dir().join(format!("vge-bridge-cli-{}-{name}.toml", std::process::id()));
        std::fs::write(&path, text).expect("writes the hand file");
        Self(path)
    }
}

impl Drop for HandFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[test]
fn run_refuses_a_bad_hand_file_naming_the_file_and_the_joint() {
    let mut rows = vec!["[-0.5, 0.5]"; 15];
    rows[4] = "[1.6, -0.3]";
    let inverted = HandFile::new("inverted", &format!("joint_limits_rad = [{}]", rows.join(", ")));
    let short = HandFile::new("short", &format!("joint_limits_rad = [{}]", rows[..14].join(", ")));
    for (file, what) in [
        (&inverted, "joint 4 (index.flex_prox): lower limit 1.6 rad is not below upper limit -0.3 rad"),
        (&short, "joint_limits_rad lists 14 joints; the hand vge15 has 15: thumb.roll, thumb.flex_prox"),
    ] {
        let hand = file.0.to_str().expect("utf-8 path");
        let out = bridge(&["run", "--policy", "/nonexistent.vgep", "--backend", "can", "--hand", hand]);
        assert!(!out.status.success());
        let err = stderr(&out);
        assert!(err.contains(&format!("hand file {hand}")) && err.contains(what), "{err}");
    }
    let out =
        bridge(&["run", "--policy", "/nonexistent.vgep", "--backend", "can", "--hand", "/nonexistent.toml"]);
    assert!(stderr(&out).contains("hand file /nonexistent.toml: reading the hand file"), "{}", stderr(&out));
}

#[test]
fn run_help_documents_the_hand_file_and_the_default_limits() {
    let out = bridge(&["run", "--help"]);
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("--hand <HAND|FILE>") && help.contains("joint_limits_rad"), "{help}");
    assert!(help.contains("thumb    [-0.500, +0.500] [-0.300, +1.600] [-0.300, +1.600]"), "{help}");
}

/// The Allegro runs none of vge15's options that do not apply to it: each refusal says why and
/// what to use instead, before any bus is touched.
#[test]
fn run_and_emulate_for_the_allegro_refuse_what_does_not_apply_saying_why() {
    for (args, why) in [
        (
            &["run", "--hand", "allegro", "--backend", "can", "--policy", "/nonexistent.vgep"][..],
            "reading policy file /nonexistent.vgep",
        ),
        (&["run", "--hand", "allegro", "--hold", "--fd"], "the Allegro speaks classic CAN"),
        (&["run", "--hand", "allegro", "--hold", "--record", "x.jsonl"], "the Allegro's is not recorded"),
        (&["run", "--hand", "allegro", "--hold", "--squeeze-rad", "5"], "--squeeze-rad must be"),
        (&["run", "--hand", "allegro", "--hold", "--kv-nms-per-rad=-1"], "--kv-nms-per-rad must be"),
        (&["run", "--policy", "/nonexistent.vgep", "--kv-nms-per-rad", "0.1"], "sets the Allegro's PD loop"),
        (&["run", "--hold"], "--hold holds the Allegro's grasp (--hand allegro)"),
        (&["emulate", "--hand", "allegro", "--model", "lag"], "the Allegro is torque-driven"),
        (&["emulate", "--hand", "allegro", "--fd"], "the Allegro speaks classic CAN"),
        (&["emulate", "--hand", "allegro", "--restart-node", "1"], "the Allegro has none"),
    ] {
        let out = bridge(args);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(why), "{args:?}: {}", stderr(&out));
    }
    let out = bridge(&["run", "--hand", "allegro", "--hold", "--policy", "/nonexistent.vgep"]);
    assert_eq!(out.status.code(), Some(2), "--hold and --policy conflict: {}", stderr(&out));
    let out = bridge(&["run", "--hand", "allegro"]);
    assert_eq!(out.status.code(), Some(2), "a policy or --hold is required: {}", stderr(&out));
    // No interface: a clear error after the loop's settings were accepted. Without the
    // simulator's statics --hold cannot press, and says to squeeze instead.
    let hold = ["run", "--hand", "allegro", "--hold", "--backend", "can", "--iface", "vcan-absent"];
    let out = bridge(&hold);
    assert_eq!(out.status.code(), Some(1));
    if cfg!(feature = "sim") {
        assert!(stderr(&out).contains("opening CAN interface vcan-absent"), "{}", stderr(&out));
    } else {
        assert!(stderr(&out).contains("--squeeze-rad R squeezes"), "{}", stderr(&out));
    }
    let out = bridge(&[&hold[..], &["--squeeze-rad", "0.05"]].concat());
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("opening CAN interface vcan-absent"), "{}", stderr(&out));
}

#[cfg(not(feature = "sim"))]
#[test]
fn without_the_sim_feature_asking_for_the_simulator_is_a_clear_error() {
    for args in [
        &["run", "--policy", "/nonexistent.vgep"][..],
        &["run", "--policy", "/nonexistent.vgep", "--backend", "sim", "--object", "sphere"],
        &["emulate", "--model", "sim"],
        &["run", "--hand", "allegro", "--hold"],
        &["emulate", "--hand", "allegro"],
    ] {
        let out = bridge(args);
        assert!(!out.status.success());
        let err = stderr(&out);
        assert!(
            err.contains("needs the simulator, and this vge-bridge was built without it"),
            "{args:?}: {err}"
        );
    }
}

/// `run --record` writes nothing it cannot write right: not over CAN (the object is not on
/// the bus), not into a `.rrd` name (a recording is vge's own file), not from a build without
/// the simulator.
#[test]
fn run_record_is_refused_over_can_and_where_it_cannot_record() {
    let rrd = std::env::temp_dir().join(format!("vge-bridge-cli-{}.rrd", std::process::id()));
    let rrd_arg = rrd.to_str().expect("utf-8 path");
    let out = bridge(&["run", "--policy", "/nonexistent.vgep", "--backend", "can", "--record", rrd_arg]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--record needs --backend sim"), "{}", stderr(&out));
    let out = bridge(&["run", "--policy", "/nonexistent.vgep", "--record", rrd_arg]);
    assert!(!out.status.success());
    let expected = if cfg!(feature = "sim") {
        "python -m vge.recording"
    } else {
        "needs the simulator, and this vge-bridge was built without it"
    };
    assert!(stderr(&out).contains(expected), "{}", stderr(&out));
    assert!(!rrd.exists(), "nothing written");
}

#[test]
fn run_refuses_a_seq_lag_outside_1_to_127_naming_the_flag() {
    for bad in ["0", "128", "many"] {
        let out = bridge(&["run", "--policy", "/nonexistent.vgep", "--backend", "can", "--max-seq-lag", bad]);
        assert_eq!(out.status.code(), Some(2), "clap's usage error for {bad}");
        let err = stderr(&out);
        assert!(err.contains("--max-seq-lag") && err.contains(bad), "{err}");
    }
    let help = bridge(&["run", "--help"]);
    assert!(String::from_utf8_lossy(&help.stdout).contains("--max-seq-lag <MAX_SEQ_LAG>"));
}

#[test]
fn run_refuses_times_and_rates_no_clock_holds_with_an_error_naming_the_flag_not_a_panic() {
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
    for (flag, value) in [
        ("--duration", "1e20"),
        ("--heartbeat-timeout-s", "1e300"),
        ("--rate", "1e-20"),
        ("--startup-timeout-s", "1e300"),
        ("--startup-timeout-s", "inf"),
    ] {
        let out =
            bridge(&["run", "--policy", policy, "--backend", "can", "--iface", "vcan-absent", flag, value]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{flag} {value}: an error, not a panic (101): {err}");
        assert!(err.contains(flag), "{flag} {value}: {err}");
    }
    let allegro_policy =
        concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/policies/allegro-proprio2-init.vgep");
    for value in ["0", "nan"] {
        let out = bridge(&[
            "run",
            "--hand",
            "allegro",
            "--policy",
            allegro_policy,
            "--backend",
            "can",
            "--iface",
            "vcan-absent",
            "--startup-timeout-s",
            value,
        ]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "allegro --startup-timeout-s {value}: {err}");
        assert!(err.contains("--startup-timeout-s"), "{value}: {err}");
    }
}
