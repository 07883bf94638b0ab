//! Two ways a run folder could claim what did not happen: a resume that changes the config
//! mid-run (refused, except the budget and the thread count), and a seed whose validation and
//! test episodes share env seeds (refused by the config's validation).

use std::path::Path;

use vge_run::config::{
    Config, RESUME_MAY_CHANGE, changed_keys, check_resume, load_config, parse_with_overrides,
};
use vge_run::episode_sets::EpisodeSet;

fn vge_config() -> Config {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/cube-fg-vge.toml");
    load_config(&path, &[]).expect("cube-fg-vge.toml loads")
}

/// The stored form a run folder holds, with `overrides` applied as `--resume` applies them.
fn resumed(stored: &Config, overrides: &[&str]) -> Config {
    let text = stored.to_toml_string().expect("serialises");
    let overrides: Vec<String> = overrides.iter().map(|s| (*s).to_owned()).collect();
    parse_with_overrides(&text, "runs/x/config.toml", &overrides).expect("overrides apply")
}

#[test]
fn changed_keys_names_every_differing_key_with_both_values() {
    let stored = vge_config();
    assert_eq!(changed_keys(&stored, &stored).expect("diff"), vec![]);
    let other = resumed(&stored, &["seed=5", "env.object_friction=0.5", "total_steps=7"]);
    let keys: Vec<String> =
        changed_keys(&stored, &other).expect("diff").iter().map(ToString::to_string).collect();
    assert_eq!(keys.len(), 3, "{keys:?}");
    assert!(keys.contains(&format!("seed = {} -> 5", stored.seed)), "{keys:?}");
    assert!(keys.contains(&format!("total_steps = {} -> 7", stored.total_steps)), "{keys:?}");
    assert!(
        keys.iter().any(|k| k.starts_with("env.object_friction = ") && k.ends_with("-> 0.5")),
        "{keys:?}"
    );
}

#[test]
fn a_resume_may_change_only_the_budget_and_the_thread_count() {
    let stored = vge_config();
    assert_eq!(RESUME_MAY_CHANGE, ["total_steps", "sac.threads"]);
    // The same values as stored (a sweep passes its seed and threads again) are no change.
    let same =
        resumed(&stored, &[&format!("seed={}", stored.seed), &format!("sac.threads={}", stored.sac.threads)]);
    assert_eq!(check_resume(&stored, &same, "runs/x/config.toml").expect("allowed"), Vec::<String>::new());
    // A longer budget continues silently.
    let longer = resumed(&stored, &["total_steps=5000000"]);
    assert!(check_resume(&stored, &longer, "runs/x/config.toml").expect("allowed").is_empty());
    // Another thread count continues, with a note that it may round differently.
    let threads = stored.sac.threads + 1;
    let more_threads = resumed(&stored, &[&format!("sac.threads={threads}")]);
    let notes = check_resume(&stored, &more_threads, "runs/x/config.toml").expect("allowed");
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(notes[0].contains("sac.threads") && notes[0].contains("bit for bit"), "{notes:?}");
    // Anything else is refused, naming each key, both values and the config it keeps.
    let other = resumed(&stored, &["seed=99", "vge.horizon=7", "total_steps=5000000"]);
    let err = check_resume(&stored, &other, "runs/x/config.toml").expect_err("refused").to_string();
    assert!(err.contains(&format!("seed = {} -> 99", stored.seed)), "{err}");
    assert!(err.contains(&format!("vge.horizon = {} -> 7", stored.vge.horizon)), "{err}");
    assert!(err.contains("runs/x/config.toml") && !err.contains("total_steps ="), "{err}");
}

/// The validation and test sets each hold `run.eval_episodes` consecutive env seeds from their
/// first; the config is refused exactly when the two ranges meet.
#[test]
fn a_seed_whose_validation_and_test_episodes_meet_is_refused() {
    let mut config = vge_config();
    let mut refused = Vec::new();
    for episodes in [20usize, 100] {
        config.run.eval_episodes = episodes;
        for seed in 0..2000u64 {
            config.seed = seed;
            let (v, t) =
                (EpisodeSet::Validation.first_seed(config.seed), EpisodeSet::Test.first_seed(config.seed));
            let n = episodes as u64;
            let meet = v < t.saturating_add(n) && t < v.saturating_add(n);
            match config.validate() {
                Ok(()) => assert!(!meet, "seed {seed}, {episodes} episodes: sets meet but the config passed"),
                Err(e) => {
                    assert!(meet, "seed {seed}, {episodes} episodes refused: {e}");
                    let e = e.to_string();
                    assert!(e.contains(&format!("seed = {seed}")) && e.contains("run.eval_episodes"), "{e}");
                    refused.push((episodes, seed));
                }
            }
        }
    }
    // The sets meet for a handful of seeds, more with more episodes (the check is not vacuous).
    assert_eq!(refused.iter().filter(|(n, _)| *n == 20).count(), 2, "{refused:?}");
    assert_eq!(refused.iter().filter(|(n, _)| *n == 100).count(), 6, "{refused:?}");
}
