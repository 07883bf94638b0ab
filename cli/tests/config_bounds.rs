//! Inputs are bounded before anything is allocated: every float of the config refuses NaN
//! and infinity (the float fields found from the config's schema, not listed here), sizes
//! that no machine holds are refused with the memory they would take, and a policy file
//! longer than any policy is refused unread by `vge inspect` and `vge eval`.

use crate::common;

use std::path::Path;
use std::process::Command;

use vge_run::config::{Config, parse_with_overrides};

/// What `--set KEY=VALUE` on an empty config file gives (the --set path of every command).
fn with(set: &str) -> Result<Config, String> {
    parse_with_overrides("", "probe", &[set.to_owned()]).map_err(|e| e.to_string())
}

/// The names serde lists when it refuses an unknown key in the section `prefix`
/// (`unknown field `x`, expected one of `a`, `b`` or `expected `a` or `b``); None when
/// `prefix` is not a section.
fn section_keys(prefix: &str) -> Option<Vec<String>> {
    let probe =
        if prefix.is_empty() { "zz_no_such_key".to_owned() } else { format!("{prefix}.zz_no_such_key") };
    let err = with(&format!("{probe}=1")).expect_err("an unknown key is refused");
    let listed = err.split("unknown field `zz_no_such_key`, expected").nth(1)?;
    Some(listed.split('`').skip(1).step_by(2).map(str::to_owned).collect())
}

/// Every leaf key of the config schema (`sac.gamma`), sections walked recursively.
fn schema_keys(prefix: &str, out: &mut Vec<String>) {
    for name in section_keys(prefix).expect("a section") {
        let key = if prefix.is_empty() { name } else { format!("{prefix}.{name}") };
        if section_keys(&key).is_some() {
            schema_keys(&key, out);
        } else {
            out.push(key);
        }
    }
}

#[test]
fn every_float_field_of_the_schema_refuses_nan_and_infinity_naming_its_key() {
    let mut keys = Vec::new();
    schema_keys("", &mut keys);
    assert!(
        keys.iter().any(|k| k == "sac.gamma") && keys.iter().any(|k| k == "run.eval_episode_s"),
        "{keys:?}"
    );
    let mut floats = Vec::new();
    for key in &keys {
        // A float field takes `nan` (a float array, such as env.mass_scale, `[nan, nan]`);
        // any other field refuses it when the config is read.
        let Some(shape) = ["{}", "[{}, {}]"]
            .into_iter()
            .find(|v| with(&format!("{key}={}", v.replace("{}", "nan"))).is_ok())
        else {
            continue;
        };
        floats.push(key.clone());
        for bad in ["nan", "inf", "-inf"] {
            let set = format!("{key}={}", shape.replace("{}", bad));
            let config = with(&set).expect("reads");
            let err = config.validate().expect_err(&format!("{set} is refused")).to_string();
            assert!(err.contains(key.as_str()) && err.contains("finite"), "{set}: {err}");
        }
    }
    // The schema's float fields, found above: the issue counted 28.
    assert!(floats.len() >= 28, "only {} float fields found: {floats:?}", floats.len());
}

/// `vge ARGS`: whether it succeeded, its stderr, and the largest resident set it reached
/// (bytes). Measured by a Python parent (`RUSAGE_CHILDREN`): a child's peak counts the memory
/// of the process that started it, which for this test binary, libtorch and all, would hide
/// what vge itself takes.
fn vge_with_peak_memory(args: &[&str]) -> (bool, String, u64) {
    let script = "import resource, subprocess, sys\n\
        r = subprocess.run(sys.argv[1:], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)\n\
        sys.stderr.buffer.write(r.stderr)\n\
        print(r.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n";
    let out = Command::new(common::python())
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_vge"))
        .args(args)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let fields: Vec<&str> = stdout.split_whitespace().collect();
    let [code, kib] = fields[..] else { panic!("python printed {stdout:?}") };
    // ru_maxrss is in KiB on Linux.
    let peak = kib.parse::<u64>().expect("KiB") * 1024;
    (code == "0", String::from_utf8_lossy(&out.stderr).into_owned(), peak)
}

/// What vge takes beyond its start (libtorch's libraries alone are over 100 MB resident):
/// the peak of `vge --help`.
fn baseline_bytes() -> u64 {
    static BASELINE: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *BASELINE.get_or_init(|| {
        let (ok, err, peak) = vge_with_peak_memory(&["--help"]);
        assert!(ok, "{err}");
        peak
    })
}

const LIMIT_BYTES: u64 = 100 << 20;

fn machine_memory_bytes() -> u64 {
    let text = std::fs::read_to_string("/proc/meminfo").expect("/proc/meminfo");
    let line = text.lines().find(|l| l.starts_with("MemTotal:")).expect("MemTotal");
    line.split_whitespace().nth(1).expect("kB").parse::<u64>().expect("number") * 1024
}

