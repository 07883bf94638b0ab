//! Table I from run folders (`vge plot --table1`): the arithmetic on known runs, and the
//! committed docs/results/table1 artefacts against the run folders they come from.

use std::path::{Path, PathBuf};

use vge_controllers::ControllerKind;
use vge_lab::table1;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_owned()
}

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vge-table1-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A run folder of `config` (a file under configs/) with two metrics rows, two periodic
/// evaluations and, when `final_eval` is given as (success rate, mean return), a final one.
fn fake_run(dir: &Path, config: &str, final_eval: Option<(f64, f64)>) {
    std::fs::create_dir_all(dir).expect("run dir");
    // As training stores it: the whole config, any base merged in.
    let merged = vge_run::config::load_config(&repo().join("configs").join(config), &[]).expect("config");
    std::fs::write(dir.join("config.toml"), merged.to_toml_string().expect("toml")).expect("config");
    std::fs::write(
        dir.join("metrics.csv"),
        "step,episodes,return,rotation,controller_share\n10000,5,1.0,0.1,0.5\n20000,9,2.0,0.2,0.4\n",
    )
    .expect("metrics");
    let (success, ret) = final_eval.unwrap_or((0.25, 10.0));
    std::fs::write(
        dir.join("eval.csv"),
        format!(
            "step,episodes,return,rotation,success\n10000,20,5.0,0.3,0.0\n20000,20,{ret},1.0,{success}\n"
        ),
    )
    .expect("eval");
    if let Some((success, ret)) = final_eval {
        let json = serde_json::json!({
            "success_rate": success, "mean_return": ret, "env_steps": 20000, "wall_s": 60.0,
            "mean_contact_switches": 10.0 * success,
            "episodes": 20, "learned": success >= 0.5,
        });
        std::fs::write(dir.join("final-eval.json"), json.to_string()).expect("final eval");
    }
}

