//! One policy for several objects: a run on two objects tests each of them (eval.csv's
//! per-object columns, `per_object` in final-eval.json, best-eval.json and `vge score`'s
//! score.json, the per-object curves of `vge plot`, `vge screen` and `vge ship`'s per-object
//! record, `vge compare` with each object as a task), and `vge eval --objects` gives one row per object whose figures are those of
//! `vge eval --object` on the same episodes.

use crate::common;

use std::path::Path;
use std::process::Output;

use serde_json::Value;
use vge_lab::gait_diagram::{DIAGRAM_PX, STACKED_PANEL_PX};

fn vge(args: &[&str], extra: &[String]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_vge")).args(args).args(extra).output().expect("vge runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A PNG's width and height in pixels, from its header.
fn png_size_px(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.len() > 24, "{} is no PNG", path.display());
    let be = |at: usize| u32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    (be(16), be(20))
}

const FIGURES: [&str; 6] =
    ["success_rate", "drop_rate", "mean_return", "mean_rotation_rad", "mean_contact_switches", "episodes"];

/// The overall figures of a report are its objects' pooled: with as many episodes per object,
/// the mean of theirs.
fn assert_overall_pools(doc: &Value, objects: &[&str], episodes_per_object: u64) {
    let per_object = doc["per_object"].as_object().unwrap_or_else(|| panic!("per_object in {doc}"));
    // (serde_json's map sorts its keys: the order is checked on the text where it matters.)
    let mut names: Vec<&str> = per_object.keys().map(String::as_str).collect();
    let mut want = objects.to_vec();
    names.sort_unstable();
    want.sort_unstable();
    assert_eq!(names, want, "one entry per object");
    for (name, figures) in per_object {
        for key in FIGURES {
            assert!(figures[key].is_number(), "{name}: {key} in {figures}");
        }
        assert_eq!(figures["episodes"].as_u64(), Some(episodes_per_object), "{name}");
    }
    assert_eq!(doc["episodes"].as_u64(), Some(episodes_per_object * objects.len() as u64));
    for key in ["success_rate", "drop_rate", "mean_return", "mean_rotation_rad", "mean_contact_switches"] {
        let mean =
            per_object.values().map(|f| f[key].as_f64().expect("number")).sum::<f64>() / objects.len() as f64;
        let overall = doc[key].as_f64().expect("overall figure");
        assert!((overall - mean).abs() < 1e-9, "{key}: overall {overall}, mean of objects {mean}");
    }
}

