//! A policy file's declared interface against the hand and observation set it is run with.

use vge_sim::observation::{ObservationLayout, ObservationSet};
use vge_sim::policy_interface::check_policy_interface;

fn fixture() -> Vec<u8> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/policies/allegro-proprio2-init.vgep");
    std::fs::read(path).expect("the stored proprio:2 Allegro policy")
}

#[test]
fn a_recorded_observation_set_must_be_the_one_its_inputs_spell() {
    let hand = vge_sim::hands::load("allegro").expect("allegro");
    let bytes = fixture();
    let info = vge_runtime::policy::inspect(&bytes).expect("a valid file");
    let layout = |set| ObservationLayout::new(set, hand.num_joints(), hand.num_fingers());
    let proprio2 = layout(ObservationSet::Proprio { history: 2 });
    check_policy_interface(&info, &hand, &proprio2).expect("its own set");

    // Other inputs than the file's: refused by the slices.
    let err = check_policy_interface(&info, &hand, &layout(ObservationSet::Full)).expect_err("full inputs");
    assert!(err.contains("observations"), "{err}");

    // The same inputs under another recorded set: refused by the record.
    let mut task = info.task.expect("a task record");
    task.observation_set = "proprio:1";
    let relabelled = vge_runtime::policy::PolicyInfo { task: Some(task), ..info };
    let err = check_policy_interface(&relabelled, &hand, &proprio2).expect_err("a relabelled file");
    assert!(err.contains("records the observation set proprio:1"), "{err}");
}
