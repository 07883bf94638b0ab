//! Policy files through `vge eval` and `vge-bridge run`: one that passes every load check
//! (valid CRC, finite weights) but overflows inside its first layer at run time must be
//! refused, not have ReLU turn the NaN into 0 and move the hand; the stored gait must turn
//! the cube and switch contacts.

use std::path::{Path, PathBuf};
use std::process::Command;

use vge_export::PolicyFile;

/// A workspace binary next to this test's executable (target/<profile>/deps/..).
fn workspace_bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe.parent().and_then(|deps| deps.parent()).expect("target/<profile>/deps");
    dir.join(name)
}

/// `vge export --init --seed SEED` into `dir`, read back.
fn exported_init(dir: &Path, seed: u64) -> PolicyFile {
    let plain = dir.join(format!("init-{seed}.vgep"));
    let out = Command::new(workspace_bin("vge"))
        .args(["export", "--init", "--seed", &seed.to_string(), "--out"])
        .arg(&plain)
        .output()
        .expect("vge export runs");
    assert!(out.status.success(), "vge export failed: {}", String::from_utf8_lossy(&out.stderr));
    PolicyFile::read(&plain).expect("a valid policy file")
}

/// An untrained hand policy from `vge export --init`, whose first layer then gets ±3e38 in
/// every row's first two weights: any observation with those inputs at about 1 or more
/// gives inf - inf = NaN in every unit.
fn overflowing_policy(dir: &Path) -> PathBuf {
    let mut file = exported_init(dir, 1);
    let first = &mut file.layers[0];
    let n_in = first.in_dim as usize;
    for row in first.weights.chunks_exact_mut(n_in) {
        row[0] = 3.0e38;
        row[1] = -3.0e38;
    }
    // Observations 0 and 1 are joint angles near 0 in a grasp: normalise them so that they
    // read as large inputs and the products overflow.
    file.obs_mean[0] = -10.0;
    file.obs_mean[1] = -10.0;
    let path = dir.join("overflowing.vgep");
    std::fs::write(&path, file.to_bytes().expect("encodes with a valid CRC")).expect("write");
    let inspect =
        Command::new(workspace_bin("vge")).arg("inspect").arg(&path).output().expect("vge inspect runs");
    assert!(
        inspect.status.success(),
        "the crafted file must load: {}",
        String::from_utf8_lossy(&inspect.stderr)
    );
    path
}

#[test]
fn a_policy_that_overflows_inside_is_refused_by_eval_and_halts_the_bridge() {
    let dir = std::env::temp_dir().join(format!("vge-overflow-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let policy = overflowing_policy(&dir);

    let eval = Command::new(workspace_bin("vge"))
        .args(["eval", "--policy"])
        .arg(&policy)
        .args(["--episodes", "1", "--episode-s", "1"])
        .output()
        .expect("vge eval runs");
    let stderr = String::from_utf8_lossy(&eval.stderr);
    assert!(!eval.status.success(), "vge eval must fail on a policy that overflows: {stderr}");
    assert!(stderr.contains("layer 0") && stderr.contains("not finite"), "{stderr}");

    let run = Command::new(workspace_bin("vge-bridge"))
        .args(["run", "--backend", "sim", "--duration", "3", "--json", "--policy"])
        .arg(&policy)
        .output()
        .expect("vge-bridge runs");
    let report = String::from_utf8_lossy(&run.stdout);
    // A safety halt: the summary, and policy_failure's exit status (docs/can-protocol.md).
    assert_eq!(run.status.code(), Some(15), "{}", String::from_utf8_lossy(&run.stderr));
    let json: serde_json::Value = serde_json::from_str(report.trim()).expect("one JSON line");
    assert_eq!(json["stop_reason"], "policy_failure", "{report}");
    assert!(json["stop_detail"].as_str().is_some_and(|d| d.contains("layer 0")), "{report}");
    assert_eq!(json["steps"], 5, "five held periods, then the halt: {report}");
    assert_eq!(json["terminated"], false, "the hand held the object: {report}");
    assert!(json["rotation_rad"].as_f64().is_some_and(|r| r.abs() < 0.05), "{report}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The contrast: the gait that ships (policies/cube.vgep) through the bridge on the simulated
/// hand turns the cube and switches contacts.
#[test]
fn the_shipped_gait_turns_the_cube_and_switches_contacts_through_the_bridge() {
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../policies/cube.vgep");
    let run = Command::new(workspace_bin("vge-bridge"))
        .args(["run", "--backend", "sim", "--duration", "10", "--json", "--policy", policy])
        .output()
        .expect("vge-bridge runs");
    let report = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let json: serde_json::Value = serde_json::from_str(report.trim()).expect("one JSON line");
    assert_eq!(json["stop_reason"], "duration", "{report}");
    // In the success test this policy turns the cube ~0.37 rad/s with ~1.4 switches per second.
    assert!(json["rotation_rad"].as_f64().is_some_and(|r| r > 2.0), "{report}");
    assert!(json["contact_switches"].as_u64().is_some_and(|n| n >= 5), "{report}");
}

/// A policy whose observation slices are in another order (same size, other meaning) is
/// refused by eval and the bridge before it runs.
#[test]
fn a_policy_observing_another_layout_is_refused() {
    let dir = std::env::temp_dir().join(format!("vge-layout-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut file = exported_init(&dir, 4);
    // q_rad and q_target_rad are both 15 wide: swap their names.
    let (a, b) = (file.obs_layout[0].name.clone(), file.obs_layout[1].name.clone());
    file.obs_layout[0].name = b;
    file.obs_layout[1].name = a;
    let swapped = dir.join("swapped.vgep");
    std::fs::write(&swapped, file.to_bytes().expect("encodes")).expect("write");

    let eval = Command::new(workspace_bin("vge"))
        .args(["eval", "--episodes", "1", "--episode-s", "0.5", "--policy"])
        .arg(&swapped)
        .output()
        .expect("vge eval runs");
    let err = String::from_utf8_lossy(&eval.stderr);
    assert!(!eval.status.success() && err.contains("the policy observes [q_target_rad 0..15"), "{err}");
    let run = Command::new(workspace_bin("vge-bridge"))
        .args(["run", "--backend", "sim", "--duration", "1", "--policy"])
        .arg(&swapped)
        .output()
        .expect("vge-bridge runs");
    let err = String::from_utf8_lossy(&run.stderr);
    // The bridge reads the set from the layout as eval does, and refuses it in the same words.
    assert!(!run.status.success() && err.contains("the policy observes [q_target_rad 0..15"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
