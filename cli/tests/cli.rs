//! The `vge` command's machine-readable outputs, and `vge sweep`'s parallel jobs and Slurm
//! job script (cli/tests/slurm.rs runs that script on a real Slurm).

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

#[test]
fn bench_update_prints_one_json_line_per_learner() {
    for algorithm in ["sac", "td3"] {
        let out = Command::new(env!("CARGO_BIN_EXE_vge"))
            .args(["bench", "update", "--json", "--updates", "5", "--batch", "32", "--algorithm", algorithm])
            .output()
            .expect("vge runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let line = String::from_utf8_lossy(&out.stdout);
        assert_eq!(line.lines().count(), 1, "{line}");
        assert!(line.contains(&format!("\"algorithm\":\"{algorithm}\"")), "{line}");
        let field = |key: &str| -> f64 {
            let rest = line.split(&format!("\"{key}\":")).nth(1).unwrap_or_else(|| panic!("{key} in {line}"));
            rest.split([',', '}'])
                .next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{key}: {line}"))
        };
        assert!(field("updates_per_s") > 0.0 && field("matmul_gflops") > 0.0, "{line}");
    }
    // The default config's widths unless --hidden names others; widths a run refuses, refused.
    let widths = |extra: &[&str]| {
        let out = vge(
            &["bench", "update", "--json", "--updates", "2", "--batch", "8"],
            &extra.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
        );
        (out.status.success(), text(&out.stdout), text(&out.stderr))
    };
    let default_hidden = format!("{:?}", vge_run::config::Config::default().sac.hidden).replace(' ', "");
    let (ok, line, err) = widths(&[]);
    assert!(ok && line.contains(&format!("\"hidden\":{default_hidden}")), "{line}{err}");
    let (ok, line, err) = widths(&["--hidden", "48,24"]);
    assert!(ok && line.contains("\"hidden\":[48,24]"), "{line}{err}");
    let (ok, _, err) = widths(&["--hidden", "0"]);
    assert!(!ok && err.contains("--hidden") && err.contains("sac.hidden"), "{err}");
    let bad = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["bench", "update", "--algorithm", "ppo"])
        .output()
        .expect("vge runs");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("ppo"));
}

#[test]
fn bench_train_measures_the_envs_stepping_beside_and_between_the_updates() {
    let out = vge(
        &["bench", "train", "--json", "--threads", "1,2", "--overlap", "yes,no", "--fixed-threads", "yes"],
        &["--steps", "48", "--set", "sac.warmup=64", "--set", "sac.hidden=[32,32]", "--set", "sac.batch=32"]
            .map(String::from),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let rows: Vec<serde_json::Value> =
        stdout.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}"))).collect();
    // One thread never overlaps, so it is measured once; two threads both ways.
    let runs: Vec<(i64, &str)> = rows
        .iter()
        .map(|r| (r["threads"].as_i64().expect("threads"), r["overlap"].as_str().expect("overlap")))
        .collect();
    assert_eq!(runs, [(1, "yes"), (2, "yes"), (2, "no")], "{stdout}");
    for (row, (threads, overlap)) in rows.iter().zip(runs) {
        assert!(row["steps_per_s"].as_f64().expect("steps_per_s") > 0.0, "{row}");
        let beside_s = row["sim_beside_updates_s"].as_f64().expect("sim_beside_updates_s");
        assert_eq!(beside_s > 0.0, threads == 2 && overlap == "yes", "{row}");
    }
    let bad = vge(&["bench", "train", "--overlap", "sometimes"], &[]);
    assert!(!bad.status.success());
    assert!(text(&bad.stderr).contains("sometimes"));
}

#[test]
fn bench_controllers_reports_every_cost_and_refuses_zero_episodes() {
    let out = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["bench", "controllers", "--json", "--episodes", "1"])
        .output()
        .expect("vge runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    for key in [
        "qp_3_contacts_us",
        "qp_4_contacts_us",
        "qp_5_contacts_us",
        "igm_median_us",
        "igm_p90_us",
        "cs_median_us",
        "cs_p90_us",
        "fg_median_us",
        "fg_p90_us",
    ] {
        let v = doc[key].as_f64().unwrap_or_else(|| panic!("{key} missing in {doc}"));
        assert!(v.is_finite() && v > 0.0, "{key} = {v}");
    }
    // IGM solves contact-force QPs every call; CS reads a precomputed trajectory.
    assert!(doc["igm_median_us"].as_f64() > doc["cs_median_us"].as_f64(), "{doc}");
    let bad = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["bench", "controllers", "--episodes", "0"])
        .output()
        .expect("vge runs");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--episodes"));
}

#[test]
fn bench_cores_measures_the_cores_and_the_threads_that_fit_and_refuses_a_bad_window() {
    let out = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["bench", "cores", "--json", "--window-s", "0.2"])
        .output()
        .expect("vge runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    let number = |key: &str| doc[key].as_f64().unwrap_or_else(|| panic!("{key} missing in {doc}"));
    let (cores, busy, idle, fit) =
        (number("cores"), number("busy_cores"), number("idle_cores"), number("threads_that_fit"));
    assert!(cores >= 1.0 && (0.0..=cores + 1e-9).contains(&busy), "{doc}");
    assert!((busy + idle - cores).abs() < 1e-9, "busy and idle make up the cores: {doc}");
    assert_eq!(fit, (idle + 0.5).floor().max(1.0), "the idle cores, rounded, at least 1: {doc}");
    for window in ["0", "-1", "NaN", "61"] {
        let bad = Command::new(env!("CARGO_BIN_EXE_vge"))
            .args(["bench", "cores", &format!("--window-s={window}")])
            .output()
            .expect("vge runs");
        assert!(!bad.status.success(), "--window-s {window} accepted");
        assert!(String::from_utf8_lossy(&bad.stderr).contains("--window-s"), "--window-s {window}");
    }
}

