//! One-line JSON summaries of bridge runs, for scripts and the issue notes.

use crate::control_loop::{LoopReport, StopReason};
use crate::sim_hand::SimHandSummary;

fn stop_reason(r: StopReason) -> &'static str {
    match r {
        StopReason::DurationReached => "duration",
        StopReason::StopRequested => "stop_requested",
        StopReason::Watchdog => "watchdog",
        StopReason::NodeFault => "node_fault",
    }
}

/// `{"rate_hz":..,"achieved_rate_hz":..,"jitter_p99_us":..,...}` with the loop's statistics,
/// the object's motion when the hand was simulated, and `extra` key/value pairs first.
pub fn json_line(
    extra: &[(&str, String)],
    rate_hz: f64,
    r: &LoopReport,
    sim: Option<&SimHandSummary>,
) -> String {
    let mut fields: Vec<(String, String)> = extra.iter().map(|(k, v)| ((*k).to_owned(), v.clone())).collect();
    let mut num = |k: &str, v: f64| fields.push((k.to_owned(), format!("{v:.3}")));
    num("rate_hz", rate_hz);
    num("achieved_rate_hz", r.achieved_rate_hz);
    num("jitter_p50_us", r.wake_jitter.p50_us);
    num("jitter_p99_us", r.wake_jitter.p99_us);
    num("jitter_max_us", r.wake_jitter.max_us);
    num("loop_p50_us", r.loop_time.p50_us);
    num("loop_p99_us", r.loop_time.p99_us);
    num("loop_max_us", r.loop_time.max_us);
    let mut int = |k: &str, v: u64| fields.push((k.to_owned(), v.to_string()));
    int("steps", r.steps);
    int("deadline_misses", r.deadline_misses);
    int("frames_in", r.frames_in);
    int("frames_out", r.frames_out);
    int("bad_frames", r.bad_frames);
    int("non_finite_holds", r.safety.non_finite_holds);
    int("delta_clamps", r.safety.delta_clamps);
    int("limit_clamps", r.safety.limit_clamps);
    fields.push(("stop_reason".to_owned(), format!("\"{}\"", stop_reason(r.stop_reason))));
    if let Some(s) = sim {
        fields.push(("sim_steps".to_owned(), s.steps.to_string()));
        fields.push(("rotation_rad".to_owned(), format!("{:.4}", s.rotation_rad)));
        fields.push(("total_reward".to_owned(), format!("{:.4}", s.total_reward)));
        fields.push(("mean_tip_contacts".to_owned(), format!("{:.3}", s.mean_tip_contacts)));
        fields.push(("terminated".to_owned(), s.terminated.to_string()));
    }
    let body: Vec<String> = fields.iter().map(|(k, v)| format!("\"{k}\":{v}")).collect();
    format!("{{{}}}", body.join(","))
}
