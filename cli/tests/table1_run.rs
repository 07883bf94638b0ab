//! `vge table1`: the controllers alone, a cell's sweep and the table, on a tiny budget; run
//! again it trains nothing more.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

fn table1(out: &Path) -> Output {
    let mut args: Vec<String> =
        ["table1", "--cells", "cube-fg-rl", "--seeds", "0..1", "--jobs", "1"].map(str::to_owned).into();
    args.extend(["--controller-episodes", "1", "--controller-episode-s", "1"].map(str::to_owned));
    args.extend(common::tiny_args());
    args.extend(["--set".to_owned(), "total_steps=200".to_owned()]);
    args.push(out.to_string_lossy().into_owned());
    Command::new(env!("CARGO_BIN_EXE_vge"))
        .args(&args)
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(".."))
        .output()
        .expect("vge runs")
}

#[test]
fn the_table_comes_from_its_controllers_and_its_cells_and_resumes_as_done() {
    let out = common::temp_dir("table1-run");
    let first = table1(&out);
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    for kind in ["fg", "cs", "igm"] {
        let json = std::fs::read_to_string(out.join(format!("controllers/{kind}.json"))).expect("controller");
        assert!(json.trim_start().starts_with('{'), "{kind}: {json}");
    }
    let run = out.join("cube-fg-rl/seed-0");
    assert!(run.join("policy.vgep").is_file() && run.join("final-eval.json").is_file());
    let table = std::fs::read_to_string(out.join("table1.csv")).expect("table1.csv");
    assert!(table.lines().any(|l| l.starts_with("fg,rl,1,")), "{table}");
    assert!(out.join("table1.md").is_file());

    // Again: the seed is done and the controllers' files are kept.
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).expect("mtime");
    let (policy, fg) = (modified(&run.join("policy.vgep")), modified(&out.join("controllers/fg.json")));
    let second = table1(&out);
    assert!(second.status.success(), "{}", String::from_utf8_lossy(&second.stderr));
    assert_eq!(modified(&run.join("policy.vgep")), policy, "not trained again");
    assert_eq!(modified(&out.join("controllers/fg.json")), fg, "not run again");
    let _ = std::fs::remove_dir_all(&out);
}
