//! What a run has cost so far, summed over its sessions: wall time, and the CPU time of the
//! training process.
//!
//! Wall time counts every second the process existed, including time it was stopped
//! (SIGSTOP, to benchmark beside it) or waiting for a core another job held; CPU time counts
//! only the seconds its threads ran. A one-thread run that had its core to itself has the
//! two about equal, so a gap between them says the wall figure includes pauses or sharing.

use std::time::Instant;

use crate::cpu_time::process_cpu_s;

pub use vge_run::run_eval::RunCost;

/// The run's clock: the earlier sessions' cost plus this session's so far.
#[derive(Debug)]
pub struct RunClock {
    before: RunCost,
    session_start: Instant,
    session_cpu_start_s: Option<f64>,
}

impl RunClock {
    /// Starts this session's count on top of `before` (zero for a new run).
    pub fn start(before: RunCost) -> Self {
        Self { before, session_start: Instant::now(), session_cpu_start_s: process_cpu_s() }
    }

    /// Wall time of this session alone (s).
    pub fn session_wall_s(&self) -> f64 {
        self.session_start.elapsed().as_secs_f64()
    }

    pub fn now(&self) -> RunCost {
        let cpu_s = match (self.before.cpu_s, self.session_cpu_start_s, process_cpu_s()) {
            (Some(before), Some(start), Some(now)) => Some(before + (now - start)),
            _ => None,
        };
        RunCost { wall_s: self.before.wall_s + self.session_wall_s(), cpu_s }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_clocks_add_this_session_to_the_earlier_ones() {
        // Other tests run threads in this process, so only lower bounds hold for CPU time.
        // The spin lasts until the process has used 0.3 s of CPU since the clock started,
        // however little of a loaded machine it gets (a 0.3 s wall-time spin got 0.2 s).
        let clock = RunClock::start(RunCost { wall_s: 10.0, cpu_s: Some(4.0) });
        let cpu_after_start = process_cpu_s().expect("linux counts CPU time");
        let spin = Instant::now();
        let mut x = 0u64;
        while process_cpu_s().is_some_and(|now| now - cpu_after_start < 0.3) && spin.elapsed().as_secs() < 60
        {
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_add(1));
            }
        }
        // Read the spin's length before the clock: read after, it would include the clock's read.
        let spin_s = spin.elapsed().as_secs_f64();
        let cost = clock.now();
        assert!(cost.wall_s >= 10.0 + spin_s, "{cost:?} after a {spin_s} s spin");
        let cpu_s = cost.cpu_s.expect("linux counts CPU time");
        assert!(cpu_s >= 4.3, "0.3 s of CPU on top of 4 s counted as {cpu_s} s");
    }

    #[test]
    fn an_uncounted_earlier_session_leaves_cpu_time_unknown() {
        let clock = RunClock::start(RunCost { wall_s: 5.0, cpu_s: None });
        assert_eq!(clock.now().cpu_s, None);
        assert!(clock.now().wall_s >= 5.0);
    }
}
