//! One-line JSON summaries of bridge runs, for scripts and the issue notes.

use serde_json::{Map, Value, json};

use crate::control_loop::LoopReport;

/// What happened to the object while the bridge drove the simulated hand (`sim_hand`, with
/// the `sim` feature). Plain data, here beside the summary that prints it, so that a bridge
/// built without the simulator prints the same summary less these fields.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimHandSummary {
    /// Control periods simulated.
    pub steps: u64,
    /// Net object rotation about +z (rad), unwrapped across ±π.
    pub rotation_rad: f32,
    /// Sum of the env's reward over the run.
    pub total_reward: f32,
    /// The env reported termination (drop, or too few fingertip contacts).
    pub terminated: bool,
    /// The object fell (the env's drop: `drop_height_m` below where the grasp left it).
    pub dropped: bool,
    pub mean_tip_contacts: f32,
    /// Fingertips that broke and remade contact with the object ([`vge_sim::gait`]).
    pub contact_switches: u32,
    /// How far the axis the object turned about overall leans from z (rad, 0 to π/2): near 0
    /// for a turn in an upright grasp, large for an object rolled about a tilted axis, which
    /// `rotation_rad` counts only in part.
    pub rotation_axis_tilt_rad: f32,
    /// How far the fingertips' contact points slid over the object (m, in its frame).
    pub tip_slip_m: f32,
}

impl SimHandSummary {
    /// The summary of an episode the env's tracker accounted; `dropped` is the env's own drop
    /// flag (the outcome's `terminated` also counts lost contacts).
    #[must_use]
    pub fn new(o: &vge_sim::episode::EpisodeOutcome, dropped: bool) -> Self {
        Self {
            steps: o.length as u64,
            rotation_rad: o.rotation_rad as f32,
            total_reward: o.episode_return as f32,
            terminated: o.terminated,
            dropped,
            mean_tip_contacts: o.mean_contacts as f32,
            contact_switches: o.contact_switches,
            rotation_axis_tilt_rad: o.rotation_axis_tilt_rad() as f32,
            tip_slip_m: o.tip_slip_m as f32,
        }
    }
}

/// Rounds to `digits` decimals, so the summary line stays short.
fn round(v: f64, digits: i32) -> Value {
    let scale = 10f64.powi(digits);
    json!((v * scale).round() / scale)
}

