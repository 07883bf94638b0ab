//! The latest readings from the hand's nodes, assembled from protocol messages, with the time
//! each arrived so the control loop can tell fresh state from stale.

use std::time::{Duration, Instant};

use vge_sim::observation::FingertipReading;

use crate::protocol::{Message, NUM_FINGERS, STATUS_FAULT};

const FINGERS: usize = NUM_FINGERS as usize;

/// Per-finger readings; `None` until the first frame of that kind arrived.
#[derive(Debug, Clone, Default)]
pub struct HandState {
    q_rad: [Option<[f32; 3]>; FINGERS],
    q_at: [Option<Instant>; FINGERS],
    /// Sequence number each node last applied.
    pub applied_seq: [Option<u8>; FINGERS],
    pub dq_radps: [Option<[f32; 3]>; FINGERS],
    pub tau_nm: [Option<[f32; 3]>; FINGERS],
    q_target_rad: [Option<[f32; 3]>; FINGERS],
    tip_position_m: [Option<([f32; 3], f32)>; FINGERS],
    tip_normal: [Option<([f32; 3], bool)>; FINGERS],
    /// A node reported a fault (fault frame, or the fault bit in its position status).
    pub fault: [bool; FINGERS],
}

impl HandState {
    /// Takes in one decoded message received at `now`. Commands and heartbeats are ignored
    /// (they carry no hand state).
    pub fn apply(&mut self, message: &Message, now: Instant) {
        match *message {
            Message::JointPosition(p) => {
                let f = usize::from(p.finger.index());
                self.q_rad[f] = Some(p.q_rad);
                self.q_at[f] = Some(now);
                self.applied_seq[f] = Some(p.seq);
                self.fault[f] |= p.status & STATUS_FAULT != 0;
            }
            Message::JointVelocity(v) => self.dq_radps[usize::from(v.finger.index())] = Some(v.dq_radps),
            Message::JointEffort(e) => self.tau_nm[usize::from(e.finger.index())] = Some(e.tau_nm),
            Message::TipContact(t) => {
                self.tip_position_m[usize::from(t.finger.index())] = Some((t.position_m, t.force_n))
            }
            Message::TipNormal(n) => {
                self.tip_normal[usize::from(n.finger.index())] = Some((n.normal, n.in_contact))
            }
            Message::JointTarget(t) => {
                self.q_target_rad[usize::from(t.finger.index())] = Some(t.q_target_rad)
            }
            Message::Fault(f) => self.fault[usize::from(f.finger.index())] = true,
            Message::JointCommand(_) | Message::Heartbeat(_) => {}
        }
    }

    /// All 15 joint positions, once every finger has reported.
    pub fn q_rad(&self) -> Option<[f32; 15]> {
        let mut q = [0.0; 15];
        for (f, chunk) in q.chunks_exact_mut(3).enumerate() {
            chunk.copy_from_slice(&self.q_rad[f]?);
        }
        Some(q)
    }

    /// All 15 targets the nodes reported holding, once every finger has reported them.
    pub fn q_target_rad(&self) -> Option<[f32; 15]> {
        let mut q = [0.0; 15];
        for (f, chunk) in q.chunks_exact_mut(3).enumerate() {
            chunk.copy_from_slice(&self.q_target_rad[f]?);
        }
        Some(q)
    }

    /// Age of the oldest finger's joint position; `None` if some finger never reported.
    pub fn oldest_position_age(&self, now: Instant) -> Option<Duration> {
        self.q_at
            .iter()
            .map(|t| t.map(|t| now.saturating_duration_since(t)))
            .try_fold(Duration::ZERO, |oldest, age| age.map(|a| oldest.max(a)))
    }

    /// Fingertip contacts for the observation: `Some` only where the latest normal frame
    /// says the tip is in contact and a contact frame has arrived.
    pub fn contacts(&self) -> [Option<FingertipReading>; FINGERS] {
        std::array::from_fn(|f| match (self.tip_position_m[f], self.tip_normal[f]) {
            (Some((position_m, force_n)), Some((normal, true))) => {
                Some(FingertipReading { position_m, normal, force_n })
            }
            _ => None,
        })
    }

    pub fn any_fault(&self) -> bool {
        self.fault.iter().any(|&f| f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{FingerId, JointPosition, TipContact, TipNormal};

    #[test]
    fn positions_complete_only_when_every_finger_reported_and_ages_track_the_oldest() {
        let mut s = HandState::default();
        let t0 = Instant::now();
        for f in 0..4 {
            let finger = FingerId::new(f).expect("finger");
            s.apply(
                &Message::JointPosition(JointPosition { finger, q_rad: [0.1; 3], status: 1, seq: 1 }),
                t0,
            );
        }
        assert!(s.q_rad().is_none());
        assert!(s.oldest_position_age(t0).is_none());
        let later = t0 + Duration::from_millis(30);
        let finger = FingerId::new(4).expect("finger");
        s.apply(&Message::JointPosition(JointPosition { finger, q_rad: [0.2; 3], status: 3, seq: 1 }), later);
        assert_eq!(s.q_rad().map(|q| q[14]), Some(0.2));
        assert_eq!(s.oldest_position_age(later), Some(Duration::from_millis(30)));
        assert!(s.fault[4] && s.any_fault());
    }

    #[test]
    fn a_contact_counts_only_while_the_tip_reports_it() {
        let mut s = HandState::default();
        let now = Instant::now();
        let finger = FingerId::new(2).expect("finger");
        s.apply(&Message::TipContact(TipContact { finger, position_m: [0.06, 0.0, 0.0], force_n: 3.0 }), now);
        assert!(s.contacts()[2].is_none());
        s.apply(
            &Message::TipNormal(TipNormal { finger, normal: [-1.0, 0.0, 0.0], in_contact: true, seq: 0 }),
            now,
        );
        assert_eq!(s.contacts()[2].map(|c| c.force_n), Some(3.0));
        s.apply(
            &Message::TipNormal(TipNormal { finger, normal: [-1.0, 0.0, 0.0], in_contact: false, seq: 0 }),
            now,
        );
        assert!(s.contacts()[2].is_none());
    }
}
