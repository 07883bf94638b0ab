//! `vge-bridge run` refuses a policy file longer than any hand policy from its length alone,
//! before reading it (a 2 GB sparse file was read whole, twice, before).

use std::process::Command;

#[test]
fn a_2gb_sparse_policy_file_is_refused_unread_naming_the_limit() {
    let dir = std::env::temp_dir().join(format!("vge-bridge-policy-size-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let z = dir.join("z.vgep");
    // As `truncate -s 2G z.vgep`: no data blocks.
    std::fs::File::create(&z).expect("create").set_len(2 << 30).expect("set_len");
    let out = Command::new(env!("CARGO_BIN_EXE_vge-bridge"))
        .args(["run", "--policy", z.to_str().expect("utf-8"), "--backend", "can"])
        .output()
        .expect("runs vge-bridge");
    let err = String::from_utf8_lossy(&out.stderr);
    let limit = vge_runtime::policy::HAND_MAX_FILE_LEN;
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("2147483648 bytes")
            && err.contains(&format!("at most {limit} bytes"))
            && err.contains("not read"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
