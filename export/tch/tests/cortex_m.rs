//! A real exported policy on an emulated Cortex-M4F, for every weight type: exports a seeded
//! tch actor 65 -> 256 -> 256 -> 15 to version-2 policy files (f32, f16, i8) with
//! vge-export, builds `runtime/firmware-m4` for `thumbv7em-none-eabihf` around each (the
//! firmware embeds the file in flash and reads its arrays in place), runs it in
//! `qemu-system-arm -machine mps2-an386`, parses the observations and actions it prints over
//! semihosting, and checks them against the host `vge_runtime::Policy` of the same file
//! (max abs diff <= 1e-6) and against tch (f32 <= 1e-5; f16 and i8 within their rounding). A
//! firmware built with a corrupted file must reject it and exit 1.
//!
//! Here rather than in vge-tests because it needs tch, which this crate already links (with
//! the libtorch rpath from its build.rs); vge-tests stays free of libtorch.
//!
//! Needs `qemu-system-arm` (Debian package `qemu-system-arm`) and the `thumbv7em-none-eabihf`
//! rustup target; scripts/test.sh installs both. Missing either is a failure, not a skip.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use tch::nn::{Module, VarStore};
use tch::{Device, Tensor};
use vge_export::firmware::{self, FirmwareRun};
use vge_export::{ActorSpec, ObsNorm, ObsSlice, PolicyFile, PolicyMeta, Provenance, WeightType};
use vge_export_tch::{build_actor, export_policy};
use vge_runtime::{AlignedBytes, HandPolicy};

const OBS_DIM: usize = 65;
const ACT_DIM: usize = 15;
/// Observations the firmware evaluates (`N_CASES` in runtime/firmware-m4/src/main.rs).
const N_CASES: usize = 8;
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);
const TOLERANCE: f32 = 1e-6;

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().nth(2).unwrap().to_path_buf()
}

fn build_and_run(policy: &Path) -> FirmwareRun {
    let target_dir = workspace_root().join("target/firmware-m4");
    let elf = firmware::build(policy, &target_dir, None).unwrap();
    let run = firmware::run(&elf, QEMU_TIMEOUT).unwrap();
    eprintln!("qemu-system-arm exited {}", run.exit_code);
    run
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
        task: None,
    };
    let f32_bytes = export_policy(&vs, "actor", &spec, meta).unwrap();
    let file = PolicyFile::from_bytes(&f32_bytes).unwrap();

    let dir = workspace_root().join("target/firmware-m4");
    std::fs::create_dir_all(&dir).unwrap();

    // First a file with one bit flipped in a weight of the middle layer: the firmware must
    // reject it (checksum) and exit 1 through semihosting, which qemu passes on, so a failing
    // firmware fails this test. (One test: every build shares target/firmware-m4.)
    let mut corrupted = f32_bytes.clone();
    corrupted[f32_bytes.len() / 2] ^= 0x10;
    let corrupted_path = dir.join("actor-corrupted.vgep");
    std::fs::write(&corrupted_path, &corrupted).unwrap();
    let run = build_and_run(&corrupted_path);
    assert_eq!(run.exit_code, 1, "a corrupted policy file must fail the firmware; output:\n{}", run.output);
    assert!(run.output.contains("error: checksum mismatch"), "{}", run.output);

    // The reference: tch's forward of the f32 actor, on the firmware's observations.
    let tch_forward = |obs: &[Vec<f32>]| -> Vec<f32> {
        let flat: Vec<f32> = obs.concat();
        let y = tch::no_grad(|| {
            let x = Tensor::from_slice(&flat).reshape([obs.len() as i64, OBS_DIM as i64]);
            let x = ((x - Tensor::from_slice(&mean)) / Tensor::from_slice(&std))
                .clamp(-f64::from(clip), f64::from(clip));
            actor.forward(&x) * Tensor::from_slice(&scale) + Tensor::from_slice(&offset)
        });
        Vec::<f32>::try_from(&y.flatten(0, -1)).unwrap()
    };

    // (weight type, bound on |firmware - tch|): f16 rounds each weight to 11 bits, i8 to 8 bits
    // per row and each layer input to 8 bits, so their bounds are those of their rounding.
    for (weights, tch_bound) in [(WeightType::F32, 1e-5f32), (WeightType::F16, 5e-3), (WeightType::I8, 5e-2)]
    {
        let bytes = file.encode(weights).unwrap();
        let info = vge_runtime::policy::inspect(&bytes).unwrap();
        let path = dir.join(format!("actor-test-{weights}.vgep"));
        std::fs::write(&path, &bytes).unwrap();
        let run = build_and_run(&path);
        let out = &run.output;
        assert_eq!(run.exit_code, 0, "{weights}: firmware exit status (semihosting); output:\n{out}");
        assert!(
            out.contains(&format!("policy file {} bytes, storage 0 f32", bytes.len())),
            "{weights}: the firmware embeds our file and reads it in place:\n{out}"
        );
        assert!(out.contains(&format!("format 3, weights {weights}, crc32 {:08x}", info.checksum)), "{out}");
        // In place: no weight in RAM, only the forward pass's buffers on the stack.
        let static_ram = run.value("static_ram_bytes").unwrap();
        assert!(static_ram < 1024, "{weights}: {static_ram} bytes of static RAM");

        let obs = run.vectors("obs").unwrap();
        let act = run.vectors("act").unwrap();
        assert_eq!(obs.len(), N_CASES, "observation lines:\n{out}");
        assert_eq!(act.len(), obs.len());

        let aligned = AlignedBytes::new(&bytes);
        let policy = HandPolicy::load(&aligned, &mut []).unwrap();
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
        let expected = tch_forward(&obs);
        let act_flat: Vec<f32> = act.concat();
        let tch_diff = expected.iter().zip(&act_flat).map(|(e, a)| (e - a).abs()).fold(0.0f32, f32::max);
        eprintln!(
            "{weights}: cortex-m4f vs host runtime: max abs diff {max_diff:e}, {identical}/{n} bit-identical; \
             vs tch: {tch_diff:e}; file {} bytes, flash {} bytes, RAM {} bytes, {:.0} instructions per forward",
            bytes.len(),
            run.flash_bytes().unwrap(),
            run.ram_bytes().unwrap(),
            run.instructions_per_forward().unwrap()
        );
        assert!(max_diff <= TOLERANCE, "{weights}: max abs diff {max_diff:e} > {TOLERANCE:e}");
        assert!(tch_diff <= tch_bound, "{weights}: firmware vs tch max abs diff {tch_diff:e}");
        // Some outputs are well away from 0: the comparison is not trivially of zeros.
        assert!(host_all.iter().zip(&offset.repeat(N_CASES)).any(|(h, o)| (h - o).abs() > 0.01));
    }
}
