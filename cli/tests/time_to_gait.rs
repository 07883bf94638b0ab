//! `vge time-to-gait` on the default config's committed seeds: the table, the JSON the
//! results write-ups read, and a threshold that is not a share refused.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_owned()
}

fn time_to_gait(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge"))
        .arg("time-to-gait")
        .args(args)
        .current_dir(repo())
        .output()
        .expect("vge runs")
}

#[test]
fn the_stored_seeds_give_the_median_and_table_is_held_out_iqm() {
    let out = time_to_gait(&["docs/results/cube-fg-vge-seeds", "--name", "fg/vge"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        text.contains("docs/results/cube-fg-vge-seeds/seed-4 | 4 | 600k (0.55) | 1,791 | 335.1 | one |"),
        "{text}"
    );
    assert!(
        text.contains("fg/vge: median time to a gait 1,719 s, at 700k env steps (6 of 6 runs counted)"),
        "{text}"
    );
    assert!(
        text.contains("selected policies' held-out success (6 scored runs): IQM 0.80 [0.73, 0.91]"),
        "{text}"
    );

    let out = time_to_gait(&[
        "docs/results/cube-fg-vge-seeds/seed-0",
        "docs/results/cube-fg-vge-seeds/seed-5",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let steps: Vec<u64> = json["runs"]
        .as_array()
        .expect("runs")
        .iter()
        .map(|r| r["first_pass"]["step"].as_u64().expect("a step"))
        .collect();
    assert_eq!(steps, [700_000, 800_000]);
    assert_eq!(json["runs"][1]["one_session"], true);
    assert_eq!(json["group"]["median_step"], 750_000.0);
}

#[test]
fn a_threshold_that_is_not_a_share_is_refused() {
    let out = time_to_gait(&["docs/results/cube-fg-vge-seeds", "--success", "50"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("--success 50: a share of episodes, from 0 to 1"), "{stderr}");
}
