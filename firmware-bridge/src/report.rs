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
    let link = &r.link;
    let fields = [
        ("rate_hz", round(rate_hz, 3)),
        ("achieved_rate_hz", round(r.achieved_rate_hz, 3)),
        ("jitter_p50_us", round(r.wake_jitter.p50_us, 3)),
        ("jitter_p99_us", round(r.wake_jitter.p99_us, 3)),
        ("jitter_max_us", round(r.wake_jitter.max_us, 3)),
        ("loop_p50_us", round(r.loop_time.p50_us, 3)),
        ("loop_p99_us", round(r.loop_time.p99_us, 3)),
        ("loop_max_us", round(r.loop_time.max_us, 3)),
        ("steps", json!(r.steps)),
        ("deadline_misses", json!(r.deadline_misses)),
        ("skipped_periods", json!(r.skipped_periods)),
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
    }
    Value::Object(m).to_string()
}
