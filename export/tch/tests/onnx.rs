//! ONNX export and import against the real `onnx` and `onnxruntime` packages (through
//! `export/tch/tests/onnx_check.py` in `.deps/py`, which scripts/test.sh installs): the checker
//! accepts every exported file, onnxruntime's actions equal the runtime's, torch-layout MLPs
//! import, broken graphs are refused with the node named, and export then import is exact.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::Device;
use tch::nn::VarStore;
use vge_export::onnx::{self, ActionScale, ImportOptions, ImportTarget, OnnxError};
use vge_export::{ActorSpec, ObsNorm, PolicyFile, PolicyMeta, Provenance, WeightType};
use vge_export_tch::{build_actor, export_policy};
use vge_runtime::policy::{HAND_MAX_LAYERS, HAND_MAX_WIDTH};
use vge_runtime::{AlignedBytes, HandPolicy};

const N_OBS: usize = 10_000;
const TOLERANCE: f32 = 1e-5;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().nth(2).unwrap().to_path_buf()
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("onnx").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `onnx_check.py` run by `.deps/py`'s Python; panics (the test fails) when the venv, onnx or
/// onnxruntime is missing, or the script fails.
fn py(args: &[&str]) -> String {
    let python = root().join(".deps/py/bin/python");
    assert!(
        python.exists(),
        "{} is missing: run scripts/test.sh, which creates it with onnx and onnxruntime",
        python.display()
    );
    let out =
        Command::new(&python).arg(root().join("export/tch/tests/onnx_check.py")).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "onnx_check.py {args:?} failed (are onnx and onnxruntime installed in .deps/py?):\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn shipped() -> Vec<u8> {
    std::fs::read(root().join("policies/cube.vgep")).unwrap()
}

/// The hand as the shipped policy describes it, with the runtime's `HandPolicy` capacity.
fn hand() -> ImportTarget {
    let p = PolicyFile::from_bytes(&shipped()).unwrap();
    ImportTarget {
        obs_layout: p.obs_layout,
        action_names: p.action_names,
        control_hz: p.control_hz,
        max_layers: HAND_MAX_LAYERS,
        max_width: HAND_MAX_WIDTH,
        task: p.task,
    }
}

/// A fresh actor as `vge export --init` makes one: 65 -> 256 -> 256 -> 15, torch's default
/// initialisation, identity normalisation, the hand's action scale.
fn init_policy(seed: i64) -> Vec<u8> {
    tch::manual_seed(seed);
    let vs = VarStore::new(Device::Cpu);
    let spec = ActorSpec { obs_dim: 65, hidden: vec![256, 256], act_dim: 15 };
    build_actor(&(vs.root() / "actor"), &spec).unwrap();
    let hand = hand();
    let provenance = Provenance {
        vge_version: "0.1.0".into(),
        config_hash: "untrained".into(),
        seed: seed as u64,
        steps: 0,
    };
    let meta = PolicyMeta {
        obs_layout: hand.obs_layout,
        action_names: hand.action_names,
        obs_norm: ObsNorm::identity(65),
        action_scale: vec![0.05; 15],
        action_offset: vec![0.0; 15],
        control_hz: hand.control_hz,
        provenance,
        task: None,
    };
    export_policy(&vs, "actor", &spec, meta).unwrap()
}

/// `n` observations spread over the policy's normalised range: `mean + std * u`, `u` uniform
/// in [-3, 3] (beyond the shipped policy's clip), from a seeded generator.
fn observations(policy: &PolicyFile, n: usize, seed: u64) -> Vec<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .flat_map(|_| {
            policy
                .obs_mean
                .iter()
                .zip(&policy.obs_std)
                .map(|(m, s)| m + s * 3.0 * (2.0 * rng.random::<f32>() - 1.0))
                .collect::<Vec<_>>()
        })
        .collect()
}

