//! `vge_lab::stats` against the reference: the same aggregates of the same score arrays
//! computed by the `rliable` package (PyPI, in .deps/py; `rliable_aggregates.py`). Point
//! estimates (IQM, mean, profile fractions) must agree to 1e-9; interval bounds, which come
//! from different resampling draws, within 0.02; the probability of improvement within 0.02.
//! Without Python or rliable the test fails: it is the check that the statistics are the
//! field's.

use crate::common;

use std::io::Write;
use std::process::{Command, Stdio};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vge_lab::stats::{Bootstrap, Estimate, Scores};

/// Enough resamples that both sides' percentile bounds sit well within the tolerance.
const RESAMPLES: usize = 5_000;

/// Groups of run scores, `[task][run]`: success rates on 100 episodes (multiples of 0.01)
/// like `score.json`'s, with ties, a bimodal group like Table I's cells, and a group on three
/// tasks so that the resampling must be stratified by task.
fn groups() -> Vec<(&'static str, Vec<Vec<f64>>)> {
    vec![
        ("vge", vec![vec![0.97, 0.12, 0.88, 1.0, 0.05, 0.93, 0.71, 0.0, 0.99, 0.64]]),
        ("fge", vec![vec![0.95, 0.81, 1.0, 1.0, 0.77, 0.9]]),
        ("rl", vec![vec![0.35, 0.9, 0.0, 0.62, 0.62, 0.41, 0.08]]),
        (
            "tasks-a",
            vec![
                vec![0.2, 0.4, 0.9, 0.55, 0.3],
                vec![0.8, 0.85, 0.1, 0.95, 0.6],
                vec![0.0, 0.05, 0.5, 0.15, 0.45],
            ],
        ),
        (
            "tasks-b",
            vec![
                vec![0.1, 0.3, 0.6, 0.2, 0.25],
                vec![0.9, 0.7, 0.75, 0.4, 0.85],
                vec![0.05, 0.0, 0.2, 0.1, 0.3],
            ],
        ),
    ]
}

/// One pair both ways round, and a pair on three tasks (stratified). rliable takes ~10 s of
/// CPU per pair at `RESAMPLES`.
const PAIRS: [(&str, &str); 3] = [("vge", "rl"), ("rl", "vge"), ("tasks-a", "tasks-b")];

const TAUS: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 0.95];

/// rliable's figures for `groups()` and `TAUS` (`part` "groups": aggregates and profiles) or
/// for `PAIRS` (`part` "pairs": probabilities of improvement). Two parts, two tests: each
/// takes rliable tens of seconds, and tests run side by side.
fn rliable(part: &str) -> serde_json::Value {
    let request = serde_json::json!({
        "part": part,
        "reps": RESAMPLES,
        "groups": groups()
            .into_iter()
            .map(|(name, by_task)| (name.to_owned(), serde_json::json!(by_task)))
            .collect::<serde_json::Map<String, serde_json::Value>>(),
        "pairs": PAIRS,
        "taus": TAUS,
    });
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rliable_aggregates.py");
    let mut child = Command::new(common::python())
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh with rliable)");
    child.stdin.take().expect("stdin").write_all(request.to_string().as_bytes()).expect("request");
    let out = child.wait_with_output().expect("python ends");
    assert!(
        out.status.success(),
        "rliable could not compute the aggregates (scripts/test.sh installs it in .deps/py): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("rliable's JSON")
}

/// `[point, low, high]` of rliable's JSON.
fn triple(v: &serde_json::Value) -> [f64; 3] {
    let a: Vec<f64> = v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect();
    [a[0], a[1], a[2]]
}

fn assert_close(what: &str, ours: Estimate, theirs: [f64; 3], point_tol: f64, bound_tol: f64) {
    assert!((ours.point - theirs[0]).abs() <= point_tol, "{what}: ours {ours:?}, rliable's {theirs:?}");
    assert!(
        (ours.ci_low - theirs[1]).abs() <= bound_tol && (ours.ci_high - theirs[2]).abs() <= bound_tol,
        "{what}: interval ours [{}, {}], rliable's [{}, {}]",
        ours.ci_low,
        ours.ci_high,
        theirs[1],
        theirs[2]
    );
}

fn bootstrap_and_scores() -> (Bootstrap, Vec<(&'static str, Scores)>) {
    let bootstrap = Bootstrap { resamples: RESAMPLES, ..Bootstrap::default() };
    let scores = groups()
        .into_iter()
        .map(|(name, by_task)| (name, Scores::by_task(by_task).expect("scores")))
        .collect();
    (bootstrap, scores)
}

#[test]
fn iqm_mean_intervals_and_profiles_agree_with_rliable() {
    let theirs = rliable("groups");
    let (bootstrap, scores) = bootstrap_and_scores();
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    for (name, s) in &scores {
        let a = bootstrap.aggregates(s, &mut rng).expect("aggregates");
        let g = &theirs["groups"][name];
        assert_close(&format!("{name} IQM"), a.iqm, triple(&g["iqm"]), 1e-9, 0.02);
        assert_close(&format!("{name} mean"), a.mean, triple(&g["mean"]), 1e-9, 0.02);
        // A check that can fail: the groups' intervals are not degenerate.
        assert!(a.iqm.ci_high - a.iqm.ci_low > 0.05, "{name}: {a:?}");

        let profile = bootstrap.performance_profile(s, &TAUS, &mut rng).expect("profile");
        let p = &theirs["profiles"][name];
        for (k, e) in profile.iter().enumerate() {
            let band = [p["points"][k].as_f64(), p["low"][k].as_f64(), p["high"][k].as_f64()]
                .map(|v| v.expect("number"));
            // A band's bounds are fractions of the runs: a draw's difference moves them by
            // whole runs at most once in a while; the point is exact.
            assert_close(
                &format!("{name} profile at tau {}", TAUS[k]),
                *e,
                band,
                1e-9,
                1.0 / s.runs() as f64 + 0.02,
            );
        }
    }
}

#[test]
fn probabilities_of_improvement_and_their_intervals_agree_with_rliable() {
    let theirs = rliable("pairs");
    let (bootstrap, scores) = bootstrap_and_scores();
    let of = |name: &str| &scores.iter().find(|(n, _)| *n == name).expect("group").1;
    let mut rng = ChaCha8Rng::seed_from_u64(43);
    for (k, (x, y)) in PAIRS.iter().enumerate() {
        let ours = bootstrap.probability_of_improvement(of(x), of(y), &mut rng).expect("P(X > Y)");
        let row = &theirs["pairs"][k];
        assert_eq!((row[0].as_str(), row[1].as_str()), (Some(*x), Some(*y)));
        let t = [row[2].as_f64(), row[3].as_f64(), row[4].as_f64()].map(|v| v.expect("number"));
        // The point is exact (a tie counts half, one pair of 10 x 7 runs is worth 0.014); the
        // bounds differ by the draws.
        assert_close(&format!("P({x} > {y})"), ours, t, 1e-9, 0.02);
    }
}
