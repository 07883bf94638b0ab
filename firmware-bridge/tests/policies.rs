//! `vge-bridge run` with policy files for one hand or another: a policy drives only the hand it
//! was made for, and only with an observation the hand can give over its link. The Allegro
//! has no fingertip sensors, so over its CAN only `proprio` policies run; the simulated
//! Allegro runs either. Refusals come before any bus is opened (the interfaces here do not
//! exist) and name the hand.

#[path = "support/policy_files.rs"]
mod policy_files;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use policy_files::write_policy;
use vge_sim::observation::ObservationSet;

fn bridge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge-bridge")).args(args).output().expect("runs vge-bridge")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A directory of this test's own, removed when dropped.
struct Dir(PathBuf);

impl Dir {
    fn new(name: &str) -> Self {
        Self(std::env::temp_dir().join(format!("vge-bridge-policies-{}-{name}", std::process::id())))
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn hand(name: &str) -> std::sync::Arc<vge_hand::Hand> {
    vge_sim::hands::load(name).expect("a shipped hand")
}

fn arg(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

const PROPRIO_2: ObservationSet = ObservationSet::Proprio { history: 2 };
/// vge15's trained policy (full observation).
const VGE15_POLICY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");

#[test]
fn a_full_observation_policy_is_refused_on_the_allegros_can_saying_it_has_no_fingertip_sensors() {
    let dir = Dir::new("full-on-can");
    let allegro = hand("allegro");
    let full = write_policy(&dir.0, &allegro, ObservationSet::Full, 1);
    let out = bridge(&[
        "run",
        "--hand",
        "allegro",
        "--backend",
        "can",
        "--iface",
        "vcan-absent",
        "--policy",
        arg(&full),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let no_sensors = format!("the hand {} has no fingertip sensors", allegro.name());
    assert!(err.contains(&no_sensors) && err.contains("`proprio` observation set"), "{err}");
    assert!(!err.contains("opening CAN interface"), "refused before the bus: {err}");
    // A proprio policy passes the check and gets as far as the interface.
    let proprio = write_policy(&dir.0, &hand("allegro"), PROPRIO_2, 1);
    let out = bridge(&[
        "run",
        "--hand",
        "allegro",
        "--backend",
        "can",
        "--iface",
        "vcan-absent",
        "--policy",
        arg(&proprio),
    ]);
    assert!(stderr(&out).contains("opening CAN interface vcan-absent"), "{}", stderr(&out));
}

/// The Allegro's untrained `proprio:2` actor as `vge export --init` wrote it (the fixture the
/// HIL test runs).
const ALLEGRO_PROPRIO_FIXTURE: &str =
    concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/policies/allegro-proprio2-init.vgep");

/// What a `proprio` policy file of vge's exporter asks for as input: the joint angles and
/// targets now and at its past steps, no fingertip contact, so the bridge feeds it over the
/// Allegro's CAN (no tip sensing); the same hand's `full` file is refused there.
#[test]
fn an_allegro_proprio_policy_file_has_no_contact_inputs_and_runs_without_tip_sensing() {
    let allegro = hand("allegro");
    let bytes = std::fs::read(ALLEGRO_PROPRIO_FIXTURE).expect("the fixture policy");
    let info = vge_runtime::policy::inspect(&bytes).expect("a valid policy file");
    let names: Vec<&str> = info.obs_layout.iter().map(|s| s.name).collect();
    assert_eq!(names, ["q_rad", "q_target_rad", "q_rad_past", "q_target_rad_past"]);
    assert!(!names.iter().any(|n| n.starts_with("contact")), "{names:?}");
    let joints = allegro.num_joints();
    assert_eq!(info.obs_dim, 2 * joints + 2 * 2 * joints, "joints and targets, now and 2 steps back");
    assert_eq!(info.task.as_ref().map(|t| t.observation_set), Some("proprio:2"));
    let feed =
        vge_bridge::policy_runner::check_policy(&info, &allegro, false).expect("runs without tip sensing");
    assert_eq!(feed.set, PROPRIO_2);
    assert!(!feed.layout.needs_tip_sensing());
    // The full observation of the same hand has the contact slices, and is refused without.
    let full_bytes = policy_files::policy_bytes(&allegro, ObservationSet::Full, 1);
    let full = vge_runtime::policy::inspect(&full_bytes).expect("a valid policy file");
    assert!(full.obs_layout.iter().any(|s| s.name.starts_with("contact")));
    let err = vge_bridge::policy_runner::check_policy(&full, &allegro, false).expect_err("no tip sensing");
    assert!(err.contains("has no fingertip sensors"), "{err}");
    assert!(
        vge_bridge::policy_runner::check_policy(&full, &allegro, true).is_ok(),
        "the simulation senses tips"
    );
}

#[test]
fn a_policy_for_one_hand_is_refused_on_the_other_naming_the_hand() {
    let dir = Dir::new("other-hand");
    let allegro_policy = write_policy(&dir.0, &hand("allegro"), PROPRIO_2, 2);
    let vge15_proprio = write_policy(&dir.0, &hand("vge15"), PROPRIO_2, 2);
    let can = ["--backend", "can", "--iface", "vcan-absent"];
    let sim = ["--backend", "sim"];
    let on_allegro = ["run", "--hand", "allegro"];
    let on_vge15 = ["run", "--hand", "vge15"];
    for (command, backend, policy, name, other) in [
        (on_allegro, &can[..], VGE15_POLICY, "allegro", "vge15"),
        (on_allegro, &can[..], arg(&vge15_proprio), "allegro", "vge15"),
        (on_allegro, &sim[..], VGE15_POLICY, "allegro", "vge15"),
        (on_vge15, &can[..], arg(&allegro_policy), "vge15", "allegro"),
        (on_vge15, &sim[..], arg(&allegro_policy), "vge15", "allegro"),
    ] {
        if backend == sim && !cfg!(feature = "sim") {
            continue;
        }
        let args = [&command[..], backend, &["--policy", policy]].concat();
        let (name, other) = (hand(name).name().to_owned(), hand(other).name().to_owned());
        let out = bridge(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(&format!("the policy drives the hand {other}, not {name}")), "{args:?}: {err}");
        assert!(!err.contains("opening CAN interface"), "{args:?}: refused before the bus: {err}");
    }
}

/// The Allegro's protocol cannot carry vge15's fingers and vice versa: a hand description
/// with four joints a finger is refused for vge's protocol, saying where it runs.
#[test]
fn a_hand_description_vges_protocol_cannot_carry_is_refused_saying_why() {
    let xml = concat!(env!("CARGO_MANIFEST_DIR"), "/../hands/allegro.xml");
    let out = bridge(&[
        "run",
        "--hand",
        xml,
        "--backend",
        "can",
        "--iface",
        "vcan-absent",
        "--policy",
        VGE15_POLICY,
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("vge's CAN protocol cannot carry it") && err.contains("--hand allegro"), "{err}");
}

#[cfg(feature = "sim")]
fn json(out: &Output) -> serde_json::Value {
    let line = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(line.trim())
        .unwrap_or_else(|e| panic!("not one JSON line ({e}): {line}\n{}", stderr(out)))
}

/// The simulated Allegro (its env, as policies are trained) runs a proprio policy and a full
/// one, and reports the object's turn, contact switches and whether it dropped.
#[cfg(feature = "sim")]
#[test]
fn the_simulated_allegro_runs_a_proprio_policy_and_reports_the_object() {
    let dir = Dir::new("allegro-sim");
    for (set, seed) in [(PROPRIO_2, 3), (ObservationSet::Full, 4)] {
        let policy = write_policy(&dir.0, &hand("allegro"), set, seed);
        let out = bridge(&[
            "run",
            "--hand",
            "allegro",
            "--backend",
            "sim",
            "--policy",
            arg(&policy),
            "--steps",
            "30",
            "--rate",
            "100",
            "--duration",
            "60",
            "--json",
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        let r = json(&out);
        eprintln!("simulated Allegro, {} policy: {r}", set.name());
        assert_eq!(r["stop_reason"], "steps", "{r}");
        assert_eq!(
            (r["hand"].as_str(), r["backend"].as_str(), r["mode"].as_str()),
            (Some("allegro"), Some("sim"), Some("policy"))
        );
        assert_eq!(r["observation"], set.name(), "{r}");
        assert_eq!(r["steps"], 30);
        assert_eq!(r["sim_steps"], 30, "one env step per control step: {r}");
        assert_eq!((r["holds"].as_u64(), r["policy_errors"].as_u64()), (Some(0), Some(0)), "{r}");
        for key in ["rotation_rad", "contact_switches", "mean_tip_contacts", "dropped", "terminated"] {
            assert!(!r[key].is_null(), "{key} in {r}");
        }
        assert!(r["mean_tip_contacts"].as_f64() > Some(1.5), "the grasp holds the cube: {r}");
        assert_eq!(r["dropped"], false, "small actions for 1.5 s of the hand's time: {r}");
        assert!(stderr(&out).contains("trained at 20 Hz, running it at 100 Hz"), "{}", stderr(&out));
    }
    // The summary in words names the same figures.
    let policy = write_policy(&dir.0, &hand("allegro"), PROPRIO_2, 3);
    let out = bridge(&[
        "run",
        "--hand",
        "allegro",
        "--backend",
        "sim",
        "--policy",
        arg(&policy),
        "--steps",
        "5",
        "--rate",
        "100",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("object:  turned") && text.contains("contact switches"),
        "{text}"
    );
}

/// vge15 runs a proprio policy too: its protocol carries the joints, and the observation is
/// built with its history.
#[cfg(feature = "sim")]
#[test]
fn vge15_runs_a_proprio_policy_over_its_protocol_in_the_sim() {
    let dir = Dir::new("vge15-proprio");
    let policy = write_policy(&dir.0, &hand("vge15"), PROPRIO_2, 5);
    let out = bridge(&[
        "run",
        "--backend",
        "sim",
        "--policy",
        arg(&policy),
        "--steps",
        "20",
        "--rate",
        "50",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let r = json(&out);
    assert_eq!((r["hand"].as_str(), r["stop_reason"].as_str()), (Some("vge15"), Some("steps")), "{r}");
    assert_eq!(r["policy_errors"], 0, "{r}");
}

/// The sim summary says how upright the turn was: the shipped vge15 gait turns its cube about
/// an axis near z, the shipped Allegro policy rolls its cube about a tilted one (its results
/// README), and `rotation_rad` alone cannot tell them apart.
#[cfg(feature = "sim")]
#[test]
fn the_sim_summary_tells_an_upright_turn_from_a_tumble() {
    let allegro_policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/allegro-cube.vgep");
    let tilt_deg = |hand: &str, policy: &str| {
        // 10 s of the hand's time, run at 200 Hz of wall time.
        let out = bridge(&[
            "run",
            "--hand",
            hand,
            "--backend",
            "sim",
            "--policy",
            policy,
            "--steps",
            "200",
            "--rate",
            "200",
            "--json",
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        let r = json(&out);
        eprintln!("{hand}, {policy}: {r}");
        assert_eq!(r["dropped"], false, "{r}");
        assert!(r["rotation_rad"].as_f64() > Some(2.0), "it turns the cube: {r}");
        assert!(r["tip_slip_m"].as_f64() >= Some(0.0), "{r}");
        r["rotation_axis_tilt_rad"].as_f64().expect("the tilt").to_degrees()
    };
    let upright = tilt_deg("vge15", VGE15_POLICY);
    let tumbling = tilt_deg("allegro", allegro_policy);
    assert!(upright < 20.0 && tumbling > 40.0, "vge15 {upright:.1} deg, Allegro {tumbling:.1} deg from z");
}