fn runtime_actions(vgep: &[u8], obs: &[f32]) -> Vec<f32> {
    let bytes = AlignedBytes::new(vgep);
    let policy = HandPolicy::load(&bytes, &mut []).unwrap();
    let (n_obs, n_act) = (policy.obs_dim(), policy.act_dim());
    obs.chunks_exact(n_obs)
        .flat_map(|o| {
            let mut a = vec![0.0; n_act];
            policy.forward(o, &mut a).unwrap();
            a
        })
        .collect()
}

fn onnxruntime_actions(model: &Path, obs: &[f32]) -> Vec<f32> {
    let dir = model.parent().unwrap();
    let (obs_path, act_path) = (dir.join("obs.f32"), dir.join("actions.f32"));
    std::fs::write(&obs_path, obs.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<_>>()).unwrap();
    py(&["run", model.to_str().unwrap(), obs_path.to_str().unwrap(), act_path.to_str().unwrap()]);
    let bytes = std::fs::read(&act_path).unwrap();
    bytes.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect()
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// Exports `vgep`, checks the file with onnx.checker, and compares onnxruntime with the
/// runtime on 10,000 observations.
fn export_check_and_compare(name: &str, vgep: &[u8]) {
    let dir = scratch(name);
    let model = dir.join("policy.onnx");
    std::fs::write(&model, onnx::policy_bytes_to_onnx(vgep).unwrap()).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&py(&["check", model.to_str().unwrap()])).unwrap();
    assert!(summary["opset"]["ai.onnx"].as_i64().unwrap() >= 17, "{summary}");
    let policy = PolicyFile::from_bytes(vgep).unwrap();
    let meta = &summary["metadata_props"];
    assert_eq!(meta["act_dim"], "15");
    assert_eq!(meta["control_hz"].as_str().unwrap().parse::<f32>().unwrap(), policy.control_hz);
    assert_eq!(meta["seed"], policy.provenance.seed.to_string());
    assert_eq!(meta["config_hash"], policy.provenance.config_hash.as_str());
    let layout: serde_json::Value = serde_json::from_str(meta["obs_layout"].as_str().unwrap()).unwrap();
    assert_eq!(layout[0]["name"], policy.obs_layout[0].name.as_str());
    assert_eq!(layout.as_array().unwrap().last().unwrap()["end"], 65);

    let obs = observations(&policy, N_OBS, 7);
    let (ours, theirs) = (runtime_actions(vgep, &obs), onnxruntime_actions(&model, &obs));
    let diff = max_abs_diff(&ours, &theirs);
    let spread = ours.iter().fold(0.0f32, |m, a| m.max(a.abs()));
    println!(
        "{name}: max |runtime - onnxruntime| = {diff:e} over {N_OBS} observations (|action| up to {spread})"
    );
    assert!(diff <= TOLERANCE, "{name}: actions differ by {diff}");
    // The comparison is not vacuous: the actions vary and are not all zero.
    assert!(spread > 0.01, "{name}: actions all near zero ({spread})");
}

#[test]
fn shipped_policy_exports_and_onnxruntime_matches_the_runtime() {
    export_check_and_compare("shipped", &shipped());
}

#[test]
fn fresh_init_policy_exports_and_onnxruntime_matches_the_runtime() {
    export_check_and_compare("init", &init_policy(3));
}

fn options(scale: Option<ActionScale>) -> ImportOptions {
    ImportOptions { action_scale: scale, source: "test.onnx".into(), ..ImportOptions::default() }
}

fn build(dir: &Path, name: &str, args: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let mut all = vec!["build", path.to_str().unwrap()];
    all.extend_from_slice(args);
    py(&all);
    path
}

