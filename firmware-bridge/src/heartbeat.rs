//! When a heartbeat is due, and its counter: one schedule for the host and the nodes.

use std::time::{Duration, Instant};

use crate::protocol::HEARTBEAT_PERIOD_MS;

const PERIOD: Duration = Duration::from_millis(HEARTBEAT_PERIOD_MS as u64);

/// A 10 Hz heartbeat schedule with its wrapping counter.
#[derive(Debug, Clone)]
pub struct HeartbeatClock {
    next: Instant,
    counter: u8,
}

impl HeartbeatClock {
    /// The first heartbeat is due at `first_due`, with counter 0.
    pub fn new(first_due: Instant) -> Self {
        Self { next: first_due, counter: 0 }
    }

    /// The counter of the heartbeat due at `now`, if one is. The next is due a period after
    /// this one's due time, or now if that has passed too: a late caller catches up with at
    /// most one extra beat, never a burst of all it missed.
    pub fn tick(&mut self, now: Instant) -> Option<u8> {
        if now < self.next {
            return None;
        }
        self.next = (self.next + PERIOD).max(now);
        let counter = self.counter;
        self.counter = self.counter.wrapping_add(1);
        Some(counter)
    }

    /// How long until the next heartbeat is due, at most `cap` (a receive timeout).
    pub fn until_due(&self, now: Instant, cap: Duration) -> Duration {
        self.next.saturating_duration_since(now).min(cap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_beat_per_period_with_an_incrementing_counter_and_no_burst_when_late() {
        let t0 = Instant::now();
        let mut c = HeartbeatClock::new(t0);
        assert_eq!(c.tick(t0), Some(0));
        assert_eq!(c.tick(t0 + Duration::from_millis(50)), None);
        assert_eq!(
            c.until_due(t0 + Duration::from_millis(50), Duration::from_secs(1)),
            Duration::from_millis(50)
        );
        assert_eq!(c.tick(t0 + Duration::from_millis(100)), Some(1));
        // Half a second late: a beat now and one catching up, not the five missed.
        assert_eq!(c.tick(t0 + Duration::from_millis(700)), Some(2));
        assert_eq!(c.tick(t0 + Duration::from_millis(750)), Some(3));
        assert_eq!(c.tick(t0 + Duration::from_millis(760)), None);
        assert_eq!(c.tick(t0 + Duration::from_millis(800)), Some(4));
    }
}
