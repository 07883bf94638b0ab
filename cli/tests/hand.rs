//! `vge hand inspect` on the shipped hands and on files it must refuse.

use std::process::Command;

fn inspect(hand: &str) -> (bool, String, String) {
    let out =
        Command::new(env!("CARGO_BIN_EXE_vge")).args(["hand", "inspect", hand]).output().expect("run vge");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_shipped_hands_are_summarised_with_their_own_sizes() {
    let (ok, out, err) = inspect("allegro");
    assert!(ok, "{err}");
    assert!(out.contains("16 joints, 4 fingers"), "{out}");
    assert!(out.contains("observation: full 60 floats (with fingertip contacts), proprio 32 floats (joints only); action 16 floats"), "{out}");
    assert!(out.contains("thj3") && out.contains("start grasp: -0.255"), "{out}");
    let (ok, out, err) = inspect("vge15");
    assert!(ok, "{err}");
    assert!(out.contains("15 joints, 5 fingers") && out.contains("full 65 floats"), "{out}");
    assert!(out.contains("start grasp: none"), "{out}");
}

#[test]
fn a_file_outside_the_subset_is_refused_naming_its_element_and_line() {
    let dir = std::env::temp_dir().join(format!("vge-hand-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("tendon.xml");
    std::fs::write(
        &file,
        "<mujoco>\n  <worldbody>\n    <body name=\"a\">\n      <joint name=\"j\"/>\n    </body>\n  </worldbody>\n  <tendon>\n    <fixed name=\"t\"><joint joint=\"j\" coef=\"1\"/></fixed>\n  </tendon>\n</mujoco>\n",
    )
    .expect("write");
    let (ok, _, err) = inspect(file.to_str().expect("utf-8 path"));
    assert!(!ok);
    assert!(err.contains("tendon.xml:8") && err.contains("fixed"), "{err}");
    let (ok, _, err) = inspect("no-such-hand");
    assert!(!ok && err.contains("not a shipped hand (vge15, allegro)"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}