#[test]
fn torch_layout_mlp_imports_and_matches_onnxruntime() {
    let dir = scratch("torch");
    let hand = hand();
    // Gemm as torch's TorchScript exporter writes Linear, MatMul + Add as its dynamo exporter
    // does, and the log_std head it writes beside SB3's mean (only an Expand's shape).
    let variants =
        [("gemm.onnx", &[][..]), ("matmul.onnx", &["--matmul"][..]), ("sb3.onnx", &["--sb3-head"][..])];
    for (name, extra) in variants {
        let model = build(&dir, name, &[&["--seed", "5"][..], extra].concat());
        let bytes = std::fs::read(&model).unwrap();
        // Tanh's [-1, 1] without a Mul: the importer wants to be told what that output means.
        let err = onnx::import(&bytes, &hand, &options(None)).unwrap_err();
        assert!(matches!(err, OnnxError::Option(_)), "{err}");

        let imported = onnx::import(&bytes, &hand, &options(Some(ActionScale::Graph))).unwrap();
        let p = &imported.policy;
        let dims: Vec<_> = p.layers.iter().map(|l| (l.in_dim, l.out_dim, l.activation)).collect();
        assert_eq!(dims, [(65, 256, 1), (256, 256, 1), (256, 15, 2)], "{name}");
        let vgep = p.to_bytes().unwrap();
        let identity = PolicyFile { obs_std: vec![1.0; 65], ..p.clone() };
        let obs = observations(&identity, N_OBS, 9);
        let (ours, theirs) = (runtime_actions(&vgep, &obs), onnxruntime_actions(&model, &obs));
        let diff = max_abs_diff(&ours, &theirs);
        println!("{name}: imported .vgep vs onnxruntime: max diff {diff:e} over {N_OBS} observations");
        assert!(diff <= TOLERANCE, "{name}: {diff}");
        assert!(ours.iter().any(|a| a.abs() > 0.1), "{name}: actions all near zero");

        // Scaled to the hand's step: the same actions times 0.05.
        let scaled = onnx::import(&bytes, &hand, &options(Some(ActionScale::Times(0.05)))).unwrap();
        let scaled_actions = runtime_actions(&scaled.policy.to_bytes().unwrap(), &obs);
        let theirs_scaled: Vec<f32> = theirs.iter().map(|a| a * 0.05).collect();
        assert!(max_abs_diff(&scaled_actions, &theirs_scaled) <= TOLERANCE * 0.05);
    }
}

/// Imports `model` into `dir/out.vgep` and returns the refusal; the file must not exist.
fn refused(dir: &Path, model: &Path, opts: &ImportOptions) -> String {
    let out = dir.join("out.vgep");
    let err = onnx::import_file(model, &out, &hand(), opts).unwrap_err();
    assert!(!out.exists(), "{} written despite the refusal {err}", out.display());
    err.to_string()
}

#[test]
fn broken_graphs_are_refused_with_the_node_named_and_nothing_written() {
    let dir = scratch("refused");
    let graph = Some(ActionScale::Graph);
    let cases: [(&str, &[&str], &[&str]); 5] = [
        (
            "unsupported.onnx",
            &["--variant", "unsupported"],
            &["/latent_pi/latent_pi.1/Sigmoid", "(Sigmoid)", "unsupported op"],
        ),
        ("elu.onnx", &["--variant", "elu"], &["/latent_pi/latent_pi.1/Elu", "(Elu)", "no such activation"]),
        ("narrow.onnx", &["--obs", "64"], &["/latent_pi/latent_pi.0/Gemm", "takes 64 inputs", "observes 65"]),
        ("nan.onnx", &["--variant", "nan"], &["/mu/Gemm", "mu.weight", "NaN", "flat index 775"]),
        ("wide.onnx", &["--hidden", "300,256"], &["/latent_pi/latent_pi.0/Gemm", "width 300", "1 to 256"]),
    ];
    for (name, args, expected) in cases {
        let model = build(&dir, name, args);
        let msg = refused(&dir, &model, &options(graph));
        println!("{name}: {msg}");
        for e in expected {
            assert!(msg.contains(e), "{name}: `{msg}` lacks `{e}`");
        }
    }
    // Too many layers for the runtime.
    let deep = build(&dir, "deep.onnx", &["--hidden", "64,64,64,64"]);
    let msg = refused(&dir, &deep, &options(graph));
    assert!(msg.contains("/mu/Gemm") && msg.contains("at most 4 layers"), "{msg}");
    // Not an ONNX file at all.
    let junk = dir.join("junk.onnx");
    std::fs::write(&junk, b"\xff\xff\xff\xff not protobuf").unwrap();
    assert!(refused(&dir, &junk, &options(graph)).starts_with("not an ONNX model"));
}