#[test]
fn plot_groups_runs_by_experiment_and_learner_and_tabulates_success() {
    let root = std::env::temp_dir().join(format!("vge-plot-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let run = |name: &str, algorithm: &str, success: f64, offset: f64| {
        let dir = root.join(format!("{name}-{algorithm}-{offset}"));
        std::fs::create_dir_all(&dir).expect("dir");
        let config = format!("name = \"{name}\"\nalgorithm = \"{algorithm}\"\nseed = 0\n");
        std::fs::write(dir.join("config.toml"), config).expect("config");
        let mut metrics = String::from(
            "step,episodes,return,rotation,contacts,success,controller_share,p_psi,critic_loss,actor_loss,bc_loss,alpha,mean_q,beta,updates,steps_per_s\n",
        );
        for k in 1..=5 {
            let r = offset + k as f64;
            metrics.push_str(&format!(
                "{},{k},{r},{},3.5,0,0.3,0.5,1,1,0,0,1,0,{k},100\n",
                k * 1000,
                r / 20.0
            ));
        }
        std::fs::write(dir.join("metrics.csv"), metrics).expect("metrics");
        let eval =
            format!("step,episodes,return,rotation,success,drops,contacts\n5000,5,1,0.1,{success},0,3.5\n");
        std::fs::write(dir.join("eval.csv"), eval).expect("eval");
        dir
    };
    let dirs = [run("cube", "sac", 0.0, 0.0), run("cube", "sac", 0.2, 1.0), run("cube", "td3", 0.6, 2.0)];
    // The second SAC seed finished: its final evaluation (55%) decides, not its last eval.csv row.
    let final_eval = "{\"success_rate\": 0.55, \"env_steps\": 5000, \"wall_s\": 12.0, \"learned\": true}";
    std::fs::write(dirs[1].join("final-eval.json"), final_eval).expect("final eval");
    // Its model selection: the snapshot at 3000 succeeds in 70% of the test grasps.
    let best_eval = "{\"selected_step\": 3000, \"success_rate\": 0.7, \"learned\": true}";
    std::fs::write(dirs[1].join("best-eval.json"), best_eval).expect("best eval");
    let png = root.join("curves.png");
    let csv = root.join("success.csv");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vge"));
    cmd.arg("plot").args(&dirs).arg("--out").arg(&png).arg("--success-csv").arg(&csv);
    let out = cmd.output().expect("vge plot");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("| cube | 2 | 0.28 | 1/2 | 0.70 | 1/1 |"),
        "two SAC seeds in one row, one learned, one with a selection:\n{table}"
    );
    assert!(table.contains("| cube (td3) | 1 | 0.60 | 1/1 | - | - |"), "the TD3 run apart:\n{table}");
    let rows = std::fs::read_to_string(&csv).expect("success.csv");
    let rows: Vec<&str> = rows.lines().collect();
    assert_eq!(
        rows[0],
        "run,experiment,learned,success_rate,env_steps,wall_s,selected_step,selected_success_rate,selected_learned"
    );
    assert!(rows[1].ends_with(",cube,false,0.0000,,,,,"), "{}", rows[1]);
    assert!(rows[2].ends_with(",cube,true,0.5500,5000,12,3000,0.7000,true"), "{}", rows[2]);
    let bytes = std::fs::read(&png).expect("png written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let _ = std::fs::remove_dir_all(&root);
}

fn vge(args: &[&str], extra: &[String]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vge")).args(args).args(extra).output().expect("vge runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn sweep_jobs_trains_seeds_side_by_side_and_names_the_failed_seed() {
    let root = common::temp_dir("sweep-jobs");
    let config = common::config("cube-fg-vge.toml");
    let out = root.join("sweep");
    // A seed folder whose checkpoint is garbage: its `train --resume` fails.
    std::fs::create_dir_all(out.join("seed-2")).expect("dir");
    std::fs::write(out.join("seed-2/checkpoint"), "garbage").expect("write");
    let (config, dir) = (config.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    let args =
        ["sweep", "--config", config, "--seeds", "0..3", "--out", dir, "--steps", "300", "--jobs", "2"];
    let run = vge(&args, &common::tiny_args());
    let (stdout, stderr) = (text(&run.stdout), text(&run.stderr));
    assert!(!run.status.success(), "a failed seed fails the sweep\n{stdout}{stderr}");
    let log2 = out.join("seed-2/train.log");
    assert!(stderr.contains(&format!("seed 2 (log {})", log2.display())), "{stderr}");
    assert!(stdout.contains("seed 2: FAILED"), "{stdout}");
    for seed in [0, 1] {
        let run_dir = out.join(format!("seed-{seed}"));
        assert!(run_dir.join("policy.vgep").exists(), "seed {seed}\n{stdout}{stderr}");
        assert!(stdout.contains(&format!("seed {seed}: done, 300 steps")), "{stdout}");
        // With the final policy's success test (a 300-step policy does not learn).
        assert!(stdout.contains("% (did not learn); "), "{stdout}");
        let log = std::fs::read_to_string(run_dir.join("train.log")).expect("train.log");
        assert!(log.contains("policy written to"), "{log}");
        // One libtorch thread per job unless --set says otherwise.
        let cfg = std::fs::read_to_string(run_dir.join("config.toml")).expect("config.toml");
        assert!(cfg.contains("threads = 1"), "{cfg}");
    }
    let again = vge(&["sweep", "--config", config, "--seeds", "0..2", "--out", dir, "--jobs", "2"], &[]);
    assert!(again.status.success(), "{}", text(&again.stderr));
    assert!(text(&again.stdout).contains("seed 1: done already"), "{}", text(&again.stdout));
    let _ = std::fs::remove_dir_all(&root);
}

/// How the job script starts vge: as a job step, so that scancel's SIGTERM reaches it.
const SRUN: &str = "srun --ntasks=1 --cpus-per-task=\"${SLURM_CPUS_PER_TASK:-1}\"";

fn sbatch_dry_run(config: &Path, dir: &Path) -> Output {
    let (config, dir) = (config.to_str().expect("utf-8"), dir.to_str().expect("utf-8"));
    let args = [
        "sweep",
        "--config",
        config,
        "--seeds",
        "0..4",
        "--out",
        dir,
        "--slurm",
        "--dry-run",
        "--partition",
        "p1",
        "--time",
        "01:00:00",
        "--cpus-per-task",
        "2",
        "--steps",
        "500",
        "--set",
        "name=\"a b\"",
    ];
    vge(&args, &[])
}

#[test]
fn sweep_slurm_dry_run_writes_an_array_job_that_resumes_and_checkpoints() {
    let root = common::temp_dir("sweep-sbatch");
    let dir = root.join("sweep");
    // Seed 1 finished: a policy that reads back whole, and its final-eval.json.
    std::fs::create_dir_all(dir.join("seed-1")).expect("dir");
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../policies/cube.vgep");
    std::fs::copy(&shipped, dir.join("seed-1/policy.vgep")).expect("copy");
    std::fs::write(
        dir.join("seed-1/final-eval.json"),
        r#"{"success_rate": 1.0, "env_steps": 1, "wall_s": 1.0}"#,
    )
    .expect("write");
    std::fs::create_dir_all(dir.join("seed-2/checkpoint")).expect("dir");
    let config = common::config("cube-fg-vge.toml");
    let run = sbatch_dry_run(&config, &dir);
    assert!(run.status.success(), "{}", text(&run.stderr));
    let dir = dir.canonicalize().expect("dir");
    let script = std::fs::read_to_string(dir.join("sweep.sbatch")).expect("sweep.sbatch");
    let vge_bin = Path::new(env!("CARGO_BIN_EXE_vge")).canonicalize().expect("vge");
    let copied = dir.join("sweep-config.toml");
    // The copy stands alone: its base merged in, the same config.
    let copy_text = std::fs::read_to_string(&copied).expect("copied config");
    assert!(!copy_text.contains("cube-base.toml"), "{copy_text}");
    assert_eq!(
        vge_run::config::load_config(&copied, &[]).expect("the copy loads alone"),
        vge_run::config::load_config(&config, &[]).expect("config")
    );
    for line in [
        "#SBATCH --array=0,2-3".to_owned(), // seed 1 is done
        "#SBATCH --partition=p1".to_owned(),
        "#SBATCH --time=01:00:00".to_owned(),
        "#SBATCH --cpus-per-task=2".to_owned(),
        "#SBATCH --requeue".to_owned(),
        "#SBATCH --signal=TERM@120".to_owned(),
        format!("#SBATCH --output={}/slurm/%A_%a.out", dir.display()),
        "seed=$SLURM_ARRAY_TASK_ID".to_owned(),
        "elif [[ -d $run/checkpoint || -d $run/checkpoint.old ]]; then".to_owned(),
        format!(
            "  exec {SRUN} {} train --resume \"$run\" --seed \"$seed\" --steps 500 --set 'name=\"a b\"' --set sac.threads=2",
            vge_bin.display()
        ),
        format!(
            "  exec {SRUN} {} train --config {} --out \"$run\" --seed \"$seed\" --steps 500 --set 'name=\"a b\"' --set sac.threads=2",
            vge_bin.display(),
            copied.display()
        ),
    ] {
        assert!(script.lines().any(|l| l == line), "no line `{line}` in\n{script}");
    }
    // The script's branches, run by bash as a task would run them, with an `srun` that only
    // drops its options (no Slurm needed): seed 1 is skipped, seed 2 takes `--resume` (and
    // fails: its checkpoint is empty).
    let bin = root.join("bin");
    std::fs::create_dir_all(&bin).expect("dir");
    std::fs::write(bin.join("srun"), "#!/bin/bash\nwhile [[ $1 == -* ]]; do shift; done\nexec \"$@\"\n")
        .expect("srun");
    Command::new("chmod").arg("+x").arg(bin.join("srun")).status().expect("chmod");
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    for (seed, expect) in [(1, "seed 1: done already"), (2, "seed-2 is not a vge run directory")] {
        let status = Command::new("bash")
            .arg(dir.join("sweep.sbatch"))
            .env("SLURM_ARRAY_TASK_ID", seed.to_string())
            .env("SLURM_ARRAY_JOB_ID", "7")
            .env("PATH", &path)
            .status()
            .expect("bash");
        let log = std::fs::read_to_string(dir.join(format!("seed-{seed}/train.log"))).expect("train.log");
        assert!(log.contains(expect), "seed {seed} ({status}):\n{log}");
    }
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn sweep_slurm_refuses_jobs_a_missing_sbatch_and_another_config() {
    let root = common::temp_dir("sweep-slurm-errors");
    let config = common::config("cube-fg-vge.toml");
    let (c, d) = (config.to_str().expect("utf-8"), root.join("s"));
    let d = d.to_str().expect("utf-8");
    let both = vge(&["sweep", "--config", c, "--seeds", "0..2", "--out", d, "--slurm", "--jobs", "2"], &[]);
    assert!(!both.status.success());
    assert!(text(&both.stderr).contains("'--slurm' cannot be used with '--jobs"), "{}", text(&both.stderr));
    let no_sbatch = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["sweep", "--config", c, "--seeds", "0..2", "--out", d, "--slurm"])
        .env("PATH", root.as_os_str())
        .output()
        .expect("vge runs");
    assert!(!no_sbatch.status.success());
    assert!(text(&no_sbatch.stderr).contains("`sbatch` is not on PATH"), "{}", text(&no_sbatch.stderr));
    assert!(!root.join("s/sweep.sbatch").exists(), "nothing written when it cannot be submitted");
    assert!(sbatch_dry_run(&config, Path::new(d)).status.success());
    let other = common::config("cube-fg-rl.toml");
    let run = sbatch_dry_run(&other, Path::new(d));
    assert!(!run.status.success());
    assert!(text(&run.stderr).contains("holds a sweep of another config"), "{}", text(&run.stderr));
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn sweep_jobs_forwards_sigterm_so_every_running_seed_checkpoints() {
    let root = common::temp_dir("sweep-jobs-term");
    let config = common::config("cube-fg-vge.toml");
    let out = root.join("sweep");
    let (config, dir) = (config.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    let sweep = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args([
            "sweep", "--config", config, "--seeds", "0..3", "--out", dir, "--steps", "1000000", "--jobs", "2",
        ])
        .args(common::tiny_args())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("vge sweep");
    let started = std::time::Instant::now();
    let checkpointed =
        |seed: u64| vge_lab::sweep::checkpoint_step(&out.join(format!("seed-{seed}"))).is_some();
    while !(checkpointed(0) && checkpointed(1)) {
        assert!(started.elapsed().as_secs() < 120, "no periodic checkpoints of seeds 0 and 1");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let pid = nix::unistd::Pid::from_raw(i32::try_from(sweep.id()).expect("pid"));
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("SIGTERM");
    let end = sweep.wait_with_output().expect("vge sweep ends");
    let stdout = text(&end.stdout);
    // Stopped, not finished: 128 + SIGTERM, as each stopped seed exits.
    assert_eq!(end.status.code(), Some(143), "{stdout}{}", text(&end.stderr));
    for seed in [0, 1] {
        let run = out.join(format!("seed-{seed}"));
        let log = std::fs::read_to_string(run.join("train.log")).expect("train.log");
        let step = vge_lab::sweep::checkpoint_step(&run).expect("checkpoint");
        assert!(log.contains(&format!("stopped at step {step}: checkpoint saved")), "{log}");
        assert!(stdout.contains(&format!("seed {seed}: stopped at step {step} (exit 143)")), "{stdout}");
    }
    assert!(stdout.contains("seed 2: not started"), "{stdout}");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn robustness_writes_csv_json_and_png_with_one_row_per_axis_and_level() {
    let dir = common::temp_dir("robustness");
    let policy = dir.join("init.vgep");
    let export = vge(&["export", "--init", "--seed", "2", "--out"], &[policy.display().to_string()]);
    assert!(export.status.success(), "{}", text(&export.stderr));
    let out = dir.join("rob");
    let run = vge(
        &["robustness", "--episodes", "2", "--episode-s", "0.5", "--levels", "3", "--policy"],
        &[policy.display().to_string(), "--out".to_owned(), out.display().to_string()],
    );
    assert!(run.status.success(), "{}", text(&run.stderr));

    let csv = std::fs::read_to_string(out.join("robustness.csv")).expect("robustness.csv");
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 5 * 3, "{csv}");
    for (axis, max) in [
        ("joint_noise_rad", 0.1),
        ("normal_error_frac", 0.5),
        ("position_error_m", 0.003),
        ("perturbation_force_n", 0.15 * 9.81),
        ("perturbation_magnitude_n", 0.15 * 9.81),
    ] {
        let levels: Vec<f64> =
            rows.iter().filter(|r| r[0] == axis).map(|r| r[1].parse().expect("level")).collect();
        assert_eq!(levels.len(), 3, "{axis}: {csv}");
        assert!(levels[0] == 0.0 && (levels[1] - max / 2.0).abs() < 1e-6 && (levels[2] - max).abs() < 1e-6);
    }
    // Level 0 of every axis is the same undisturbed run: return fraction exactly 1.
    let clean: Vec<&Vec<&str>> = rows.iter().filter(|r| r[1] == "0").collect();
    assert_eq!(clean.len(), 5);
    assert!(clean.iter().all(|r| r[3] == clean[0][3]), "{csv}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("robustness.json")).expect("json"))
            .expect("valid");
    assert_eq!(json["rows"].as_array().map(Vec::len), Some(15));
    assert_eq!(json["episodes"], 2);
    let png = std::fs::read(out.join("robustness.png")).expect("png");
    assert!(png.len() > 10_000 && png.starts_with(b"\x89PNG"), "{} bytes", png.len());

    let refused = vge(
        &["robustness", "--levels", "1", "--policy"],
        &[policy.display().to_string(), "--out".into(), out.display().to_string()],
    );
    assert!(!refused.status.success() && text(&refused.stderr).contains("--levels"));

    // Screening on the pushes alone: only the named axes, in the order given.
    let pushes = dir.join("pushes");
    let run = vge(
        &["robustness", "--episodes", "1", "--episode-s", "0.5", "--levels", "2", "--policy"],
        &[
            policy.display().to_string(),
            "--axes".to_owned(),
            "perturbation_magnitude_n,perturbation_force_n".to_owned(),
            "--out".to_owned(),
            pushes.display().to_string(),
        ],
    );
    assert!(run.status.success(), "{}", text(&run.stderr));
    let csv = std::fs::read_to_string(pushes.join("robustness.csv")).expect("robustness.csv");
    let axes: Vec<&str> = csv.lines().skip(1).filter_map(|l| l.split(',').next()).collect();
    assert_eq!(
        axes,
        [
            "perturbation_magnitude_n",
            "perturbation_magnitude_n",
            "perturbation_force_n",
            "perturbation_force_n"
        ],
        "{csv}"
    );
    assert!(std::fs::read(pushes.join("robustness.png")).expect("png").starts_with(b"\x89PNG"));
    for (bad, says) in [("joint_noise", "unknown axis"), ("joint_noise_rad,joint_noise_rad", "twice")] {
        let refused = vge(
            &["robustness", "--axes", bad, "--policy"],
            &[policy.display().to_string(), "--out".into(), pushes.display().to_string()],
        );
        assert!(
            !refused.status.success() && text(&refused.stderr).contains(says),
            "{}",
            text(&refused.stderr)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eval_plot_draws_the_gait_diagram_of_one_episode() {
    let dir = common::temp_dir("gait-plot");
    let policy = dir.join("init.vgep");
    let export = vge(&["export", "--init", "--seed", "3", "--out"], &[policy.display().to_string()]);
    assert!(export.status.success(), "{}", text(&export.stderr));
    // Into a folder that does not exist yet: it is made.
    let png = dir.join("figures/new").join("gait.png");
    let run = vge(
        &["eval", "--episodes", "1", "--episode-s", "1", "--json", "--policy"],
        &[policy.display().to_string(), "--plot".to_owned(), png.display().to_string()],
    );
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(text(&run.stderr).contains("gait diagram"), "{}", text(&run.stderr));
    let bytes = std::fs::read(&png).expect("the PNG");
    assert!(bytes.len() > 10_000 && bytes.starts_with(b"\x89PNG"), "{} bytes", bytes.len());

    // A folder that cannot be made (a file stands in its place) is named.
    let blocked = dir.join("a-file");
    std::fs::write(&blocked, b"").expect("a file");
    let refused = vge(
        &["eval", "--episodes", "1", "--episode-s", "1", "--policy"],
        &[policy.display().to_string(), "--plot".to_owned(), blocked.join("gait.png").display().to_string()],
    );
    assert!(!refused.status.success());
    assert!(text(&refused.stderr).contains(&blocked.display().to_string()), "{}", text(&refused.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `vge eval --run DIR` scores a finished run's final policy again on its own episodes, shows
/// the stored figures beside the new ones, and with `--write` replaces `final-eval.json`
/// keeping what describes the training (env steps, wall and CPU time).
#[test]
fn eval_run_rescores_a_finished_run_and_write_replaces_its_final_eval() {
    let stored = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/runs/euler-yaw-fge-seed-0");
    let dir = common::temp_dir("rescore");
    for file in ["config.toml", "policy.vgep"] {
        std::fs::copy(stored.join(file), dir.join(file)).expect("copy the run");
    }
    let mut doc: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(stored.join("final-eval.json")).expect("final-eval.json"),
    )
    .expect("json");
    doc["success_rate"] = serde_json::json!(0.125);
    doc["cpu_s"] = serde_json::json!(11.5);
    std::fs::write(dir.join("final-eval.json"), doc.to_string()).expect("write");
    let arg = dir.display().to_string();

    let shown = vge(&["eval", "--run"], std::slice::from_ref(&arg));
    assert!(shown.status.success(), "{}", text(&shown.stderr));
    let out = text(&shown.stdout);
    assert!(out.contains("success rate     0.850 (stored: 0.125)"), "{out}");
    assert!(out.contains("  fingertip slip   ") && out.contains(" m per rad turned"), "{out}");
    assert!(out.contains("about an axis tilted ") && out.contains(" deg from z"), "{out}");
    let written = vge(&["eval", "--write", "--run"], std::slice::from_ref(&arg));
    assert!(written.status.success(), "{}", text(&written.stderr));
    let now: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("final-eval.json")).expect("rewritten"))
            .expect("json");
    assert_eq!(now["success_rate"], 0.85);
    assert_eq!(now["env_steps"], doc["env_steps"]);
    assert_eq!(now["wall_s"], doc["wall_s"]);
    assert_eq!(now["cpu_s"], doc["cpu_s"]);
    assert_eq!(now["per_episode"].as_array().map(Vec::len), Some(20));
    let slip = now["mean_tip_slip_m"].as_f64().expect("the slip figure");
    assert!(slip.is_finite() && slip > 0.0, "the fixture's policy turns the cube: {slip} m");
    assert!(now["per_episode"][0]["tip_slip_m"].as_f64().is_some_and(f64::is_finite), "{now}");
    let tilt = now["mean_rotation_axis_tilt_rad"].as_f64().expect("the tilt figure");
    assert!((0.0..=std::f64::consts::FRAC_PI_2 + 1e-9).contains(&tilt), "{tilt} rad");

    // An unfinished run (no final-eval.json) cannot be rewritten; neither flag: an error.
    std::fs::remove_file(dir.join("final-eval.json")).expect("remove");
    let refused = vge(&["eval", "--write", "--run"], &[arg]);
    assert!(!refused.status.success());
    assert!(text(&refused.stderr).contains("not a finished run"), "{}", text(&refused.stderr));
    let neither = vge(&["eval"], &[]);
    assert!(!neither.status.success());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The tilt of the axis a policy turns the object about tells an upright turn from a tumble
/// that the success test counts only in its z part: the shipped vge15 gait turns the cube
/// about z, the shipped Allegro policy tumbles it about an axis far from vertical; both pass
/// the success test, and only the first passes it with the object upright (`--max-tilt-rad`).
#[test]
fn eval_reports_how_far_the_turning_axis_leans_from_z() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    // (tilt of the turning axis in deg, upright success rate)
    let tilt_deg = |policy: &str| -> (f64, f64) {
        let path = root.join("policies").join(policy).display().to_string();
        let out = vge(&["eval", "--episodes", "2", "--json", "--max-tilt-rad", "0.35", "--policy"], &[path]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let line = text(&out.stdout);
        let doc: serde_json::Value =
            serde_json::from_str(line.lines().next().expect("a line")).expect("json");
        let net =
            doc["per_episode"][0]["net_rotation_rad"].as_array().expect("the net rotation vector").clone();
        let z = net[2].as_f64().expect("z");
        assert!(
            (z - doc["per_episode"][0]["rotation_rad"].as_f64().expect("rotation")).abs() < 1e-6,
            "{doc}"
        );
        assert_eq!(doc["success_rate"].as_f64(), Some(1.0), "{policy}: {doc}");
        assert_eq!(doc["max_tilt_rad"].as_f64(), Some(0.35), "{doc}");
        let tilt_deg = doc["mean_rotation_axis_tilt_rad"].as_f64().expect("the tilt").to_degrees();
        (tilt_deg, doc["upright_success_rate"].as_f64().expect("the upright success rate"))
    };
    let (upright, upright_success) = tilt_deg("cube.vgep");
    let (tumbling, tumbling_success) = tilt_deg("allegro-cube.vgep");
    assert!(upright < 20.0, "the vge15 gait turns the cube about an axis {upright} deg from z");
    assert!(tumbling > 45.0, "the Allegro policy turns the cube about an axis {tumbling} deg from z");
    assert_eq!((upright_success, tumbling_success), (1.0, 0.0));
    // A bound a tilt cannot have is refused before any episode.
    let policy = root.join("policies/cube.vgep").display().to_string();
    let refused = vge(&["eval", "--max-tilt-rad", "1.6", "--policy"], &[policy]);
    assert!(!refused.status.success());
    assert!(text(&refused.stderr).contains("outside 0 to pi/2"), "{}", text(&refused.stderr));
}

/// `--max-tilt-rad` with `--objects`: each object's upright success rate beside its success
/// rate, in the order asked for. The shipped multi-object gait turns its objects upright, so
/// every success is an upright one, and a bound of 0 rad passes none.
#[test]
fn eval_objects_scores_the_upright_success_test_per_object() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let policy = root.join("policies/multi-object.vgep").display().to_string();
    // (the report, its raw line: serde_json's Value sorts keys, the line keeps their order)
    let run = |max_tilt_rad: &str| -> (serde_json::Value, String) {
        let args = ["eval", "--json", "--objects", "sphere,cube", "--episodes", "2", "--episode-s", "10"];
        let out = vge(
            &args,
            &["--max-tilt-rad".to_owned(), max_tilt_rad.to_owned(), "--policy".to_owned(), policy.clone()],
        );
        assert!(out.status.success(), "{}", text(&out.stderr));
        (serde_json::from_slice(&out.stdout).expect("one JSON line"), text(&out.stdout))
    };
    let (doc, raw) = run("0.35");
    let upright = doc["upright_success_rate_per_object"].as_object().expect("per object");
    assert_eq!(upright.len(), 2, "{doc}");
    let per_object = &raw[raw.find("\"upright_success_rate_per_object\"").expect("the key")..];
    let at = |name: &str| per_object.find(&format!("\"{name}\"")).expect(name);
    assert!(at("sphere") < at("cube"), "in the order asked for: {per_object}");
    for (object, rate) in upright {
        assert_eq!(rate.as_f64(), doc["per_object"][object]["success_rate"].as_f64(), "{object}: {doc}");
    }
    assert!(doc["upright_success_rate"].as_f64().expect("overall") > 0.0, "{doc}");
    assert_eq!(doc["upright_success_rate"], doc["success_rate"], "{doc}");
    let (none, _) = run("0");
    assert_eq!(none["upright_success_rate"].as_f64(), Some(0.0), "{none}");
}

#[test]
fn resuming_a_run_stored_before_a_default_changed_is_refused_with_the_fix() {
    let root = std::env::temp_dir().join(format!("vge-cli-old-default-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).expect("temp dir");
    // A run trained on the paper's reward, before env.charge_reverse_rotation existed.
    let stored =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/configs/paper-reward-vge-seed-0.toml");
    let old = std::fs::read_to_string(stored).expect("stored config");
    std::fs::write(root.join("config.toml"), &old).expect("write");
    let out = vge(&["train", "--resume", root.to_str().expect("utf-8")], &[]);
    let err = text(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("predates env.charge_reverse_rotation") && err.contains("= false"), "{err}");
    // With the key written in, the config passes and the missing checkpoint is what stops it.
    let fixed = old.replacen("[env]\n", "[env]\ncharge_reverse_rotation = false\n", 1);
    assert_ne!(fixed, old);
    std::fs::write(root.join("config.toml"), &fixed).expect("write");
    let out = vge(&["train", "--resume", root.to_str().expect("utf-8")], &[]);
    let err = text(&out.stderr);
    assert!(!out.status.success() && !err.contains("predates") && err.contains("checkpoint"), "{err}");
    // A run from before the learner could be chosen trained with SAC, the default then.
    let sac_era = fixed.replacen("algorithm = \"td3\"\n", "", 1);
    assert_ne!(sac_era, fixed);
    std::fs::write(root.join("config.toml"), sac_era).expect("write");
    let out = vge(&["train", "--resume", root.to_str().expect("utf-8")], &[]);
    let err = text(&out.stderr);
    assert!(err.contains("predates algorithm") && err.contains("algorithm = \"sac\""), "{err}");
    let _ = std::fs::remove_dir_all(&root);
}

/// A resume keeps the run's config: `--seed` or a `--set` that changes it is refused naming the
/// key, while `--steps` passes that check (and here stops at the missing checkpoint).
#[test]
fn resuming_with_another_config_is_refused_naming_the_key() {
    let root = common::temp_dir("cli-resume-change");
    let stored =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/configs/paper-reward-vge-seed-0.toml");
    let config = std::fs::read_to_string(stored).expect("stored config").replacen(
        "[env]\n",
        "[env]\ncharge_reverse_rotation = false\n",
        1,
    );
    std::fs::write(root.join("config.toml"), &config).expect("write");
    let dir = root.to_str().expect("utf-8");
    let out = vge(&["train", "--resume", dir, "--seed", "7"], &[]);
    let err = text(&out.stderr);
    assert!(!out.status.success() && err.contains("seed = 0 -> 7") && err.contains("--resume"), "{err}");
    let out = vge(&["train", "--resume", dir, "--set", "vge.horizon=3"], &[]);
    let err = text(&out.stderr);
    assert!(!out.status.success() && err.contains("vge.horizon = ") && err.contains("-> 3"), "{err}");
    let out = vge(&["train", "--resume", dir, "--steps", "123456"], &[]);
    let err = text(&out.stderr);
    assert!(
        !out.status.success() && !err.contains("keeps the config") && err.contains("checkpoint"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(root.join("config.toml")).expect("read"),
        config,
        "the stored config is kept"
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// `vge screen` screens the snapshots whose periodic test passed (and the
/// final policy) on the success test and the two pushes, with the real vge.
#[test]
fn screen_snapshots_tests_the_passing_snapshots_and_the_final_policy() {
    let run = common::temp_dir("screen-snapshots");
    let snapshots = run.join("snapshots");
    std::fs::create_dir_all(&snapshots).expect("snapshots/");
    for (name, seed) in
        [("snapshots/policy-100.vgep", "4"), ("snapshots/policy-200.vgep", "5"), ("policy.vgep", "6")]
    {
        let export =
            vge(&["export", "--init", "--seed", seed, "--out"], &[run.join(name).display().to_string()]);
        assert!(export.status.success(), "{}", text(&export.stderr));
    }
    // 200 failed its test; 300 passed but its snapshot is gone; 400 is the final policy.
    std::fs::copy(run.join("policy.vgep"), snapshots.join("policy-400.vgep")).expect("copy");
    let header = "step,episodes,return,rotation,success,drops,contacts,contact_switches";
    let eval_csv = format!(
        "{header}\n100,20,1,1,0.9000,0,4,1\n200,20,1,1,0.1000,0,4,1\n300,20,1,1,1.0000,0,4,1\n400,20,1,1,0.8000,0,4,1\n"
    );
    std::fs::write(run.join("eval.csv"), eval_csv).expect("eval.csv");
    let screen =
        |dir: &Path| vge(&["screen", "--seed", "11000", "--episodes", "1"], &[dir.display().to_string()]);
    // The policies are measured on the run's task, which its config.toml holds: without it,
    // the screen is refused naming the file (and the OS's error once).
    let refused = screen(&run);
    let err = text(&refused.stderr);
    assert!(!refused.status.success() && err.contains("config.toml"), "{err}");
    assert_eq!(err.matches("No such file or directory").count(), 1, "{err}");
    let config = vge_run::config::load_config(&common::config("cube-fg-rl.toml"), &[]).expect("config");
    std::fs::write(run.join("config.toml"), config.to_toml_string().expect("toml")).expect("config.toml");
    let out = screen(&run);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let csv = std::fs::read_to_string(run.join("screen.csv")).expect("screen.csv");
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0][0], "step");
    let steps: Vec<&str> = rows[1..].iter().map(|r| r[0]).collect();
    assert_eq!(steps, ["100", "400"], "the final policy is snapshot 400, screened once: {csv}");
    for row in &rows[1..] {
        assert_eq!(row.len(), rows[0].len(), "{csv}");
        let success: f64 = row[1].parse().expect("success");
        assert!((0.0..=1.0).contains(&success), "{csv}");
    }

    let empty = common::temp_dir("screen-snapshots-empty");
    let refused = screen(&empty);
    let err = text(&refused.stderr);
    assert!(!refused.status.success() && err.contains("eval.csv") && err.contains("missing"), "{err}");
    let _ = std::fs::remove_dir_all(&run);
    let _ = std::fs::remove_dir_all(&empty);
}

/// `vge ship` copies the run's policy and config, measures the copy on the run's own task (here
/// the 0.4 kg cube of a task variant, whose paper-level push is its own weight) and writes its
/// record, robustness figure and gait diagram; a run that is not finished is refused and
/// nothing is written; a name already shipped is refused unless --force replaces it.
#[test]
fn ship_copies_measures_and_records_a_finished_runs_policy_and_refuses_an_unfinished_one() {
    let run = common::temp_dir("ship-run");
    let export = vge(
        &["export", "--init", "--seed", "3", "--out"],
        &[run.join("policy-best.vgep").display().to_string()],
    );
    assert!(export.status.success(), "{}", text(&export.stderr));
    // A run folder stores its config whole (its base merged in).
    let variant =
        vge_run::config::load_config(&common::config("variants/heavy-cube.toml"), &[]).expect("config");
    std::fs::write(run.join("config.toml"), variant.to_toml_string().expect("toml")).expect("config");
    let policies = run.join("shipped");
    let ship_with = |policy: &str, force: bool| {
        let mut args =
            vec![run.display().to_string(), "--policies".to_owned(), policies.display().to_string()];
        if force {
            args.push("--force".to_owned());
        }
        vge(
            &["ship", "--policy", policy, "--name", "trial", "--episodes", "1", "--robustness-episodes", "1"],
            &args,
        )
    };
    let ship = || ship_with("policy-best.vgep", false);
    // No final-eval.json: not a finished run.
    let refused = ship();
    let err = text(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("final-eval.json") && err.contains("not a finished"),
        "{err}"
    );
    assert!(!policies.exists(), "a refused ship wrote files");

    std::fs::write(run.join("final-eval.json"), r#"{"success_rate": 0.0, "env_steps": 1, "wall_s": 1.0}"#)
        .expect("json");
    let out = ship();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let read = |name: &str| std::fs::read(policies.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(read("trial.vgep") == std::fs::read(run.join("policy-best.vgep")).expect("policy"));
    assert!(read("trial.toml") == std::fs::read(run.join("config.toml")).expect("config"));
    assert!(read("trial-robustness.png").starts_with(b"\x89PNG"));
    assert!(read("trial-gait.png").starts_with(b"\x89PNG"));
    let record: serde_json::Value = serde_json::from_slice(&read("trial.json")).expect("trial.json");
    assert_eq!(record["source_policy"], "policy-best.vgep");
    assert!(record["provenance"].as_str().expect("provenance").contains("seed"), "{record}");
    assert_eq!(record["success_test"]["episodes"], 1);
    // An untrained actor turns nothing: the success goal fails, and says so.
    assert_eq!(record["goals"]["success_rate >= 0.8"], false, "{record}");
    let axes = record["return_fraction_at_paper_level"].as_object().expect("per axis");
    assert_eq!(axes.len(), 5, "{record}");
    // The pushes at the paper's level weigh what the run's cube weighs: 0.4 kg, not 0.15.
    let rows = record["robustness"]["rows"].as_array().expect("rows");
    let push = rows
        .iter()
        .find(|r| r["axis"] == "perturbation_magnitude_n" && r["fraction_of_max"] == 1.0)
        .expect("the paper-level push");
    let level_n = push["level"].as_f64().expect("level");
    assert!((level_n - 0.4 * 9.81).abs() < 1e-3, "{push}");
    assert!(record.get("per_object").is_none(), "one object, no per_object: {record}");
    assert!(text(&out.stdout).contains("FAILS  success_rate >= 0.8"), "{}", text(&out.stdout));

    // Shipping another policy under the same name is refused before anything is measured,
    // and the shipped files stay; --force replaces them.
    let other =
        vge(&["export", "--init", "--seed", "4", "--out"], &[run.join("policy.vgep").display().to_string()]);
    assert!(other.status.success(), "{}", text(&other.stderr));
    let shipped = read("trial.vgep");
    let refused = ship_with("policy.vgep", false);
    let err = text(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("trial.vgep exists") && err.contains("--force"),
        "{err}"
    );
    assert!(!err.contains("measuring"), "refused before measuring: {err}");
    assert!(read("trial.vgep") == shipped, "a refused ship replaced the policy");
    let forced = ship_with("policy.vgep", true);
    assert!(forced.status.success(), "{}", text(&forced.stderr));
    assert!(read("trial.vgep") == std::fs::read(run.join("policy.vgep")).expect("policy"));
    assert!(read("trial.vgep") != shipped, "two seeds, two policies");
    let _ = std::fs::remove_dir_all(&run);
}

#[test]
fn export_init_refuses_a_network_the_runtime_cannot_run_before_building_it() {
    let out = std::env::temp_dir().join(format!("vge-export-too-big-{}.vgep", std::process::id()));
    for hidden in ["100000000000", "64,64,64,64", "0"] {
        let export = vge(&["export", "--init", "--hidden", hidden, "--out"], &[out.display().to_string()]);
        let err = text(&export.stderr);
        assert_eq!(export.status.code(), Some(1), "--hidden {hidden}: an error, not a panic: {err}");
        assert!(err.contains("at most 3 hidden layers of 1 to 256 units"), "--hidden {hidden}: {err}");
        assert!(!out.exists(), "--hidden {hidden}: nothing written");
    }
}
