//! The runtime on an emulated Cortex-M4F: builds `runtime/firmware-m4` for
//! `thumbv7em-none-eabihf` with a policy blob written here, runs it in
//! `qemu-system-arm -machine mps2-an386`, parses the observations and actions it prints over
//! semihosting, and checks them against the host runtime (max abs diff <= 1e-6).
//!
//! Needs `qemu-system-arm` (Debian package `qemu-system-arm`) and the `thumbv7em-none-eabihf`
//! rustup target; scripts/test.sh installs both. Missing either is a failure, not a skip.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use vge_runtime::{Activation, Layer, PolicyMlp};

/// Must match `DIMS` in runtime/firmware-m4 (build.rs and src/main.rs).
const DIMS: [usize; 4] = [65, 256, 256, 15];
const QEMU: &str = "qemu-system-arm";
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);
const TOLERANCE: f32 = 1e-6;

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// A tch-like `Linear` initialisation (U(-1/sqrt(in), 1/sqrt(in))) from splitmix64, as the
/// firmware's blob layout: per layer, row-major `out × in` weights then `out` biases.
fn policy_floats(seed: u64) -> Vec<f32> {
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    let mut out = Vec::new();
    for w in DIMS.windows(2) {
        let bound = 1.0 / (w[0] as f32).sqrt();
        out.extend((0..w[0] * w[1] + w[1]).map(|_| next() * bound));
    }
    out
}

fn host_layers(floats: &[f32]) -> Vec<Layer<'_>> {
    let mut rest = floats;
    let mut layers = Vec::new();
    for (i, w) in DIMS.windows(2).enumerate() {
        let (n_in, n_out) = (w[0], w[1]);
        let (weights, r) = rest.split_at(n_in * n_out);
        let (bias, r) = r.split_at(n_out);
        rest = r;
        let activation = if i + 2 == DIMS.len() { Activation::Tanh } else { Activation::Relu };
        layers.push(Layer { in_dim: n_in, out_dim: n_out, weights, bias, activation });
    }
    assert!(rest.is_empty());
    layers
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
fn cortex_m4f_firmware_in_qemu_matches_host_runtime() {
    let floats = policy_floats(0x7E57_C0DE);
    let blob: Vec<u8> = floats.iter().flat_map(|x| x.to_le_bytes()).collect();
    let dir = workspace_root().join("target/firmware-m4");
    std::fs::create_dir_all(&dir).unwrap();
    let policy = dir.join("policy-test.bin");
    std::fs::write(&policy, &blob).unwrap();

    // First a truncated blob: the firmware must report it and exit 1 through semihosting,
    // which qemu passes on, so a failing firmware fails this test. (One test, not two: both
    // builds share target/firmware-m4 and would race.)
    let truncated = dir.join("policy-truncated.bin");
    std::fs::write(&truncated, &blob[..blob.len() - 4]).unwrap();
    let (code, out) = run_qemu(&build_firmware(&truncated));
    assert_eq!(code, 1, "a truncated policy must fail the firmware; output:\n{out}");
    assert!(out.contains("error: policy blob too short"), "{out}");

    let elf = build_firmware(&policy);
    let (code, out) = run_qemu(&elf);
    assert_eq!(code, 0, "firmware exit status (semihosting); output:\n{out}");
    assert!(out.contains(&format!("policy {} bytes", blob.len())), "firmware embeds our blob:\n{out}");

    let obs = parse(&out, "obs");
    let act = parse(&out, "act");
    assert_eq!(obs.len(), 8, "observation lines:\n{out}");
    assert_eq!(act.len(), obs.len());

    let layers = host_layers(&floats);
    let mlp = PolicyMlp::new(&layers).unwrap();
    let (mut max_diff, mut identical, mut n) = (0.0f32, 0usize, 0usize);
    for (o, a) in obs.iter().zip(&act) {
        assert_eq!((o.len(), a.len()), (DIMS[0], DIMS[3]));
        let mut host = [0.0f32; DIMS[3]];
        mlp.forward(o, &mut host).unwrap();
        for (h, m) in host.iter().zip(a) {
            max_diff = max_diff.max((h - m).abs());
            identical += usize::from(h.to_bits() == m.to_bits());
            n += 1;
        }
    }
    eprintln!("cortex-m4f vs host: max abs diff {max_diff:e}, {identical}/{n} actions bit-identical");
    if let Some(line) = out.lines().find(|l| l.starts_with("stack_peak_bytes")) {
        eprintln!("firmware {line}");
    }
    assert!(max_diff <= TOLERANCE, "max abs diff {max_diff:e} > {TOLERANCE:e}");
}