/// `{"rate_hz":..,"achieved_rate_hz":..,"jitter_p99_us":..,...}` with the loop's statistics,
/// the object's motion when the hand was simulated, and `extra` key/value pairs.
pub fn json_line(
    extra: &[(&str, Value)],
    rate_hz: f64,
    r: &LoopReport,
    sim: Option<&SimHandSummary>,
) -> String {
    let mut m = Map::new();
    for (k, v) in extra {
        m.insert((*k).to_owned(), v.clone());
    }
    let (pace, link) = (&r.pace, &r.link);
    let fields = [
        ("rate_hz", round(rate_hz, 3)),
        ("achieved_rate_hz", round(pace.achieved_rate_hz, 3)),
        ("jitter_p50_us", round(pace.wake_jitter.p50_us, 3)),
        ("jitter_p99_us", round(pace.wake_jitter.p99_us, 3)),
        ("jitter_max_us", round(pace.wake_jitter.max_us, 3)),
        ("loop_p50_us", round(pace.loop_time.p50_us, 3)),
        ("loop_p99_us", round(pace.loop_time.p99_us, 3)),
        ("loop_max_us", round(pace.loop_time.max_us, 3)),
        ("steps", json!(pace.steps)),
        ("deadline_misses", json!(pace.deadline_misses)),
        ("skipped_periods", json!(pace.skipped_periods)),
        ("frames_in", json!(link.frames_in)),
        ("frames_out", json!(link.frames_out)),
        ("messages_in", json!(link.messages_in)),
        ("messages_out", json!(link.messages_out)),
        ("bad_frames", json!(link.bad_frames)),
        ("stale_frames", json!(link.stale_frames)),
        ("implausible_frames", json!(link.implausible_frames)),
        ("lost_frames", json!(link.lost_frames)),
        ("error_frames", json!(link.error_frames.total())),
        ("error_frames_bus_off", json!(link.error_frames.bus_off)),
        ("error_frames_controller", json!(link.error_frames.controller)),
        ("error_frames_protocol", json!(link.error_frames.protocol)),
        ("error_frames_no_ack", json!(link.error_frames.no_ack)),
        ("error_frames_other", json!(link.error_frames.other)),
        ("tx_dropped", json!(link.tx_dropped)),
        ("overload_periods", json!(link.overload_periods)),
        ("heartbeats_out", json!(link.heartbeats_out)),
        ("holds", json!(r.holds)),
        ("policy_errors", json!(r.policy_errors)),
        ("non_finite_holds", json!(r.safety.non_finite_holds)),
        ("delta_clamps", json!(r.safety.delta_clamps)),
        ("limit_clamps", json!(r.safety.limit_clamps)),
        ("stop_reason", json!(r.stop_reason.as_str())),
        ("stop_detail", json!(r.stop_detail)),
    ];
    for (k, v) in fields {
        m.insert(k.to_owned(), v);
    }
    if let Some(s) = sim {
        m.insert("sim_steps".to_owned(), json!(s.steps));
        m.insert("rotation_rad".to_owned(), round(f64::from(s.rotation_rad), 4));
        m.insert("total_reward".to_owned(), round(f64::from(s.total_reward), 4));
        m.insert("mean_tip_contacts".to_owned(), round(f64::from(s.mean_tip_contacts), 3));
        m.insert("terminated".to_owned(), json!(s.terminated));
        m.insert("dropped".to_owned(), json!(s.dropped));
        m.insert("contact_switches".to_owned(), json!(s.contact_switches));
        m.insert("rotation_axis_tilt_rad".to_owned(), round(f64::from(s.rotation_axis_tilt_rad), 4));
        m.insert("tip_slip_m".to_owned(), round(f64::from(s.tip_slip_m), 4));
    }
    Value::Object(m).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control_loop::{ErrorFrameCounts, LinkCounts, StopReason};
    use crate::pacing::PaceFigures;
    use crate::safety::{SafetyCounts, SafetyFilter};
    use crate::stats::Percentiles;
    use vge_hand::JointLimit;

    /// A report whose every figure differs, so that a key reading the wrong figure shows.
    fn report() -> LoopReport {
        let pace = PaceFigures {
            steps: 41,
            achieved_rate_hz: 19.876_54,
            wake_jitter: Percentiles { p50_us: 12.345_6, p99_us: 45.678_9, max_us: 78.901_2 },
            loop_time: Percentiles { p50_us: 3.171_59, p99_us: 6.213_18, max_us: 9.424_77 },
            deadline_misses: 3,
            skipped_periods: 2,
        };
        let link = LinkCounts {
            frames_in: 101,
            frames_out: 102,
            messages_in: 103,
            messages_out: 104,
            bad_frames: 5,
            stale_frames: 6,
            implausible_frames: 7,
            lost_frames: 8,
            error_frames: ErrorFrameCounts {
                bus_off: 21,
                controller: 22,
                protocol: 23,
                no_ack: 24,
                other: 25,
            },
            tx_dropped: 9,
            overload_periods: 10,
            heartbeats_out: 11,
        };
        let mut safety =
            SafetyFilter::new(0.05, vec![JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 2], &[0.0; 2]);
        safety.counts = SafetyCounts { non_finite_holds: 13, delta_clamps: 14, limit_clamps: 15 };
        LoopReport::new(StopReason::Watchdog, "node 2 silent".to_owned(), pace, link, 12, 4, &safety)
    }

    /// Scripts and tests read these keys (`vge-bridge run --json`, scripts/demo.sh, the HIL
    /// tests): every key and value of a report's line, exactly.
    #[test]
    fn a_reports_json_line_keeps_its_keys_and_values() {
        let sim = SimHandSummary {
            steps: 400,
            rotation_rad: 0.123_456,
            total_reward: -1.987_61,
            terminated: false,
            dropped: true,
            mean_tip_contacts: 3.456_7,
            contact_switches: 6,
            rotation_axis_tilt_rad: 0.876_543,
            tip_slip_m: 0.012_345_6,
        };
        let line = json_line(&[("mode", json!("sim"))], 20.000_4, &report(), Some(&sim));
        let expected = concat!(
            r#"{"achieved_rate_hz":19.877,"bad_frames":5,"contact_switches":6,"deadline_misses":3,"#,
            r#""delta_clamps":14,"dropped":true,"error_frames":115,"error_frames_bus_off":21,"#,
            r#""error_frames_controller":22,"error_frames_no_ack":24,"error_frames_other":25,"#,
            r#""error_frames_protocol":23,"frames_in":101,"frames_out":102,"heartbeats_out":11,"#,
            r#""holds":12,"implausible_frames":7,"jitter_max_us":78.901,"jitter_p50_us":12.346,"#,
            r#""jitter_p99_us":45.679,"limit_clamps":15,"loop_max_us":9.425,"loop_p50_us":3.172,"#,
            r#""loop_p99_us":6.213,"lost_frames":8,"mean_tip_contacts":3.457,"messages_in":103,"#,
            r#""messages_out":104,"mode":"sim","non_finite_holds":13,"overload_periods":10,"#,
            r#""policy_errors":4,"rate_hz":20.0,"rotation_axis_tilt_rad":0.8765,"rotation_rad":0.1235,"#,
            r#""sim_steps":400,"#,
            r#""skipped_periods":2,"stale_frames":6,"steps":41,"stop_detail":"node 2 silent","#,
            r#""stop_reason":"watchdog","terminated":false,"tip_slip_m":0.0123,"total_reward":-1.9876,"#,
            r#""tx_dropped":9}"#,
        );
        assert_eq!(line, expected);
        // Without the simulated hand, the same line less the object's keys.
        let sim_keys = [
            "sim_steps",
            "rotation_rad",
            "total_reward",
            "mean_tip_contacts",
            "terminated",
            "dropped",
            "contact_switches",
            "rotation_axis_tilt_rad",
            "tip_slip_m",
        ];
        let mut expected: Map<String, Value> = serde_json::from_str(expected).expect("JSON");
        for key in sim_keys {
            expected.remove(key);
        }
        let line = json_line(&[("mode", json!("sim"))], 20.000_4, &report(), None);
        assert_eq!(line, Value::Object(expected).to_string());
    }
}