#[test]
fn claimed_and_given_layouts_are_checked_against_the_hands() {
    use onnx_protobuf::{Message, ModelProto};
    let dir = scratch("layout");
    let bytes = onnx::policy_bytes_to_onnx(&shipped()).unwrap();
    let mut model = ModelProto::parse_from_bytes(&bytes).unwrap();
    let entry = model.metadata_props.iter_mut().find(|e| e.key == "obs_layout").unwrap();
    entry.value = entry.value.replace("\"q_rad\"", "\"q_deg\"");
    let path = dir.join("renamed.onnx");
    std::fs::write(&path, model.write_to_bytes().unwrap()).unwrap();
    let msg = refused(&dir, &path, &options(None));
    assert!(msg.contains("metadata_props `obs_layout`") && msg.contains("q_deg 0..15"), "{msg}");

    let good = dir.join("good.onnx");
    std::fs::write(&good, &bytes).unwrap();
    let mut shifted = hand().obs_layout;
    shifted[0].end = 14;
    shifted[1].start = 14;
    let opts = ImportOptions { obs_layout: Some(shifted), ..options(None) };
    let msg = refused(&dir, &good, &opts);
    assert!(msg.contains("layout given"), "{msg}");
    // A user normalisation on top of the graph's own is refused too.
    let opts = ImportOptions { obs_norm: Some(ObsNorm::identity(65)), ..options(None) };
    assert!(refused(&dir, &good, &opts).contains("normalise/sub_mean"));
}

#[test]
fn export_then_import_round_trips_exactly() {
    let hand = hand();
    for (name, vgep) in [("shipped", shipped()), ("init", init_policy(4))] {
        let original = PolicyFile::from_bytes(&vgep).unwrap();
        let model = onnx::policy_bytes_to_onnx(&vgep).unwrap();
        let imported = onnx::import(&model, &hand, &options(None)).unwrap();
        assert!(imported.notes.is_empty(), "{name}: {:?}", imported.notes);
        // Every field, provenance included, comes back.
        assert_eq!(imported.policy, original, "{name}");
        let back = imported.policy.to_bytes().unwrap();
        let obs = observations(&original, 1000, 11);
        let (a, b) = (runtime_actions(&vgep, &obs), runtime_actions(&back, &obs));
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()), "{name}: actions differ");
    }
}

/// The shipped policy with a task record, as a policy file.
fn shipped_with_task() -> Vec<u8> {
    let task = vge_export::PolicyTask {
        hand: "allegro".into(),
        hand_sha256: std::array::from_fn(|i| 0xf0 ^ i as u8),
        observation_set: "proprio:8".into(),
        object: "cube".into(),
        orientation: "palm_down".into(),
    };
    PolicyFile { task: Some(task), ..PolicyFile::from_bytes(&shipped()).unwrap() }.to_bytes().unwrap()
}

