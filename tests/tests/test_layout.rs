//! Every test file is built. Crates that build their test files as modules of one binary
//! (`autotests = false`, `tests/main.rs`) compile only the files that `main.rs` declares or
//! that `Cargo.toml` names as a test target: a new `tests/*.rs` left out of both would never
//! run, and nothing else would say so.

use std::path::{Path, PathBuf};

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The workspace's members (root Cargo.toml's `workspace.members`) whose Cargo.toml turns
/// autotests off.
fn crates_without_autotests(root: &Path) -> Vec<PathBuf> {
    let workspace: toml::Table =
        std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml").parse().expect("TOML");
    let members = workspace["workspace"]["members"].as_array().expect("workspace.members");
    members
        .iter()
        .map(|m| root.join(m.as_str().expect("a member's path")))
        .filter(|folder| {
            let manifest = std::fs::read_to_string(folder.join("Cargo.toml")).expect("member Cargo.toml");
            manifest.lines().any(|l| l.trim() == "autotests = false")
        })
        .collect()
}

#[test]
fn every_test_file_is_a_module_of_the_integration_binary_or_a_test_target_of_its_own() {
    let root = workspace_root();
    let crates = crates_without_autotests(&root);
    // The simulator, hand files, controllers, runs, lab, runtime, bridge and CLI.
    assert!(crates.len() >= 8, "only {} crates with autotests = false: {crates:?}", crates.len());
    let mut missing = Vec::new();
    for krate in &crates {
        let manifest = std::fs::read_to_string(krate.join("Cargo.toml")).expect("Cargo.toml");
        let main = std::fs::read_to_string(krate.join("tests/main.rs")).expect("tests/main.rs");
        for entry in std::fs::read_dir(krate.join("tests")).expect("tests/").flatten() {
            let path = entry.path();
            if path.extension().and_then(|e| e.to_str()) != Some("rs") {
                continue;
            }
            let stem = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 name");
            let declared = stem == "main"
                || main.lines().any(|l| l.trim() == format!("mod {stem};"))
                || manifest.contains(&format!("path = \"tests/{stem}.rs\""));
            if !declared {
                missing.push(path);
            }
        }
    }
    assert!(
        missing.is_empty(),
        "test files that no binary builds (add `mod NAME;` to the crate's tests/main.rs, or a \
         [[test]] with its path to its Cargo.toml): {missing:?}"
    );
}
