//! `vge config show`: a shipped config resolved as training reads it, with the hash that
//! tests/fixtures/config-hashes.txt records for it, and overrides that change both.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_owned()
}

fn show(args: &[&str]) -> (toml::Table, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["config", "show"])
        .args(args)
        .current_dir(repo())
        .output()
        .expect("vge runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let hash = text.lines().last().and_then(|l| l.strip_prefix("# hash ")).expect("a hash line").to_owned();
    (text.parse().expect("the output is TOML"), hash)
}

fn recorded_hash(config: &str) -> String {
    let fixture = std::fs::read_to_string(repo().join("tests/fixtures/config-hashes.txt")).expect("fixture");
    fixture
        .lines()
        .find_map(|l| l.strip_prefix(config)?.strip_prefix(' ').map(str::to_owned))
        .expect("the config is in the fixture")
}

#[test]
fn a_shipped_config_resolves_to_its_recorded_hash_and_overrides_change_it() {
    for config in ["configs/cube-fg-vge.toml", "configs/cube-fg-fge-robust-finetune.toml"] {
        let (table, hash) = show(&[config]);
        assert_eq!(hash, recorded_hash(config), "{config}");
        assert!(!table.contains_key("base"), "resolved: no base left");
        assert!(table.contains_key("env") && table.contains_key("sac"), "every section written");
    }
    let (table, hash) = show(&["configs/cube-fg-vge.toml", "--set", "total_steps=5000"]);
    assert_eq!(table["total_steps"].as_integer(), Some(5000));
    assert_ne!(hash, recorded_hash("configs/cube-fg-vge.toml"));
    let out = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["config", "show", "configs/cube-fg-vge.toml", "--set", "no_such_key=1"])
        .current_dir(repo())
        .output()
        .expect("vge runs");
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("no_such_key"));
}
