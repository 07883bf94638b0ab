//! `vge` answers MKL's vendor check so that libtorch's SGEMM runs AVX-512 kernels on any CPU
//! that has them (vge_trainer::mkl), and `VGE_MKL_VENDOR_CHECK=1` restores MKL's own answer.
//! Read back through `vge bench update --json`'s `mkl_code_branch`, MKL's own report.

use std::process::Command;

fn code_branch(keep_vendor_check: bool) -> String {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_vge"));
    cmd.args(["bench", "update", "--updates", "1", "--batch", "8", "--json"]);
    if keep_vendor_check {
        cmd.env("VGE_MKL_VENDOR_CHECK", "1");
    } else {
        cmd.env_remove("VGE_MKL_VENDOR_CHECK");
    }
    let out = cmd.output().expect("vge runs");
    assert!(out.status.success(), "vge bench update failed: {}", String::from_utf8_lossy(&out.stderr));
    let line: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON line");
    line["mkl_code_branch"].as_str().expect("the PyPI libtorch has MKL").to_owned()
}

fn cpu_vendor() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").expect("/proc/cpuinfo");
    info.lines()
        .find_map(|l| l.strip_prefix("vendor_id").map(|v| v.trim_start_matches([' ', '\t', ':']).to_owned()))
        .expect("a vendor_id line")
}

#[test]
fn mkl_runs_its_avx512_kernels_wherever_the_cpu_has_them() {
    if !std::arch::is_x86_feature_detected!("avx512f") {
        eprintln!("this CPU has no AVX-512: nothing to check");
        return;
    }
    let branch = code_branch(false);
    assert!(branch.starts_with("avx512"), "MKL runs the {branch} branch on an AVX-512 CPU");
    let own = code_branch(true);
    if cpu_vendor() == "GenuineIntel" {
        assert_eq!(own, branch, "on Intel MKL's own answer is the same");
    } else {
        assert!(!own.starts_with("avx512"), "VGE_MKL_VENDOR_CHECK=1 left the override on ({own})");
    }
}
