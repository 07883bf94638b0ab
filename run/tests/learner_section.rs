//! `[learner]` with `kind` is the section of the learner's settings; `[sac]` and the top-level
//! `algorithm` are its older spellings, which the canonical TOML keeps. Both load to the same
//! config (and so the same hash); a file that sets one setting both ways is refused, and
//! `--set learner.KEY=...` overrides either spelling.

use vge_run::config::{AlgorithmName, Config, apply_override, parse_with_overrides};

fn load(text: &str, overrides: &[&str]) -> Result<Config, String> {
    let overrides: Vec<String> = overrides.iter().map(|o| (*o).to_owned()).collect();
    parse_with_overrides(text, "test.toml", &overrides).map_err(|e| e.to_string())
}

#[test]
fn the_learner_section_is_the_sac_section_under_its_new_name() {
    let new = load("[learner]\nkind = \"sac\"\nutd = 0.5\nbatch = 64\n", &[]).expect("new spelling");
    let old = load("algorithm = \"sac\"\n[sac]\nutd = 0.5\nbatch = 64\n", &[]).expect("old spelling");
    assert_eq!(new, old);
    assert_eq!(new.algorithm, AlgorithmName::Sac);
    assert_eq!(new.sac.utd, 0.5);
    assert_eq!(new.hash_hex(), old.hash_hex());
    // The canonical TOML keeps the old spelling, which every stored config uses.
    let canonical = new.to_toml_string().expect("toml");
    assert!(canonical.contains("[sac]") && canonical.contains("algorithm = \"sac\""), "{canonical}");
    assert!(!canonical.contains("[learner]"), "{canonical}");
    // A kind alone picks the learner and leaves the defaults.
    let kind_only = load("[learner]\nkind = \"sac\"\n", &[]).expect("kind only");
    assert_eq!(kind_only.algorithm, AlgorithmName::Sac);
    assert_eq!(kind_only.sac, Config::default().sac);
}

#[test]
fn one_setting_spelt_both_ways_in_a_file_is_refused() {
    let both_sections = load("[learner]\nutd = 0.5\n[sac]\nbatch = 64\n", &[]).expect_err("both sections");
    assert!(both_sections.contains("[sac] is the older name of [learner]"), "{both_sections}");
    let both_kinds = load("algorithm = \"td3\"\n[learner]\nkind = \"sac\"\n", &[]).expect_err("both kinds");
    assert!(both_kinds.contains("`algorithm` is the older name of `learner.kind`"), "{both_kinds}");
    let not_a_table = load("learner = 3\n", &[]).expect_err("not a table");
    assert!(not_a_table.contains("[learner] is the table of the learner's settings"), "{not_a_table}");
    let unknown_kind = load("[learner]\nkind = \"ppo\"\n", &[]).expect_err("unknown kind");
    assert!(unknown_kind.contains("ppo"), "{unknown_kind}");
}

#[test]
fn set_overrides_either_spelling() {
    let file = "algorithm = \"td3\"\n[sac]\nutd = 0.25\n";
    let c = load(file, &["learner.kind=sac", "learner.utd=0.5"]).expect("overrides");
    assert_eq!((c.algorithm, c.sac.utd), (AlgorithmName::Sac, 0.5));
    let c =
        load("[learner]\nkind = \"sac\"\nutd = 0.25\n", &["sac.utd=1.0", "algorithm=td3"]).expect("old keys");
    assert_eq!((c.algorithm, c.sac.utd), (AlgorithmName::Td3, 1.0));
    let mut d = Config::default();
    apply_override(&mut d, "learner.batch=32").expect("apply_override");
    assert_eq!(d.sac.batch, 32);
}
