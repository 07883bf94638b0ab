//! The `vge` command's machine-readable outputs.

use std::process::Command;

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
    let bad = Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(["bench", "update", "--algorithm", "ppo"])
        .output()
        .expect("vge runs");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("ppo"));
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
    let png = root.join("curves.png");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vge"));
    cmd.arg("plot").args(&dirs).arg("--out").arg(&png);
    let out = cmd.output().expect("vge plot");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("| cube | 2 |"), "two SAC seeds in one row:\n{table}");
    assert!(table.contains("| cube (td3) | 1 |"), "the TD3 run apart:\n{table}");
    let bytes = std::fs::read(&png).expect("png written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let _ = std::fs::remove_dir_all(&root);
}
