//! Every test file is built, and merged test files leave the process alone. Crates that build
//! their test files as modules of one binary (`autotests = false`, `tests/main.rs`) compile
//! only the files that `main.rs` declares or that `Cargo.toml` names as a test target: a new
//! `tests/*.rs` left out of both would never run, and nothing else would say so.

use std::path::{Path, PathBuf};

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A workspace member that builds its test files as modules of one binary.
struct MergedCrate {
    folder: PathBuf,
    /// Its Cargo.toml's text.
    manifest: String,
}

impl MergedCrate {
    /// Whether `relative` (a path from the crate's folder, e.g. `tests/slurm.rs`) is a
    /// `[[test]]` target of its own, not a module of the merged binary.
    fn is_own_test_target(&self, relative: &str) -> bool {
        relative != "tests/main.rs" && self.manifest.contains(&format!("path = \"{relative}\""))
    }
}

/// The workspace's members (root Cargo.toml's `workspace.members`) whose Cargo.toml turns
/// autotests off.
fn crates_without_autotests(root: &Path) -> Vec<MergedCrate> {
    let workspace: toml::Table =
        std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml").parse().expect("TOML");
    let members = workspace["workspace"]["members"].as_array().expect("workspace.members");
    members
        .iter()
        .map(|m| root.join(m.as_str().expect("a member's path")))
        .filter_map(|folder| {
            let manifest = std::fs::read_to_string(folder.join("Cargo.toml")).expect("member Cargo.toml");
            manifest
                .lines()
                .any(|l| l.trim() == "autotests = false")
                .then_some(MergedCrate { folder, manifest })
        })
        .collect()
}

#[test]
fn every_test_file_is_a_module_of_the_integration_binary_or_a_test_target_of_its_own() {
    let root = workspace_root();
    let crates = crates_without_autotests(&root);
    // The simulator, hand files, controllers, runs, lab, runtime, bridge and CLI.
    let folders: Vec<&PathBuf> = crates.iter().map(|krate| &krate.folder).collect();
    assert!(crates.len() >= 8, "only {} crates with autotests = false: {folders:?}", crates.len());
    let mut missing = Vec::new();
    for krate in &crates {
        let main = std::fs::read_to_string(krate.folder.join("tests/main.rs")).expect("tests/main.rs");
        for entry in std::fs::read_dir(krate.folder.join("tests")).expect("tests/").flatten() {
            let path = entry.path();
            if path.extension().and_then(|e| e.to_str()) != Some("rs") {
                continue;
            }
            let stem = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 name");
            let declared = stem == "main"
                || main.lines().any(|l| l.trim() == format!("mod {stem};"))
                || krate.is_own_test_target(&format!("tests/{stem}.rs"));
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

/// Calls that change state shared by every thread of a process: the environment, the working
/// folder, libtorch's seed and thread pools.
const PROCESS_WIDE: &[&str] = &[
    "set_var(",
    "remove_var(",
    "set_current_dir(",
    "manual_seed(",
    "set_num_threads(",
    "set_num_interop_threads(",
];

/// Every `.rs` file under `folder`, its subfolders included.
fn rust_files(folder: &Path, into: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(folder).expect("a readable tests/ folder").flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, into);
        } else if path.extension().and_then(|e| e.to_str()) == Some("rs") {
            into.push(path);
        }
    }
}

#[test]
fn no_test_merged_into_an_integration_binary_changes_process_wide_state() {
    // Under plain `cargo test` one binary's tests run as threads of one process: a test in the
    // merged binary that sets an environment variable or libtorch's seed would change what the
    // tests beside it see, by timing. Such a test belongs in a `[[test]]` of its own.
    let root = workspace_root();
    let mut offending = Vec::new();
    for krate in crates_without_autotests(&root) {
        let mut files = Vec::new();
        rust_files(&krate.folder.join("tests"), &mut files);
        for file in files {
            let relative =
                file.strip_prefix(&krate.folder).expect("under the crate").to_string_lossy().into_owned();
            if krate.is_own_test_target(&relative) {
                continue;
            }
            let text = std::fs::read_to_string(&file).expect("a readable test file");
            for (number, line) in text.lines().enumerate() {
                let code = line.trim_start();
                if code.starts_with("//") {
                    continue;
                }
                if let Some(call) = PROCESS_WIDE.iter().find(|call| code.contains(*call)) {
                    offending.push(format!("{}:{}: {call}", file.display(), number + 1));
                }
            }
        }
    }
    assert!(
        offending.is_empty(),
        "tests in a merged `integration` binary that change process-wide state (move each into a \
         [[test]] of its own in the crate's Cargo.toml, as the learner's seeded tests are): \
         {offending:#?}"
    );
}