#[test]
fn cells_count_finished_seeds_by_config_and_write_every_artefact() {
    let root = tempdir("known");
    // Folder names say nothing: the config decides the cell.
    fake_run(&root.join("a/seed-0"), "cube-fg-fge.toml", Some((0.6, 100.0)));
    fake_run(&root.join("a/seed-1"), "cube-fg-fge.toml", Some((0.4, 200.0)));
    fake_run(&root.join("b/x"), "cube-fg-fge.toml", Some((0.5, 300.0)));
    fake_run(&root.join("b/y"), "cube-fg-fge.toml", None);
    fake_run(&root.join("c"), "cube-cs-vge.toml", Some((0.0, 12.5)));
    // A cell whose only run is still running.
    fake_run(&root.join("e"), "cube-cs-fge.toml", None);
    // Not a cell: several objects.
    fake_run(&root.join("d"), "multi-object-fg-vge.toml", Some((1.0, 50.0)));
    let out = tempdir("known-out");
    std::fs::create_dir_all(out.join("controllers")).expect("controllers dir");
    std::fs::write(
        out.join("controllers/fg.json"),
        r#"{"kind":"fg","success_rate":0.05,"mean_return":11.5,"mean_contact_switches":7.3}"#,
    )
    .expect("fg alone");

    // Overlapping roots list a run once.
    let written = table1::write(&[root.clone(), root.join("a")], &out).expect("table");
    assert_eq!(written.skipped, vec![root.join("d")]);
    let csv = std::fs::read_to_string(out.join("table1.csv")).expect("csv");
    assert_eq!(
        csv,
        "controller,method,seeds,learned,success_rate_mean,return_mean,return_std,env_steps,\
         scored,iqm,iqm_ci_low,iqm_ci_high,mean,mean_ci_low,mean_ci_high,final_iqm,final_iqm_ci_low,\
         final_iqm_ci_high\n\
         fg,fge,3,2,0.5000,200.00,100.00,20000,0,,,,,,,,,\n\
         fg,controller-alone,,,0.0500,11.50,,,,,,,,,,,,\n\
         cs,fge,0,0,,,,,0,,,,,,,,,\n\
         cs,vge,1,0,0.0000,12.50,,20000,0,,,,,,,,,\n"
    );
    let fge = &written.rows[0];
    assert_eq!((fge.controller, fge.seeds, fge.learned, fge.unfinished), (ControllerKind::Fg, 3, 2, 1));
    let md = std::fs::read_to_string(out.join("table1.md")).expect("md");
    // Contact switches: the mean of 6, 4 and 5. The last tests: each seed's two periodic
    // tests (0 and its final 0.6, 0.4, 0.5) average 0.3, 0.2, 0.25.
    assert!(
        md.contains(
            "| FG | fge | 2/3 (67%), 1 still rising, 1 running | 0: 60%, 0: 40%, 0: 50% | - | - | - | - | 73% | 0.50 | 0.25 | 200.0 ± 100.0 | 5.0 | 20000 |"
        ),
        "{md}"
    );
    assert!(
        md.contains(
            "| FG | controller-alone | (no learning) | - | - | - | - | - | - | 0.05 | - | 11.5 | 7.3 | - |"
        ),
        "{md}"
    );
    assert!(md.contains("\nThe last 3 periodic tests (the final one included)"), "{md}");
    // Not learned, and its last test (12.5) beat its first (5.0) by more than a quarter.
    assert!(md.contains("| CS | vge | 0/1 (0%), 1 still rising | 0: 0% | - | - | - | - | 27% |"), "{md}");
    assert!(md.contains("\nStill rising: a seed that did not learn"), "{md}");
    assert!(
        md.contains("| CS | fge | 0/0 (0%), 1 running | - | - | - | - | - | 67% | - | - | - | - | - |"),
        "{md}"
    );
    for png in ["curves-fg.png", "curves-cs.png"] {
        let bytes = std::fs::read(out.join(png)).expect(png);
        assert!(bytes.starts_with(b"\x89PNG"), "{png}");
    }
    assert!(!out.join("curves-igm.png").exists());

    // A folder without runs is an error, not an empty table.
    let empty = tempdir("empty");
    assert!(table1::write(&[empty], &out).is_err());
}

