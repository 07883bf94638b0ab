//! Configs that build on a base (`base = "FILE"`): the file's keys over its base's, tables
//! merged key by key; the Table I grid configs are a few lines each on `configs/cube-base.toml`
//! and load to the base with their own keys set; loops, missing bases and a base in text
//! without a folder are refused naming the file.

use std::path::{Path, PathBuf};

use vge_run::config::{ConfigError, load_config, parse_with_overrides};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vge-config-base-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

const GRID: [&str; 15] = [
    "cube-fg-rl",
    "cube-fg-rl-bc",
    "cube-fg-fge",
    "cube-fg-vge",
    "cube-fg-vge-bc",
    "cube-cs-rl",
    "cube-cs-rl-bc",
    "cube-cs-fge",
    "cube-cs-vge",
    "cube-cs-vge-bc",
    "cube-igm-rl",
    "cube-igm-rl-bc",
    "cube-igm-fge",
    "cube-igm-vge",
    "cube-igm-vge-bc",
];

/// Each grid config is at most 15 lines, and is exactly the base with the keys it writes:
/// loading it equals loading the base with those keys as `--set` overrides.
#[test]
fn each_table1_config_is_the_base_with_its_own_keys() {
    let base = repo().join("configs/cube-base.toml");
    for name in GRID {
        let path = repo().join(format!("configs/{name}.toml"));
        let text = std::fs::read_to_string(&path).expect("config");
        assert!(text.lines().count() <= 15, "{name}: {} lines", text.lines().count());
        let table: toml::Table = text.parse().expect("TOML");
        assert_eq!(table.get("base").and_then(|b| b.as_str()), Some("cube-base.toml"), "{name}");
        let mut sets = Vec::new();
        for (key, value) in table.iter().filter(|(k, _)| *k != "base") {
            match value {
                toml::Value::Table(section) => {
                    sets.extend(section.iter().map(|(k, v)| format!("{key}.{k}={v}")));
                }
                v => sets.push(format!("{key}={v}")),
            }
        }
        let loaded = load_config(&path, &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
        let by_hand = load_config(&base, &sets).expect("base with the keys");
        assert_eq!(loaded, by_hand, "{name}");
        assert_eq!(loaded.name, name);
        // What a run folder stores is the whole config, without the base.
        let stored = loaded.to_toml_string().expect("toml");
        assert!(!stored.contains("base"), "{stored}");
        assert_eq!(parse_with_overrides(&stored, "stored", &[]).expect("stored config loads"), loaded);
    }
}

/// The protocol has one default: `cube-base.toml` is `Config::default` with a name and plain
/// RL as its method, so a changed default changes the protocol in one place.
#[test]
fn the_protocol_base_is_the_defaults() {
    let path = repo().join("configs/cube-base.toml");
    let table: toml::Table = std::fs::read_to_string(&path).expect("cube-base.toml").parse().expect("TOML");
    let keys: Vec<&str> = table.keys().map(String::as_str).collect();
    assert_eq!(keys, ["method", "name"], "cube-base.toml writes only its name and method");
    let loaded = load_config(&path, &[]).expect("cube-base.toml loads");
    let defaults =
        parse_with_overrides("name = \"cube-base\"\nmethod = \"rl\"\n", "defaults", &[]).expect("defaults");
    assert_eq!(loaded, defaults);
}

/// Every shipped config names a base and only what differs from it: at most 25 lines each.
#[test]
fn every_shipped_config_is_short_and_built_on_a_base() {
    let mut files = Vec::new();
    for dir in ["configs", "configs/variants"] {
        for entry in std::fs::read_dir(repo().join(dir)).expect("configs") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                files.push(path);
            }
        }
    }
    assert!(files.len() > 30, "{} configs found", files.len());
    for path in files {
        let text = std::fs::read_to_string(&path).expect("config");
        let lines = text.lines().count();
        assert!(lines <= 25, "{}: {lines} lines", path.display());
        let table: toml::Table = text.parse().expect("TOML");
        let is_base = path.ends_with("configs/cube-base.toml");
        assert!(is_base || table.contains_key("base"), "{} names no base", path.display());
    }
}

#[test]
fn a_base_merges_under_the_file_table_by_table_and_chains() {
    let dir = temp_dir("merge");
    std::fs::write(
        dir.join("root.toml"),
        "name = \"root\"\ntotal_steps = 5000\n[env]\nobjects = [\"cube\", \"sphere\"]\ncontrol_hz = 20.0\n[sac]\nbatch = 64\n",
    )
    .expect("write");
    std::fs::create_dir_all(dir.join("sub")).expect("sub");
    std::fs::write(
        dir.join("sub/middle.toml"),
        "base = \"../root.toml\"\nname = \"middle\"\n[env]\ncontrol_hz = 10.0\n",
    )
    .expect("write");
    std::fs::write(dir.join("sub/leaf.toml"), "base = \"middle.toml\"\n[env]\nobjects = [\"sphere\"]\n")
        .expect("write");
    let leaf = load_config(&dir.join("sub/leaf.toml"), &["sac.utd=0.5".to_owned()]).expect("leaf loads");
    assert_eq!(leaf.name, "middle", "the middle's name over the root's");
    assert_eq!(leaf.total_steps, 5000, "the root's key where no one else sets it");
    assert_eq!(leaf.env.control_hz, 10.0, "a table merges key by key");
    assert_eq!(leaf.env.objects.len(), 1, "an array replaces the base's whole");
    assert_eq!(leaf.sac.batch, 64);
    assert_eq!(leaf.sac.utd, 0.5, "--set applies over the merged config");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn loops_missing_bases_and_a_base_without_a_file_are_refused_naming_them() {
    let dir = temp_dir("refused");
    std::fs::write(dir.join("a.toml"), "base = \"b.toml\"\n").expect("write");
    std::fs::write(dir.join("b.toml"), "base = \"a.toml\"\n").expect("write");
    let e = load_config(&dir.join("a.toml"), &[]).expect_err("a loop");
    assert!(e.to_string().contains("already built on") && e.to_string().contains("a.toml"), "{e}");

    std::fs::write(dir.join("orphan.toml"), "base = \"nowhere.toml\"\n").expect("write");
    let e = load_config(&dir.join("orphan.toml"), &[]).expect_err("missing base");
    assert!(matches!(&e, ConfigError::Io { path, .. } if path.ends_with("nowhere.toml")), "{e}");

    std::fs::write(dir.join("number.toml"), "base = 3\n").expect("write");
    let e = load_config(&dir.join("number.toml"), &[]).expect_err("not a file name");
    assert!(e.to_string().contains("names a file"), "{e}");

    let e = parse_with_overrides("base = \"cube-base.toml\"\n", "text", &[]).expect_err("no folder");
    assert!(e.to_string().contains("only from a config file"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
