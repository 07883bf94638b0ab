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
