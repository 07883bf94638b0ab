//! Fingertip slip in real episodes: a shipped policy that turns the cube slides its
//! fingertips over it, and the report's figure is the mean of its episodes'.

use std::path::{Path, PathBuf};

use vge_run::eval::{SUCCESS_TEST_GRASP_NOISE_RAD, eval_policy_bytes, policy_task_env, success_test_env};
use vge_sim::ObjectShape;

fn policies() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../policies")
}

#[test]
fn a_policy_that_turns_the_cube_slips_its_fingertips_over_it() {
    // The shipped Allegro policy turns the cube without a contact switch; the shipped vge15
    // gait turns it by switching contacts. 5 s episodes from randomised grasps.
    for (file, min_rotation_rad) in [("allegro-cube.vgep", 10.0), ("cube.vgep", 1.0)] {
        let bytes = std::fs::read(policies().join(file)).expect("the shipped policy");
        let task = policy_task_env(&bytes, None, ObjectShape::Cube).expect("its task");
        let env = success_test_env(&task, 5.0, SUCCESS_TEST_GRASP_NOISE_RAD);
        let report = eval_policy_bytes(&bytes, &env, 2, 0).expect("episodes");
        for e in &report.per_episode {
            println!(
                "{file}: {:.2} rad, {} switches, {:.4} m of slip",
                e.rotation_rad, e.contact_switches, e.tip_slip_m
            );
            assert!(e.rotation_rad > min_rotation_rad, "{file} turns the cube: {e:?}");
            // A still Allegro grasp creeps under 2 mm in 5 s (vge-sim's tests/tip_slip.rs).
            assert!(e.tip_slip_m.is_finite() && e.tip_slip_m > 0.05, "{file}: {e:?}");
        }
        let mean = report.per_episode.iter().map(|e| e.tip_slip_m).sum::<f64>() / 2.0;
        assert!((report.mean_tip_slip_m - mean).abs() < 1e-12, "{report:?}");
        let json: serde_json::Value = serde_json::from_str(&report.to_json_line()).expect("json");
        assert_eq!(json["mean_tip_slip_m"].as_f64(), Some(report.mean_tip_slip_m));
        assert_eq!(json["per_episode"][1]["tip_slip_m"].as_f64(), Some(report.per_episode[1].tip_slip_m));
    }
}
