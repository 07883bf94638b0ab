//! A real exported policy on an emulated Cortex-M4F: exports a seeded tch actor
//! 65 -> 256 -> 256 -> 15 to a policy file with vge-export, builds `runtime/firmware-m4` for
//! `thumbv7em-none-eabihf` with `VGE_POLICY` pointing at it (the firmware embeds the file
//! and loads it with `vge_runtime::Policy::load`), runs it in
//! `qemu-system-arm -machine mps2-an386`, parses the observations and actions it prints over
//! semihosting, and checks them against the host `vge_runtime::Policy` (max abs diff <= 1e-6)
//! and tch (<= 1e-5). A firmware built with a corrupted file must reject it and exit 1.
//!
//! Here rather than in vge-tests because it needs tch, which this crate already links (with
//! the libtorch rpath from its build.rs); vge-tests stays free of libtorch.
//!
//! Needs `qemu-system-arm` (Debian package `qemu-system-arm`) and the `thumbv7em-none-eabihf`
//! rustup target; scripts/test.sh installs both. Missing either is a failure, not a skip.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use tch::nn::{Module, VarStore};
use tch::{Device, Tensor};
use vge_export::{ActorSpec, ObsNorm, ObsSlice, PolicyMeta, Provenance, build_actor, export_policy};
use vge_runtime::HandPolicy;

const OBS_DIM: usize = 65;
const ACT_DIM: usize = 15;
/// Observations the firmware evaluates (`N_CASES` in runtime/firmware-m4/src/main.rs).
const N_CASES: usize = 8;
const QEMU: &str = "qemu-system-arm";
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);
const TOLERANCE: f32 = 1e-6;

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Builds the firmware with `VGE_POLICY=policy` into `target/firmware-m4`; returns the ELF.
fn build_firmware(policy: &Path) -> PathBuf {
    let root = workspace_root();
    let target_dir = root.join("target/firmware-m4");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    // Run from the firmware folder so that its .cargo/config.toml (target, linker script)
    // applies. Not --locked: its own Cargo.lock follows vge-runtime's dependencies. Also
    // drop flags meant for the host build (e.g. -C target-cpu=native).
    let status = Command::new(cargo)
        .current_dir(root.join("runtime/firmware-m4"))
        .args(["build", "--release"])
        .env("CARGO_TARGET_DIR", &target_dir)
        .env("VGE_POLICY", policy)
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .status()
        .expect("run cargo to build runtime/firmware-m4");
    assert!(
        status.success(),
        "building runtime/firmware-m4 failed ({status}); it needs `rustup target add thumbv7em-none-eabihf`"
    );
    target_dir.join("thumbv7em-none-eabihf/release/vge-firmware-m4")
}