/// A tiny run of the multi-object config on two objects (one env each) with periodic
/// evaluations: every evaluation tests both objects, and the files say so.
#[test]
fn a_two_object_run_evaluates_both_objects_and_writes_per_object() {
    let dir = common::temp_dir("multi-object-run");
    let run = dir.join("run");
    let config = common::config("multi-object-fg-vge.toml");
    let mut args = vec!["--config".to_owned(), config.display().to_string()];
    args.extend(common::tiny_args());
    for o in ["env.objects=[\"cube\", \"sphere\"]", "run.eval_interval=100", "sac.threads=1"] {
        args.extend(["--set".to_owned(), o.to_owned()]);
    }
    args.extend(["--steps".to_owned(), "300".to_owned(), "--out".to_owned(), run.display().to_string()]);
    let out = vge(&["train"], &args);
    assert!(out.status.success(), "{}", text(&out.stderr));

    // eval.csv: the overall columns as in a single-object run, then each object's.
    let csv = std::fs::read_to_string(run.join("eval.csv")).expect("eval.csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let mut want: Vec<String> = "step,episodes,return,rotation,success,drops,contacts,contact_switches"
        .split(',')
        .map(str::to_owned)
        .collect();
    for object in ["cube", "sphere"] {
        want.extend(
            ["success", "return", "rotation", "drops", "contact_switches"].map(|f| format!("{object}_{f}")),
        );
    }
    assert_eq!(header, want.iter().map(String::as_str).collect::<Vec<_>>());
    let rows: Vec<Vec<f64>> =
        lines.map(|l| l.split(',').map(|f| f.parse().expect("a number")).collect()).collect();
    assert_eq!(rows.iter().map(|r| r[0] as u64).collect::<Vec<_>>(), [100, 200, 300]);
    for r in &rows {
        assert_eq!(r.len(), header.len());
        assert_eq!(r[1], 4.0, "two episodes on each of two objects");
        let column = |name: &str| r[header.iter().position(|h| *h == name).expect(name)];
        let mean = (column("cube_success") + column("sphere_success")) / 2.0;
        assert!((column("success") - mean).abs() < 1e-3, "{r:?}");
    }

    // metrics.csv: the usual columns, then each object's success, return and rotation over
    // the window's training episodes (25-step episodes, a row every 50 steps of 2 envs: an
    // episode of each object ends in every window).
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).expect("metrics.csv");
    let mut metrics_lines = metrics.lines();
    let metrics_header: Vec<&str> = metrics_lines.next().expect("header").split(',').collect();
    let per_object: Vec<String> = ["cube", "sphere"]
        .iter()
        .flat_map(|o| ["success", "return", "rotation"].map(|f| format!("{o}_{f}")))
        .collect();
    let split = metrics_header.len() - per_object.len();
    assert_eq!(
        metrics_header[split..],
        per_object.iter().map(String::as_str).collect::<Vec<_>>()[..],
        "{metrics_header:?}"
    );
    assert_eq!((metrics_header[0], metrics_header[split - 1]), ("step", "steps_per_s"), "{metrics_header:?}");
    let metrics_rows: Vec<Vec<&str>> = metrics_lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(metrics_rows.len(), 6, "{metrics}");
    for row in &metrics_rows {
        assert_eq!(row.len(), metrics_header.len(), "{metrics}");
        for field in &row[split..] {
            let value: f64 = field.parse().unwrap_or_else(|_| panic!("a per-object figure in {row:?}"));
            assert!(value.is_finite(), "{row:?}");
        }
    }

    // final-eval.json and best-eval.json: per_object beside the overall figures.
    let final_eval = json(&run.join("final-eval.json"));
    assert_overall_pools(&final_eval, &["cube", "sphere"], 2);
    assert_eq!(final_eval["per_episode"].as_array().map(Vec::len), Some(4));
    let learned = final_eval["per_object"]
        .as_object()
        .expect("per_object")
        .values()
        .all(|f| f["success_rate"].as_f64() >= Some(0.5));
    assert_eq!(final_eval["learned"].as_bool(), Some(learned), "learned means every object");
    let best = json(&run.join("best-eval.json"));
    assert_overall_pools(&best, &["cube", "sphere"], 2);
    let selected = best["selected_step"].as_u64().expect("selected_step");
    assert!([100, 200, 300].contains(&selected), "{best}");
    let row = rows.iter().find(|r| r[0] as u64 == selected).expect("the selected row");
    let worst = row[header.iter().position(|h| *h == "cube_success").expect("cube_success column")]
        .min(row[header.iter().position(|h| *h == "sphere_success").expect("sphere_success column")]);
    assert_eq!(best["validation_worst_object_success_rate"].as_f64(), Some(worst));
    assert!(run.join("policy-best.vgep").exists());

    // vge score scores each object on the same held-out episodes; the figures pool them.
    let score = vge(&["score", "--episodes", "3", "--threads", "1"], &[run.display().to_string()]);
    assert!(score.status.success(), "{}", text(&score.stderr));
    let stdout = text(&score.stdout);
    assert!(stdout.contains("  cube: selected") && stdout.contains("  sphere: selected"), "{stdout}");
    let scored = json(&run.join("score.json"));
    for policy in ["final", "selected"] {
        let per_object = scored[policy]["per_object"].as_object().unwrap_or_else(|| panic!("{scored}"));
        assert_eq!(per_object.len(), 2, "{scored}");
        let mut success = 0.0;
        for object in ["cube", "sphere"] {
            assert_eq!(per_object[object]["episodes"].as_u64(), Some(3), "{policy} {object}");
            success += per_object[object]["success_rate"].as_f64().expect("success_rate") / 2.0;
        }
        let pooled = scored[policy]["success_rate"].as_f64().expect("success_rate");
        assert!((pooled - success).abs() < 1e-9, "{policy}: pooled {pooled}, mean of objects {success}");
    }
    let text_order = std::fs::read_to_string(run.join("score.json")).expect("score.json");
    assert!(text_order.find("\"cube\"") < text_order.find("\"sphere\""), "the config's order");
    let again = vge(&["score", "--episodes", "3"], &[run.display().to_string()]);
    assert!(text(&again.stdout).contains("already scored, skipped"), "{}", text(&again.stdout));

    // vge compare takes each object as a task (rliable's runs x tasks): three copies of the
    // run with set per-object scores, whose IQM over runs x objects (0.575) differs from the
    // IQM of their pooled success (0.55).
    let per_run = [(1.0, 0.0), (0.9, 0.5), (0.8, 0.1)];
    let mut copies = Vec::new();
    for (k, (cube, sphere)) in per_run.into_iter().enumerate() {
        let copy = dir.join(format!("copy-{k}"));
        common::copy_dir(&run, &copy);
        let mut score = json(&copy.join("score.json"));
        score["selected"]["per_object"]["cube"]["success_rate"] = cube.into();
        score["selected"]["per_object"]["sphere"]["success_rate"] = sphere.into();
        score["selected"]["success_rate"] = ((cube + sphere) / 2.0).into();
        std::fs::write(copy.join("score.json"), score.to_string()).expect("score.json");
        copies.push(copy.display().to_string());
    }
    let compared = dir.join("compare");
    let compare = vge(
        &["compare", "--out", &compared.display().to_string(), "--resamples", "2000"],
        &[format!("vge={}", copies.join(",")), format!("one={}", run.display())],
    );
    assert!(compare.status.success(), "{}", text(&compare.stderr));
    let csv = std::fs::read_to_string(compared.join("compare.csv")).expect("compare.csv");
    let selected: Vec<&str> =
        csv.lines().find(|l| l.starts_with("vge,selected,")).expect("vge's row").split(',').collect();
    let figure = |i: usize| selected[i].parse::<f64>().expect("a number");
    assert_eq!(selected[2], "3", "{csv}");
    assert!((figure(3) - 0.575).abs() < 1e-4, "IQM over runs x objects: {csv}");
    assert!((figure(6) - 0.55).abs() < 1e-4, "mean over objects of their means: {csv}");
    // A group's figures do not depend on the groups beside it: each interval draws from a
    // generator seeded by its own label.
    let alone = dir.join("compare-alone");
    let out = vge(
        &["compare", "--out", &alone.display().to_string(), "--resamples", "2000"],
        &[format!("vge={}", copies.join(","))],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let alone_csv = std::fs::read_to_string(alone.join("compare.csv")).expect("compare.csv");
    let vge_rows =
        |csv: &str| csv.lines().filter(|l| l.starts_with("vge,")).map(str::to_owned).collect::<Vec<_>>();
    assert_eq!(vge_rows(&alone_csv), vge_rows(&csv));
    assert_eq!(vge_rows(&csv).len(), 3, "selected, final, last snapshots: {csv}");
    let md = std::fs::read_to_string(compared.join("compare.md")).expect("compare.md");
    assert!(md.contains("| group | cube | sphere |") && md.contains("each object is a task"), "{md}");
    // The critic at the end of each run, per group: the copies are one run three times.
    let critic = md.split("The critic at the end of each run").nth(1).expect("the critic's section");
    let vge_row = critic.lines().find(|l| l.starts_with("| vge |")).expect("vge's critic row");
    let gaps: Vec<&str> = vge_row.split(" | ").nth(2).expect("per run").split(", ").collect();
    assert_eq!(gaps.len(), 3, "{vge_row}");
    let gap = |g: &str| g.split(": ").nth(1).expect("seed: gap").parse::<f64>().expect("a gap");
    assert!(gaps.iter().all(|g| gap(g) == gap(gaps[0])), "{vge_row}");
    // P(A > B) of the final policies too, each ordered pair: the two directions sum to 1
    // (ties count half to each).
    let last =
        std::fs::read_to_string(compared.join("improvement-final.csv")).expect("improvement-final.csv");
    let p: Vec<(String, f64)> = last
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (format!("{}>{}", f[0], f[1]), f[2].parse().expect("a probability"))
        })
        .collect();
    assert_eq!(p.iter().map(|(k, _)| k.as_str()).collect::<Vec<_>>(), ["vge>one", "one>vge"], "{last}");
    assert!((p[0].1 + p[1].1 - 1.0).abs() < 1e-4, "{last}");
    assert!(
        md.contains("Probability of improvement (final policy's success, `improvement-final.csv`)"),
        "{md}"
    );
    // Each run on each object: 4 runs x 2 objects, the set selected success on its object.
    let per_object = std::fs::read_to_string(compared.join("per-object.csv")).expect("per-object.csv");
    let lines: Vec<Vec<&str>> = per_object.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(lines.len(), 8, "{per_object}");
    let copy_1_sphere = lines
        .iter()
        .find(|l| l[0] == "vge" && l[1].ends_with("copy-1") && l[3] == "sphere")
        .unwrap_or_else(|| panic!("copy-1's sphere row: {per_object}"));
    assert_eq!(copy_1_sphere[6], "0.5000", "selected success: {per_object}");
    assert!(md.contains("| first pass |"), "{md}");

    // --metric ranks by another figure of the same episodes: the rotation, set per object
    // (IQM over runs x objects of 10, 2, 6, 4, 1, 3 is 3.75; the mean of the objects' means
    // 4.33), with profiles over the scores' range.
    for (k, (cube, sphere)) in [(10.0, 2.0), (6.0, 4.0), (1.0, 3.0)].into_iter().enumerate() {
        let copy = dir.join(format!("copy-{k}"));
        let mut score = json(&copy.join("score.json"));
        score["selected"]["per_object"]["cube"]["mean_rotation_rad"] = cube.into();
        score["selected"]["per_object"]["sphere"]["mean_rotation_rad"] = sphere.into();
        std::fs::write(copy.join("score.json"), score.to_string()).expect("score.json");
    }
    let by_rotation = dir.join("compare-rotation");
    let compare = vge(
        &[
            "compare",
            "--metric",
            "rotation_rad",
            "--out",
            &by_rotation.display().to_string(),
            "--resamples",
            "2000",
        ],
        &[format!("vge={}", copies.join(","))],
    );
    assert!(compare.status.success(), "{}", text(&compare.stderr));
    let csv = std::fs::read_to_string(by_rotation.join("compare.csv")).expect("compare.csv");
    let selected: Vec<&str> =
        csv.lines().find(|l| l.starts_with("vge,selected,")).expect("vge's row").split(',').collect();
    let figure = |i: usize| selected[i].parse::<f64>().expect("a number");
    assert!((figure(3) - 3.75).abs() < 1e-4, "IQM of the rotations: {csv}");
    assert!((figure(6) - 13.0 / 3.0).abs() < 1e-4, "mean over objects: {csv}");
    let md = std::fs::read_to_string(by_rotation.join("compare.md")).expect("compare.md");
    assert!(md.contains("| rotation_rad IQM [95% CI] |") && md.contains("secondary reading"), "{md}");
    assert!(by_rotation.join("profiles.png").exists() && by_rotation.join("aggregates.png").exists());
    let bad = vge(&["compare", "--metric", "speed", "--out", &by_rotation.display().to_string()], &copies);
    assert!(!bad.status.success());
    assert!(
        text(&bad.stderr).contains("unknown metric `speed`; one of success, held, rotation_rad, return"),
        "{}",
        text(&bad.stderr)
    );

    // vge screen and vge ship measure the policy on each object.
    let screen = vge(&["screen", "--episodes", "1", "--min-success", "0"], &[run.display().to_string()]);
    assert!(screen.status.success(), "{}", text(&screen.stderr));
    assert!(run.join("screen.csv").exists());
    let policies = dir.join("shipped");
    let ship = vge(
        &[
            "ship",
            "--policy",
            "policy-best.vgep",
            "--name",
            "both",
            "--episodes",
            "2",
            "--robustness-episodes",
            "1",
        ],
        &[run.display().to_string(), "--policies".to_owned(), policies.display().to_string()],
    );
    assert!(ship.status.success(), "{}", text(&ship.stderr));
    let record = json(&policies.join("both.json"));
    let objects = record["per_object"].as_array().unwrap_or_else(|| panic!("per_object in {record}"));
    let names: Vec<&str> = objects.iter().map(|o| o["object"].as_str().expect("object")).collect();
    assert_eq!(names, ["cube", "sphere"], "the run's objects in its order");
    for (o, min) in objects.iter().zip([0.8, 0.5]) {
        let name = o["object"].as_str().expect("object");
        assert_eq!(o["success_test"]["episodes"].as_u64(), Some(2), "{o}");
        for key in ["return_fraction_at_paper_level", "success_at_paper_level"] {
            assert_eq!(o[key].as_object().map(|m| m.len()), Some(5), "{name}: {key} per axis: {o}");
        }
        let success = o["success_test"]["success_rate"].as_f64().expect("success_rate");
        let goal = format!("{name}: success_rate >= {min}");
        assert_eq!(record["goals"][&goal].as_bool(), Some(success >= min), "{goal} in {record}");
    }
    assert_eq!(record["success_test"]["episodes"].as_u64(), Some(4), "both objects' episodes pooled");
    assert!(record["goals"].get("success_rate >= 0.8").is_none(), "no pooled success goal: {record}");
    for object in ["cube", "sphere"] {
        assert_eq!(png_size_px(&policies.join(format!("both-gait-{object}.png"))), DIAGRAM_PX, "{object}");
    }
    assert_eq!(
        png_size_px(&policies.join("both-gait.png")),
        (STACKED_PANEL_PX.0, 2 * STACKED_PANEL_PX.1),
        "both objects' diagrams, one panel each, in NAME-gait.png"
    );

    // vge plot draws the per-object curves beside the usual figure.
    let png = dir.join("curves.png");
    let plot = vge(&["plot", "--out", &png.display().to_string()], &[run.display().to_string()]);
    assert!(plot.status.success(), "{}", text(&plot.stderr));
    // Two objects' columns: periodic evaluations above training episodes, 420 x 400 each.
    assert_eq!(png_size_px(&dir.join("curves-per-object.png")), (840, 800));
    // A run from a vge without the training episodes' per-object columns: one row, not an
    // empty one.
    let metrics = run.join("metrics.csv");
    let text_before = std::fs::read_to_string(&metrics).expect("metrics.csv");
    let keep: Vec<usize> = text_before
        .lines()
        .next()
        .expect("header")
        .split(',')
        .enumerate()
        .filter(|(_, c)| !c.starts_with("cube_") && !c.starts_with("sphere_"))
        .map(|(i, _)| i)
        .collect();
    let without: String = text_before
        .lines()
        .map(|l| {
            let fields: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| fields[i]).collect::<Vec<_>>().join(",") + "\n"
        })
        .collect();
    std::fs::write(&metrics, without).expect("metrics.csv");
    let plot = vge(&["plot", "--out", &png.display().to_string()], &[run.display().to_string()]);
    assert!(plot.status.success(), "{}", text(&plot.stderr));
    assert_eq!(png_size_px(&dir.join("curves-per-object.png")), (840, 400));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A single-object run writes no per-object columns or fields (it writes what it always did).