#[test]
fn a_seed_that_passed_a_periodic_test_and_ended_below_it_is_counted_apart() {
    let root = tempdir("fell");
    // Passed at 10k (80%), 0% at the end: the late swing.
    fake_run(&root.join("fell"), "cube-cs-vge.toml", Some((0.0, 12.5)));
    std::fs::write(
        root.join("fell/eval.csv"),
        "step,episodes,return,rotation,success\n10000,20,300.0,15.0,0.8\n20000,20,12.5,1.0,0.0\n",
    )
    .expect("eval");
    // Its own selection (the 10k snapshot) learned on held-out grasps: counted by the selection.
    std::fs::write(root.join("fell/best-eval.json"), r#"{"selected_step":10000,"success_rate":0.8}"#)
        .expect("best eval");
    // Never passed (and still rising: 5 then 40).
    fake_run(&root.join("never"), "cube-cs-vge.toml", Some((0.2, 40.0)));
    // Learned: not counted, whatever its periodic tests did.
    fake_run(&root.join("learned"), "cube-cs-vge.toml", Some((0.9, 400.0)));
    for (run, seed) in [("fell", 2), ("never", 7), ("learned", 11)] {
        let path = root.join(run).join("config.toml");
        let config = std::fs::read_to_string(&path).expect("config");
        std::fs::write(&path, config.replacen("\nseed = 0\n", &format!("\nseed = {seed}\n"), 1))
            .expect("seed");
    }
    let out = tempdir("fell-out");
    let written = table1::write(&[root], &out).expect("table");
    assert_eq!((written.rows[0].learned, written.rows[0].passed_then_fell), (1, 1));
    let md = std::fs::read_to_string(out.join("table1.md")).expect("md");
    // Per seed, in seed order whatever the folders' order.
    assert!(
        md.contains(
            "| CS | vge | 1/3 (33%), 1 passed earlier, 1 still rising | 2: 0%, 7: 20%, 11: 90% | 1/1 | - | - |"
        ),
        "{md}"
    );
    assert!(
        md.contains("\nPassed earlier: of the 2 seeds that did not learn, 1 passed a periodic test"),
        "{md}"
    );
}

#[test]
fn committed_table1_is_what_its_run_folders_give() {
    let results = repo().join("docs/results");
    // Each committed table and the roots its README names: the table's own folder and
    // VGE + FG's seeds. The three archives (the Euler-yaw reward, the paper's reward, then
    // utd 0.5 with the controllers stopped at 400k) always; the current table once its
    // first runs are in; the comparison on the sac-alpha0 variant, whose plain-RL seeds 0-2
    // are the variant screen's runs beside it.
    let mut tables: Vec<(PathBuf, Vec<PathBuf>)> = ["euler-yaw-reward", "paper-reward", "utd05-hs400k"]
        .map(|archive| {
            (results.join(archive).join("table1"), vec![results.join(archive).join("cube-fg-vge-seeds")])
        })
        .into();
    if results.join("table1/table1.csv").exists() {
        tables.push((results.join("table1"), vec![results.join("cube-fg-vge-seeds")]));
    }
    let sac_alpha0 = results.join("variants/sac-alpha0");
    tables.push((sac_alpha0.join("table1"), (0..3).map(|k| sac_alpha0.join(format!("seed-{k}"))).collect()));
    for (committed, others) in tables {
        let out = tempdir("committed");
        let _ = std::fs::remove_dir_all(&out);
        std::fs::create_dir_all(out.join("controllers")).expect("controllers dir");
        for entry in std::fs::read_dir(committed.join("controllers")).expect("the table's controllers/") {
            let path = entry.expect("entry").path();
            std::fs::copy(&path, out.join("controllers").join(path.file_name().expect("name")))
                .expect("copy");
        }
        let roots: Vec<PathBuf> = std::iter::once(committed.clone()).chain(others).collect();
        table1::write(&roots, &out).expect("recompute");
        for file in ["table1.csv", "table1.md"] {
            let want = std::fs::read_to_string(committed.join(file)).expect(file);
            let got = std::fs::read_to_string(out.join(file)).expect(file);
            assert_eq!(
                got,
                want,
                "{} differs from what the run folders give",
                committed.join(file).display()
            );
        }
    }
}

/// A `score.json` whose selected policy succeeds in `success` of the episodes and whose
/// final policy in half as many.
fn write_score(dir: &Path, success: f64) {
    let policy = |file: &str, success: f64| {
        serde_json::json!({
            "file": file, "step": 20000, "crc32": 1, "success_rate": success, "mean_return": 100.0,
            "drop_rate": 0.0, "mean_rotation_rad": 7.0, "mean_contact_switches": 20.0,
        })
    };
    let score = serde_json::json!({
        "definition": vge_run::score::DEFINITION, "episodes": 100, "seed": 1u64 << 52,
        "episode_s": 30.0, "grasp_noise_rad": 0.02,
        "selected": policy("policy-best.vgep", success), "final": policy("policy.vgep", success / 2.0),
    });
    std::fs::write(dir.join("score.json"), score.to_string()).expect("score.json");
}

#[test]
fn scored_cells_get_their_iqm_intervals_improvements_and_profiles() {
    let root = tempdir("scored");
    for (k, s) in [0.2, 0.9, 0.95, 1.0].into_iter().enumerate() {
        let dir = root.join(format!("vge/seed-{k}"));
        fake_run(&dir, "cube-fg-vge.toml", Some((s, 100.0)));
        write_score(&dir, s);
    }
    for (k, s) in [0.1, 0.3].into_iter().enumerate() {
        let dir = root.join(format!("rl/seed-{k}"));
        fake_run(&dir, "cube-fg-rl.toml", Some((s, 100.0)));
        write_score(&dir, s);
    }
    // A finished run not scored yet: counted, not in the statistics.
    fake_run(&root.join("rl/seed-2"), "cube-fg-rl.toml", Some((0.5, 100.0)));
    let rl_bc = root.join("rl-bc/seed-0");
    fake_run(&rl_bc, "cube-fg-rl-bc.toml", Some((0.2, 100.0)));
    write_score(&rl_bc, 0.2);
    let out = tempdir("scored-out");
    let written = table1::write(&[root], &out).expect("table");
    let csv = std::fs::read_to_string(out.join("table1.csv")).expect("csv");
    // VGE: IQM of 0.2, 0.9, 0.95, 1.0 drops one from each end (0.925), mean 0.7625.
    let vge = csv.lines().find(|l| l.starts_with("fg,vge,")).expect("vge row");
    let fields: Vec<&str> = vge.split(',').collect();
    assert_eq!((fields[8], fields[9], fields[12]), ("4", "0.9250", "0.7625"), "{vge}");
    let (low, high): (f64, f64) = (fields[10].parse().expect("low"), fields[11].parse().expect("high"));
    assert!(low <= 0.925 && 0.925 <= high && low < high, "{vge}");
    // Beside it the final policies' IQM: of 0.1, 0.45, 0.475, 0.5.
    assert_eq!(fields[15], "0.4625", "{vge}");
    let rl = csv.lines().find(|l| l.starts_with("fg,rl,")).expect("rl row");
    assert_eq!(rl.split(',').nth(8), Some("2"), "two of three scored: {rl}");
    // P(VGE > RL): 7 of the 8 pairs.
    let improvement = std::fs::read_to_string(out.join("improvement.csv")).expect("improvement.csv");
    let mut lines = improvement.lines();
    assert_eq!(lines.next(), Some("a,b,prob_improvement,ci_low,ci_high"));
    let row = lines.next().expect("VGE against RL");
    assert!(row.starts_with("fg/vge,fg/rl,0.8750,"), "{improvement}");
    // Every guided method is set against RL, RL + BC too: 0.2 beats 0.1, not 0.3.
    let row = lines.next().expect("RL + BC against RL");
    assert!(row.starts_with("fg/rl-bc,fg/rl,0.5000,"), "{improvement}");
    assert_eq!(lines.next(), None, "the other pairs' cells have no runs: {improvement}");
    assert_eq!(written.improvements.len(), 2);
    // The final policies score half their selected ones (write_score): VGE's 0.1, 0.45,
    // 0.475, 0.5 beat RL's 0.05 and 0.15 in 7 of 8 pairs; RL + BC's 0.1 sits between RL's.
    let last = std::fs::read_to_string(out.join("improvement-final.csv")).expect("improvement-final.csv");
    let mut lines = last.lines();
    assert_eq!(lines.next(), Some("a,b,prob_improvement,ci_low,ci_high"));
    assert!(lines.next().is_some_and(|r| r.starts_with("fg/vge,fg/rl,0.8750,")), "{last}");
    assert!(lines.next().is_some_and(|r| r.starts_with("fg/rl-bc,fg/rl,0.5000,")), "{last}");
    assert_eq!(written.improvements_final.len(), 2, "{last}");
    let md = std::fs::read_to_string(out.join("table1.md")).expect("md");
    assert!(md.contains("| fg/vge | fg/rl | 0.88 |"), "{md}");
    assert!(md.contains("The same of the final policies (`improvement-final.csv`)"), "{md}");
    assert!(md.contains("0.93 ["), "the IQM with its interval: {md}");
    assert!(md.contains("(2 of 3 runs)"), "{md}");
    let png = std::fs::read(out.join("profiles-fg.png")).expect("profiles-fg.png");
    assert!(png.starts_with(b"\x89PNG"));
}