/// Runs the firmware under qemu; returns (exit code, stdout).
fn run_qemu(elf: &Path) -> (i32, String) {
    let mut child = Command::new(QEMU)
        .args(["-cpu", "cortex-m4", "-machine", "mps2-an386", "-nographic", "-monitor", "none"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!(
                "cannot start {QEMU}: {e}. Install it: apt-get install -y --no-install-recommends qemu-system-arm"
            )
        });
    let mut stdout = child.stdout.take().unwrap();
    let reader = thread::spawn(move || {
        let mut s = String::new();
        stdout.read_to_string(&mut s).unwrap();
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > QEMU_TIMEOUT {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("{QEMU} did not exit within {QEMU_TIMEOUT:?}");
        }
        thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    let out = reader.join().unwrap();
    let code = status.code().unwrap_or_else(|| panic!("{QEMU} killed by a signal; stderr: {stderr}"));
    eprintln!("{QEMU} exited {code}; stderr: {stderr}");
    (code, out)
}

/// `<tag> <case> <hex f32 bits>...` lines, in order.
fn parse(out: &str, tag: &str) -> Vec<Vec<f32>> {
    out.lines()
        .filter_map(|l| l.strip_prefix(tag).and_then(|r| r.strip_prefix(' ')))
        .enumerate()
        .map(|(i, rest)| {
            let mut words = rest.split_whitespace();
            assert_eq!(words.next().unwrap().parse::<usize>().unwrap(), i, "case number of {tag} line");
            words.map(|w| f32::from_bits(u32::from_str_radix(w, 16).unwrap())).collect()
        })
        .collect()
}

#[test]
fn cortex_m4f_firmware_runs_exported_policy_like_host_runtime() {
    // Alone in this test binary: the global torch RNG is not shared with other tests.
    tch::manual_seed(0x7E57);
    let vs = VarStore::new(Device::Cpu);
    let spec = ActorSpec { obs_dim: OBS_DIM, hidden: vec![256, 256], act_dim: ACT_DIM };
    let actor = build_actor(&(vs.root() / "actor"), &spec).unwrap();
    // Non-trivial normalisation, clip and scaling, so the whole pipeline is compared.
    let mean: Vec<f32> = (0..OBS_DIM).map(|i| 0.5 * (i as f32 * 0.7).sin()).collect();
    let std: Vec<f32> = (0..OBS_DIM).map(|i| 0.5 + (i as f32 * 0.3).cos().abs()).collect();
    let scale: Vec<f32> = (0..ACT_DIM).map(|i| 0.05 * (i + 1) as f32).collect();
    let offset: Vec<f32> = (0..ACT_DIM).map(|i| 0.001 * i as f32 - 0.005).collect();
    let clip = 5.0f32;
    let meta = PolicyMeta {
        obs_layout: vec![ObsSlice::new("q", 0..15), ObsSlice::new("rest", 15..65)],
        action_names: (0..ACT_DIM).map(|i| format!("j{i}")).collect(),
        obs_norm: ObsNorm { mean: mean.clone(), std: std.clone(), clip: Some(clip) },
        action_scale: scale.clone(),
        action_offset: offset.clone(),
        control_hz: 20.0,
        provenance: Provenance {
            vge_version: env!("CARGO_PKG_VERSION").into(),
            config_hash: "cortex-m-test".into(),
            seed: 0x7E57,
            steps: 0,
        },
    };
    let bytes = export_policy(&vs, "actor", &spec, meta).unwrap();
    let info = vge_runtime::policy::inspect(&bytes).unwrap();

    let dir = workspace_root().join("target/firmware-m4");
    std::fs::create_dir_all(&dir).unwrap();
    let policy_path = dir.join("actor-test.vgep");
    std::fs::write(&policy_path, &bytes).unwrap();

    // First a file with one bit flipped in a weight of the middle layer: the firmware must
    // reject it (checksum) and exit 1 through semihosting, which qemu passes on, so a failing
    // firmware fails this test. (One test, not two: both builds share target/firmware-m4.)
    let mut corrupted = bytes.clone();
    corrupted[bytes.len() / 2] ^= 0x10;
    let corrupted_path = dir.join("actor-corrupted.vgep");
    std::fs::write(&corrupted_path, &corrupted).unwrap();
    let (code, out) = run_qemu(&build_firmware(&corrupted_path));
    assert_eq!(code, 1, "a corrupted policy file must fail the firmware; output:\n{out}");
    assert!(out.contains("error: ChecksumMismatch"), "{out}");

    let elf = build_firmware(&policy_path);
    let (code, out) = run_qemu(&elf);
    assert_eq!(code, 0, "firmware exit status (semihosting); output:\n{out}");
    assert!(
        out.contains(&format!("policy file {} bytes, storage {} f32", bytes.len(), info.storage_len)),
        "firmware embeds our file and sizes its storage from it:\n{out}"
    );
    assert!(out.contains(&format!("crc32 {:08x}", info.checksum)), "{out}");

    let obs = parse(&out, "obs");
    let act = parse(&out, "act");
    assert_eq!(obs.len(), N_CASES, "observation lines:\n{out}");
    assert_eq!(act.len(), obs.len());

    let mut storage = vec![0.0f32; info.storage_len];
    let policy = HandPolicy::load(&bytes, &mut storage).unwrap();
    let (mut max_diff, mut identical, mut n) = (0.0f32, 0usize, 0usize);
    let mut host_all = Vec::new();
    for (o, a) in obs.iter().zip(&act) {
        assert_eq!((o.len(), a.len()), (OBS_DIM, ACT_DIM));
        let mut host = [0.0f32; ACT_DIM];
        policy.forward(o, &mut host).unwrap();
        for (h, m) in host.iter().zip(a) {
            max_diff = max_diff.max((h - m).abs());
            identical += usize::from(h.to_bits() == m.to_bits());
            n += 1;
        }
        host_all.extend_from_slice(&host);
    }

    // And tch's forward of the same actor on the same observations (the parity bound).
    let obs_flat: Vec<f32> = obs.concat();
    let expected = tch::no_grad(|| {
        let x = Tensor::from_slice(&obs_flat).reshape([N_CASES as i64, OBS_DIM as i64]);
        let x = ((x - Tensor::from_slice(&mean)) / Tensor::from_slice(&std))
            .clamp(-f64::from(clip), f64::from(clip));
        actor.forward(&x) * Tensor::from_slice(&scale) + Tensor::from_slice(&offset)
    });
    let expected = Vec::<f32>::try_from(&expected.flatten(0, -1)).unwrap();
    let act_flat: Vec<f32> = act.concat();
    let tch_diff = expected.iter().zip(&act_flat).map(|(e, a)| (e - a).abs()).fold(0.0f32, f32::max);

    eprintln!(
        "cortex-m4f vs host runtime: max abs diff {max_diff:e}, {identical}/{n} actions bit-identical; \
         vs tch: {tch_diff:e}; policy file {} bytes",
        bytes.len()
    );
    if let Some(line) = out.lines().find(|l| l.starts_with("stack_peak_bytes")) {
        eprintln!("firmware {line}");
    }
    assert!(max_diff <= TOLERANCE, "max abs diff {max_diff:e} > {TOLERANCE:e}");
    assert!(tch_diff <= 1e-5, "firmware vs tch max abs diff {tch_diff:e}");
    // Some outputs are well away from 0: the comparison is not trivially of zeros.
    assert!(host_all.iter().zip(&offset.repeat(N_CASES)).any(|(h, o)| (h - o).abs() > 0.01));
}