#[test]
fn a_single_object_run_writes_no_per_object_figures() {
    let dir = common::temp_dir("single-object-run");
    let config = common::config("cube-fg-vge.toml");
    let mut args = vec!["--config".to_owned(), config.display().to_string()];
    args.extend(common::tiny_args());
    for o in ["run.eval_interval=100", "sac.threads=1"] {
        args.extend(["--set".to_owned(), o.to_owned()]);
    }
    args.extend(["--steps".to_owned(), "200".to_owned(), "--out".to_owned(), dir.display().to_string()]);
    let out = vge(&["train"], &args);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let csv = std::fs::read_to_string(dir.join("eval.csv")).expect("eval.csv");
    assert_eq!(
        csv.lines().next(),
        Some("step,episodes,return,rotation,success,drops,contacts,contact_switches")
    );
    for file in ["final-eval.json", "best-eval.json"] {
        let doc = json(&dir.join(file));
        assert!(doc.get("per_object").is_none(), "{file}: {doc}");
        assert!(doc.get("validation_worst_object_success_rate").is_none(), "{file}");
        assert_eq!(doc["episodes"].as_u64(), Some(2), "{file}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `vge eval --objects all` on an untrained policy: one row per object of the paper's five
/// and the overall figures; each object's figures are `vge eval --object` on the same seeds.
#[test]
fn eval_objects_gives_one_row_per_object_on_the_episodes_of_eval_object() {
    let dir = common::temp_dir("eval-objects");
    let policy = dir.join("init.vgep");
    let export = vge(&["export", "--init", "--seed", "4", "--out"], &[policy.display().to_string()]);
    assert!(export.status.success(), "{}", text(&export.stderr));
    let p = policy.display().to_string();
    let common_args = ["--episodes", "2", "--episode-s", "1", "--seed", "9"];

    let table = vge(&["eval", "--objects", "all", "--policy", &p], &common_args.map(str::to_owned));
    assert!(table.status.success(), "{}", text(&table.stderr));
    let out = text(&table.stdout);
    let rows: Vec<&str> =
        out.lines().filter(|l| l.starts_with("  ") && !l.trim_start().starts_with("object")).collect();
    let names: Vec<&str> = rows.iter().map(|l| l.split_whitespace().next().expect("name")).collect();
    assert_eq!(names, ["cube", "sphere", "cylinder", "dodecahedron", "icosahedron", "overall"], "{out}");
    assert!(out.contains("verdict"), "{out}");

    let objects = ["sphere", "hexagonal-prism"];
    let png = dir.join("gait.png");
    let line = vge(
        &[
            "eval",
            "--json",
            "--objects",
            &objects.join(","),
            "--policy",
            &p,
            "--plot",
            &png.display().to_string(),
        ],
        &common_args.map(str::to_owned),
    );
    assert!(line.status.success(), "{}", text(&line.stderr));
    let doc: Value = serde_json::from_slice(&line.stdout).expect("one JSON line");
    assert_overall_pools(&doc, &objects, 2);
    let raw = text(&line.stdout);
    let at = |key: &str| raw.find(&format!("\"{key}\":{{")).unwrap_or_else(|| panic!("{key} in {raw}"));
    assert!(at("sphere") < at("hexagonal-prism"), "per_object in the order asked for: {raw}");
    assert_eq!(doc["per_episode"].as_array().map(Vec::len), Some(4));
    for object in objects {
        let single =
            vge(&["eval", "--json", "--object", object, "--policy", &p], &common_args.map(str::to_owned));
        assert!(single.status.success(), "{}", text(&single.stderr));
        let single: Value = serde_json::from_slice(&single.stdout).expect("one JSON line");
        for key in FIGURES {
            assert_eq!(doc["per_object"][object][key], single[key], "{object}: {key}");
        }
        assert_eq!(
            png_size_px(&dir.join(format!("gait-{object}.png"))),
            DIAGRAM_PX,
            "a gait diagram per object"
        );
    }
    assert_eq!(png_size_px(&png), (STACKED_PANEL_PX.0, 2 * STACKED_PANEL_PX.1), "and both in one figure");

    // A name twice, an unknown name, or both --object and --objects: refused, naming it.
    for (args, says) in [
        (vec!["--objects", "cube,cube"], "named twice"),
        (vec!["--objects", "cube,torus"], "torus"),
        (vec!["--objects", "all", "--object", "sphere"], "--object"),
    ] {
        let refused =
            vge(&["eval", "--policy", &p], &args.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>());
        assert!(!refused.status.success(), "{args:?}");
        assert!(text(&refused.stderr).contains(says), "{args:?}: {}", text(&refused.stderr));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