#[test]
fn sizes_no_machine_holds_are_refused_with_the_estimate_before_anything_is_allocated() {
    let root = common::temp_dir("config-bounds");
    let config = common::config("cube-fg-vge.toml");
    // A replay buffer twice this machine's memory: valid anywhere it fits, refused here.
    let twice_here = (2 * machine_memory_bytes() / 656).to_string();
    for (set, key, why) in [
        ("sac.buffer_size=1000000000000".to_owned(), "sac.buffer_size", "more than the 1.10 TB"),
        ("num_envs=100000000".to_owned(), "num_envs", "more than the 1.10 TB"),
        // Refused by its own bound (episodes are reserved whole) before the estimate.
        (
            "env.episode_length=1000000000000".to_owned(),
            "env.episode_length",
            "needs 1 to 1000000 control steps",
        ),
        ("run.eval_episodes=100000000000000".to_owned(), "run.eval_episodes", "more than the 1.10 TB"),
        (format!("sac.buffer_size={twice_here}"), "sac.buffer_size", "more than this machine's"),
    ] {
        let out = root.join("run");
        let args =
            ["train", "--config", config.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8")];
        let (ok, err, peak) = vge_with_peak_memory(&[&args[..], &["--set", &set]].concat());
        assert!(!ok, "{set} was not refused");
        let estimate = why.starts_with("more than");
        assert!(err.contains(key) && err.contains(why), "{set}: {err}");
        assert!(!estimate || err.contains("would hold about"), "{set}: {err}");
        assert!(peak < baseline_bytes() + LIMIT_BYTES, "{set}: refused after taking {peak} bytes");
        assert!(!out.exists(), "{set}: a refused run left a folder");
    }
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn eval_episode_s_nan_is_refused_by_vge_train_naming_the_key() {
    let root = common::temp_dir("config-nan");
    let config = common::config("cube-fg-vge.toml");
    let out = root.join("run");
    let args = ["train", "--config", config.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8")];
    for bad in ["nan", "inf"] {
        let set = format!("run.eval_episode_s={bad}");
        let (ok, err, _) = vge_with_peak_memory(&[&args[..], &["--set", &set]].concat());
        assert!(!ok && err.contains("run.eval_episode_s must be a finite number"), "{set}: {err}");
    }
    let _ = std::fs::remove_dir_all(&root);
}

/// A 2 GB sparse file (as `truncate -s 2G`).
fn sparse_2gb(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("z.vgep");
    std::fs::File::create(&path).expect("create").set_len(2 << 30).expect("set_len");
    path
}

#[test]
fn a_2gb_sparse_policy_file_is_refused_unread_by_inspect_and_eval() {
    let root = common::temp_dir("policy-size");
    let z = sparse_2gb(&root);
    let z = z.to_str().expect("utf-8");
    let limit = vge_run::eval::EVAL_MAX_FILE_LEN;
    assert_eq!(limit, vge_export::MAX_FILE_LEN, "inspect and eval read the same files");
    for args in [vec!["inspect", z], vec!["eval", "--policy", z, "--episodes", "1"]] {
        let (ok, err, peak) = vge_with_peak_memory(&args);
        assert!(!ok, "{args:?} accepted a 2 GB file");
        assert!(
            err.contains("2147483648 bytes")
                && err.contains(&format!("at most {limit} bytes"))
                && err.contains("not read"),
            "{args:?}: {err}"
        );
        assert!(peak < baseline_bytes() + LIMIT_BYTES, "{args:?}: refused after taking {peak} bytes");
    }
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn the_largest_policies_fit_the_file_size_limits() {
    use vge_runtime::policy::{HAND_MAX_FILE_LEN, HAND_MAX_LAYERS, HAND_MAX_WIDTH};
    // The shipped policy, and an actor at the hand's capacity: 3 hidden layers of 256.
    let shipped = std::fs::metadata(Path::new(env!("CARGO_MANIFEST_DIR")).join("../policies/cube.vgep"))
        .expect("policy");
    assert!(shipped.len() < HAND_MAX_FILE_LEN as u64);
    let widest = 4 * (HAND_MAX_LAYERS * HAND_MAX_WIDTH * HAND_MAX_WIDTH) as u64;
    assert!(widest < HAND_MAX_FILE_LEN as u64 && (HAND_MAX_FILE_LEN as u64) < 4 << 20, "{HAND_MAX_FILE_LEN}");
}

/// `vge ARGS` as [`vge_with_peak_memory`], also timed (s), and killed (a failure) after 120 s:
/// an input that blocks vge (a FIFO read) fails the test instead of hanging it.
fn vge_timed(args: &[&str]) -> (bool, String, u64, f64) {
    let script = "import resource, subprocess, sys, time\n\
        t = time.monotonic()\n\
        r = subprocess.run(sys.argv[1:], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=120)\n\
        s = time.monotonic() - t\n\
        sys.stderr.buffer.write(r.stderr)\n\
        print(r.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, s)\n";
    let out = Command::new(common::python())
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_vge"))
        .args(args)
        .output()
        .expect("python runs (VGE_PYTHON, or .deps/py made by scripts/test.sh)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let fields: Vec<&str> = stdout.split_whitespace().collect();
    let [code, kib, seconds] = fields[..] else {
        panic!("vge {args:?} did not end in 120 s: {stdout}{stderr}")
    };
    let peak = kib.parse::<u64>().expect("KiB") * 1024;
    (code == "0", stderr, peak, seconds.parse().expect("seconds"))
}

/// A config whose base is `/dev/zero`, a FIFO or a 1 GB (sparse) file is refused naming that
/// file, unread: without reading it (the memory vge takes stays near its start), without
/// blocking on the FIFO, within seconds.
#[test]
fn a_base_of_dev_zero_a_fifo_or_a_1gb_file_is_refused_unread_naming_it() {
    let root = common::temp_dir("config-base-bounds");
    let fifo = root.join("fifo.toml");
    assert!(Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs").success());
    let big = root.join("big.toml");
    std::fs::File::create(&big).expect("create").set_len(1 << 30).expect("a sparse 1 GB file");
    for (base, why) in [
        ("/dev/zero".to_owned(), "not a regular file (a character device)"),
        (fifo.display().to_string(), "not a regular file (a FIFO)"),
        (big.display().to_string(), "1073741824 bytes, more than the 4194304"),
    ] {
        let config = root.join("c.toml");
        std::fs::write(&config, format!("base = \"{base}\"\nseed = 1\n")).expect("config");
        let out = root.join("run");
        let args =
            ["train", "--config", config.to_str().expect("utf-8"), "--out", out.to_str().expect("utf-8")];
        let (ok, err, peak, seconds) = vge_timed(&args);
        eprintln!("base {base}: refused in {seconds:.2} s, peak {} MB", peak >> 20);
        assert!(!ok, "base {base} was not refused");
        assert!(err.contains(&base) && err.contains(why) && err.contains("not read"), "{base}: {err}");
        assert!(peak < baseline_bytes() + LIMIT_BYTES, "{base}: refused after taking {peak} bytes");
        assert!(!out.exists(), "{base}: a refused run left a folder");
    }
    let _ = std::fs::remove_dir_all(&root);
}

/// Protobuf's wire format by hand: field `field` of length-delimited `bytes`.
fn pb_bytes(out: &mut Vec<u8>, field: u64, bytes: &[u8]) {
    let mut varint = |mut v: u64| loop {
        let b = (v & 0x7f) as u8;
        v >>= 7;
        out.push(if v == 0 { b } else { b | 0x80 });
        if v == 0 {
            break;
        }
    };
    varint(field << 3 | 2);
    varint(bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// An ONNX model of one chain of `n` nodes of `op`, about 70 bytes a node (57 MB for 850,000,
/// the size of a file that once took 2.45 GB and 9 s to refuse), written directly: built as
/// messages it would take gigabytes here too.
fn onnx_chain(n: usize, op: &str) -> Vec<u8> {
    let mut graph = Vec::with_capacity(n * 80);
    let mut node = Vec::new();
    for i in 0..n {
        node.clear();
        pb_bytes(&mut node, 1, format!("value_{i:07}").as_bytes());
        pb_bytes(&mut node, 1, b"weight");
        pb_bytes(&mut node, 2, format!("value_{:07}", i + 1).as_bytes());
        pb_bytes(&mut node, 3, format!("node_{i:07}_of_chain").as_bytes());
        pb_bytes(&mut node, 4, op.as_bytes());
        pb_bytes(&mut graph, 1, &node);
    }
    let mut model = vec![0x08, 0x08]; // ir_version 8
    pb_bytes(&mut model, 7, &graph);
    model
}

/// What `vge --help` takes to start (s): libtorch's libraries load before any command runs.
fn start_seconds() -> f64 {
    let (ok, err, _, seconds) = vge_timed(&["--help"]);
    assert!(ok, "{err}");
    seconds
}

/// ONNX files of an 850,000-node chain, within the importer's 64 MiB file cap, are refused by
/// their layer count (a chain of Gemm) or node count (a chain of Identity) before a message is
/// built: the file is read (57 MB), and little more memory or time is taken.
#[test]
fn an_850000_node_onnx_chain_is_refused_by_its_layer_or_node_count_unbuilt() {
    let root = common::temp_dir("onnx-chain");
    let start = start_seconds();
    for (op, why) in [("Gemm", "more than 8 Gemm and MatMul nodes"), ("Identity", "more than 1024 nodes")] {
        let model = onnx_chain(850_000, op);
        assert!(model.len() as u64 <= vge_export::onnx::MAX_ONNX_FILE_LEN, "{} bytes", model.len());
        let path = root.join("chain.onnx");
        std::fs::write(&path, &model).expect("write");
        let out = root.join("chain.vgep");
        let (path, out) = (path.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
        let (ok, err, peak, seconds) =
            vge_timed(&["import", "--onnx", path, "--out", out, "--action-scale", "hand"]);
        let over = peak.saturating_sub(baseline_bytes());
        eprintln!(
            "{} MB chain of {op}: refused in {seconds:.2} s (vge starts in {start:.2} s), {} MB over vge's start",
            model.len() >> 20,
            over >> 20
        );
        assert!(!ok && err.contains(why), "{op}: {err}");
        assert!(over < 200 << 20, "{op}: refused after taking {over} bytes more than vge's start");
        assert!(!Path::new(out).exists());
    }
    let _ = std::fs::remove_dir_all(&root);
}
