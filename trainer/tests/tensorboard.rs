//! Event files written by `vge_trainer::tensorboard` read back by TensorBoard itself
//! (`tb_read.py`, TensorBoard's EventAccumulator; scripts/test.sh installs it in .deps/py).

mod common;

use common::tensorboard_scalars;
use vge_trainer::tensorboard::EventWriter;

#[test]
fn tensorboard_reads_our_scalars_and_drops_a_resumed_sessions_overlap() {
    let dir = std::env::temp_dir().join(format!("vge-tb-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    {
        let mut first = EventWriter::create(&dir, ".s0").expect("event file");
        for step in [10u64, 20, 30] {
            first
                .scalars(step, &[("train/return", step as f64 * 0.5), ("train/mean_q", -1.25)])
                .expect("write");
        }
    }
    // A session resumed from a checkpoint at step 20: its points replace the first
    // session's after 20; the row at 20 itself was logged before the checkpoint and stays.
    let mut second = EventWriter::create(&dir, ".s20").expect("second event file");
    second.session_start(20).expect("session start");
    for step in [30u64, 40] {
        second.scalars(step, &[("train/return", 100.0 + step as f64)]).expect("write");
    }
    drop(second);

    let scalars = tensorboard_scalars(&dir);
    let returns: Vec<(u64, f64)> =
        scalars.iter().filter(|(t, _, _)| t == "train/return").map(|(_, s, v)| (*s, *v)).collect();
    assert_eq!(returns, vec![(10, 5.0), (20, 10.0), (30, 130.0), (40, 140.0)]);
    let q: Vec<(u64, f64)> =
        scalars.iter().filter(|(t, _, _)| t == "train/mean_q").map(|(_, s, v)| (*s, *v)).collect();
    assert_eq!(q, vec![(10, -1.25), (20, -1.25)]);
    let _ = std::fs::remove_dir_all(&dir);
}
