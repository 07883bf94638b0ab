//! Every hand in hands/ loads with its TOML, and its fingers cover its joints in order.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use vge_hand::Hand;

#[test]
fn every_shipped_hand_loads_and_its_fingers_partition_the_joint_vector() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../hands");
    let mut loaded = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "xml") {
            let hand = Hand::load(&path).unwrap_or_else(|e| panic!("{e}"));
            let mut next = 0;
            for finger in hand.fingers() {
                assert_eq!(finger.joints.start, next, "{}: {}", hand.name(), finger.name);
                next = finger.joints.end;
            }
            assert_eq!(next, hand.num_joints());
            let q = vec![0.0f64; hand.num_joints()];
            assert_eq!(hand.fingertip_positions_m(&q).unwrap().len(), hand.num_fingers());
            loaded.push(path.file_stem().unwrap().to_string_lossy().into_owned());
        }
    }
    assert!(loaded.iter().any(|n| n == "vge15"), "{loaded:?}");
}
