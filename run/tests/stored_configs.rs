//! Every config the repository stores loads, validates and keeps its hash: the experiment
//! configs under `configs/` (their bases merged in) and the `config.toml` of every run folder
//! under `docs/results/` and `tests/fixtures/`. The hash ([`Config::hash_hex`], of the
//! canonical TOML) is what a run folder is resumed and compared by, so a change of a default,
//! a key or the canonical form that would change what a stored config means shows up here
//! as a changed hash, naming the file.
//!
//! The expected hashes are in `tests/fixtures/config-hashes.txt`; a config added later only has
//! to load and validate until the fixture is rewritten. After a deliberate change
//! (a new key left out of the canonical TOML at its default keeps every hash), rewrite it with
//! `VGE_BLESS_CONFIG_HASHES=1 cargo test --release -p vge-run --test integration stored_configs`
//! and say why in the commit.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use vge_run::config::load_config;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

const FIXTURE: &str = "tests/fixtures/config-hashes.txt";

/// Every stored config, relative to the repository, sorted.
fn stored_configs() -> Vec<String> {
    let root = repo();
    let mut found = Vec::new();
    let mut stack = vec![root.join("configs"), root.join("docs/results"), root.join("tests/fixtures")];
    while let Some(dir) = stack.pop() {
        let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let in_configs = path.starts_with(root.join("configs"));
            let is_run_config = path.file_name().is_some_and(|n| n == "config.toml");
            if (in_configs && path.extension().is_some_and(|e| e == "toml")) || is_run_config {
                let relative = path.strip_prefix(&root).expect("under the repository");
                found.push(relative.to_string_lossy().into_owned());
            }
        }
    }
    found.sort();
    found
}

/// `path hash` of every stored config, as the fixture lists them.
fn current_hashes() -> BTreeMap<String, String> {
    let root = repo();
    stored_configs()
        .into_iter()
        .map(|relative| {
            let config = load_config(&root.join(&relative), &[])
                .unwrap_or_else(|e| panic!("{relative} no longer loads: {e}"));
            config.validate().unwrap_or_else(|e| panic!("{relative} no longer validates: {e}"));
            (relative, config.hash_hex())
        })
        .collect()
}

#[test]
fn every_stored_config_loads_and_keeps_its_hash() {
    let current = current_hashes();
    assert!(current.len() > 100, "found only {} stored configs", current.len());
    let fixture = repo().join(FIXTURE);
    if std::env::var_os("VGE_BLESS_CONFIG_HASHES").is_some() {
        let text: String = current.iter().map(|(path, hash)| format!("{path} {hash}\n")).collect();
        std::fs::write(&fixture, text).expect("writing the hash fixture");
        return;
    }
    let text = std::fs::read_to_string(&fixture).expect("tests/fixtures/config-hashes.txt");
    let expected: BTreeMap<String, String> = text
        .lines()
        .map(|line| {
            let (path, hash) = line.split_once(' ').expect("`path hash` lines");
            (path.to_owned(), hash.to_owned())
        })
        .collect();
    let mut problems = Vec::new();
    for (path, hash) in &current {
        match expected.get(path) {
            // A config added since the fixture was written: it loads and validates, which is
            // all a new one can be held to.
            None => {}
            Some(want) if want != hash => problems.push(format!("{path}: hash {hash}, was {want}")),
            Some(_) => {}
        }
    }
    for path in expected.keys().filter(|p| !current.contains_key(*p)) {
        problems.push(format!("{path}: in the fixture but gone"));
    }
    assert!(problems.is_empty(), "stored configs changed:\n{}", problems.join("\n"));
}