#[test]
fn the_task_record_round_trips_through_metadata_props() {
    use onnx_protobuf::{Message, ModelProto};
    let vgep = shipped_with_task();
    let original = PolicyFile::from_bytes(&vgep).unwrap();
    let model = onnx::policy_bytes_to_onnx(&vgep).unwrap();
    let props = ModelProto::parse_from_bytes(&model).unwrap().metadata_props;
    let get = |k: &str| props.iter().find(|e| e.key == k).map(|e| e.value.clone());
    assert_eq!(get(onnx::keys::HAND).as_deref(), Some("allegro"));
    assert_eq!(get(onnx::keys::HAND_SHA256).unwrap(), original.task.as_ref().unwrap().hand_sha256_hex());
    assert_eq!(get(onnx::keys::OBSERVATION_SET).as_deref(), Some("proprio:8"));
    let imported = onnx::import(&model, &hand(), &options(None)).unwrap();
    assert_eq!(imported.policy, original);
    // A policy without a record writes no task key, and imports without one.
    let bare = onnx::policy_bytes_to_onnx(&shipped()).unwrap();
    let props = ModelProto::parse_from_bytes(&bare).unwrap().metadata_props;
    assert!(!props.iter().any(|e| onnx::keys::TASK.contains(&e.key.as_str())));
    assert_eq!(onnx::import(&bare, &hand(), &options(None)).unwrap().policy.task, None);
}

#[test]
fn a_bad_task_key_is_refused_naming_the_key() {
    use onnx_protobuf::{Message, ModelProto};
    let model = onnx::policy_bytes_to_onnx(&shipped_with_task()).unwrap();
    // The import refusal once `key` is set to `value` (Some) or removed (None).
    let refusal = |key: &str, value: Option<&str>| {
        let mut m = ModelProto::parse_from_bytes(&model).unwrap();
        m.metadata_props.retain(|e| e.key != key);
        if let Some(v) = value {
            let mut e = onnx_protobuf::StringStringEntryProto::new();
            (e.key, e.value) = (key.to_owned(), v.to_owned());
            m.metadata_props.push(e);
        }
        let bytes = m.write_to_bytes().unwrap();
        onnx::import(&bytes, &hand(), &options(None)).unwrap_err().to_string()
    };
    let long = "x".repeat(65);
    let sha_upper = "AB".repeat(32);
    for (key, value, why) in [
        ("hand", Some(""), "is empty"),
        ("hand", Some(long.as_str()), "65 bytes"),
        ("hand_sha256", Some("abc"), "3 bytes, not 64 hex digits"),
        ("hand_sha256", Some(&"zz".repeat(32)), "not a hex digit"),
        ("hand_sha256", None, "missing"),
        ("observation_set", Some("proprio:0"), "`proprio:0` is not"),
        ("observation_set", None, "missing"),
        ("object", Some(long.as_str()), "65 bytes"),
        ("orientation", Some(long.as_str()), "65 bytes"),
    ] {
        let msg = refusal(key, value);
        assert!(msg.starts_with(&format!("metadata_props `{key}`")) && msg.contains(why), "{key}: {msg}");
    }
    // A task without its hand names the first task key it has.
    let msg = refusal("hand", None);
    assert!(msg.starts_with("metadata_props `hand_sha256`") && msg.contains("name the hand"), "{msg}");
    // Upper-case hex is read; object and orientation may be left out (unspecified).
    let mut m = ModelProto::parse_from_bytes(&model).unwrap();
    m.metadata_props.retain(|e| e.key != "object" && e.key != "orientation");
    m.metadata_props.iter_mut().filter(|e| e.key == "hand_sha256").for_each(|e| e.value = sha_upper.clone());
    let task =
        onnx::import(&m.write_to_bytes().unwrap(), &hand(), &options(None)).unwrap().policy.task.unwrap();
    assert_eq!((task.hand_sha256, task.object.as_str(), task.orientation.as_str()), ([0xab; 32], "", ""));
}

#[test]
fn i8_policies_are_not_exported() {
    let i8 = PolicyFile::from_bytes(&shipped()).unwrap().encode(WeightType::I8).unwrap();
    assert!(matches!(onnx::policy_bytes_to_onnx(&i8), Err(OnnxError::Quantised)));
}
