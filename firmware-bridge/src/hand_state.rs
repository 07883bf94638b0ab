//! The latest readings from the hand's nodes, assembled from protocol messages, with the time
//! each arrived so the control loop can tell fresh state from stale.
//!
//! Readings are checked before they are kept (`Plausibility`): a frame whose seq lags the
//! last command sent by more than a bound is stale, a joint position outside the joint's
//! range plus a margin is implausible. Neither enters the state; [`HandState::apply`] says
//! which it was (the loop counts them), and both flag their finger as suspect until the loop
//! takes the flags ([`HandState::take_suspects`]).
//!
//! A node that restarts is noticed from its heartbeats ([`RestartSign`]): its boot-up
//! heartbeat (state booting), its counter starting again, or its enable state forgotten. The
//! loop clears what start-up saw ([`HandState::clear_restarts`]) and halts on any later one.
//!
//! The tables are sized by the hand ([`HandState::new`]: one slot per finger node, three joints
//! each); a frame from a node the hand does not have is refused ([`Applied::OtherNode`]).

use std::time::{Duration, Instant};

use vge_hand::JointLimit;
use vge_sim::observation::FingertipReading;

use crate::protocol::{HOST_NODE, JOINTS_PER_NODE, Message, NodeLayout, NodeState, STATUS_FAULT};

/// What a reading must satisfy to be believed.
#[derive(Debug, Clone)]
pub struct Plausibility {
    /// Every joint's range, in the hand's joint order.
    pub limits: Vec<JointLimit>,
    /// How far outside its range a measured joint may read (encoder noise, compliance).
    pub margin_rad: f32,
    /// Largest accepted lag of a frame's seq behind the last command sent.
    pub max_seq_lag: u8,
}

/// The last heartbeat of a node, and how often its counter repeated in a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeartbeatSeen {
    pub at: Instant,
    pub counter: u8,
    pub state: NodeState,
    pub repeats: u32,
}

/// Counter steps a heartbeat may advance by: 1, or more where beats were lost on the bus. A
/// larger step (a counter that went back, typically to 0) is a node that started counting
/// again: it restarted. Five beats lost are half a second without a heartbeat, which is a
/// lost node anyway.
pub const HEARTBEAT_MAX_STEP: u8 = 5;

/// What in a node's heartbeats says it restarted (docs/can-protocol.md, Semantics: restart).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestartSign {
    /// A heartbeat with state booting: the node's boot-up message.
    BootUp,
    /// The counter moved by more than [`HEARTBEAT_MAX_STEP`] (went back): it counts afresh.
    CounterJump { from: u8, to: u8 },
    /// The node reported enabled, then ready, with no disabling command in between: it lost
    /// the enable state the host's commands gave it.
    EnableLost,
}

impl std::fmt::Display for RestartSign {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BootUp => write!(f, "boot-up heartbeat (state booting)"),
            Self::CounterJump { from, to } => write!(f, "heartbeat counter went from {from} to {to}"),
            Self::EnableLost => {
                write!(f, "heartbeat state went from enabled to ready without a disabling command")
            }
        }
    }
}

/// What happened to one received message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Applied {
    Kept,
    /// Its seq lagged the last command by more than allowed (or was never sent).
    Stale,
    /// A joint position outside its range plus the margin.
    Implausible,
    /// Not hand state (commands, the host's heartbeat).
    Ignored,
    /// From a node id the hand does not have (another, larger hand's, or a stray node).
    OtherNode,
}

/// Per-finger readings, one slot per node of the hand; `None` until the first frame of that
/// kind arrived.
#[derive(Debug, Clone)]
pub struct HandState {
    q_rad: Vec<Option<[f32; 3]>>,
    q_at: Vec<Option<Instant>>,
    /// Sequence number each node last applied.
    pub applied_seq: Vec<Option<u8>>,
    pub dq_radps: Vec<Option<[f32; 3]>>,
    pub tau_nm: Vec<Option<[f32; 3]>>,
    q_target_rad: Vec<Option<[f32; 3]>>,
    tip_position_m: Vec<Option<([f32; 3], f32)>>,
    tip_normal: Vec<Option<([f32; 3], bool)>>,
    /// A node reported a fault (fault frame, the fault bit in its position status, or
    /// heartbeat state fault).
    pub fault: Vec<bool>,
    pub heartbeat: Vec<Option<HeartbeatSeen>>,
    /// The first sign of a restart of each node since the last `clear_restarts`.
    pub restarted: Vec<Option<RestartSign>>,
    /// Fingers that sent a stale or implausible frame since the last `take_suspects`.
    suspect: Vec<bool>,
}

impl HandState {
    /// No readings yet from the nodes of `nodes`.
    pub fn new(nodes: NodeLayout) -> Self {
        let n = nodes.num_fingers();
        Self {
            q_rad: vec![None; n],
            q_at: vec![None; n],
            applied_seq: vec![None; n],
            dq_radps: vec![None; n],
            tau_nm: vec![None; n],
            q_target_rad: vec![None; n],
            tip_position_m: vec![None; n],
            tip_normal: vec![None; n],
            fault: vec![false; n],
            heartbeat: vec![None; n],
            restarted: vec![None; n],
            suspect: vec![false; n],
        }
    }

    /// Finger nodes of the hand.
    pub fn num_fingers(&self) -> usize {
        self.q_rad.len()
    }

    /// Takes in one decoded message received at `now`, after checking it against `check`
    /// and `last_seq_sent` (the seq of the host's last command; `None` before the first).
    pub fn apply(
        &mut self,
        message: &Message,
        now: Instant,
        check: &Plausibility,
        last_seq_sent: Option<u8>,
    ) -> Applied {
        let node = match message {
            Message::Heartbeat(h) => (h.node != HOST_NODE).then_some(usize::from(h.node)),
            m => message_finger(m),
        };
        if node.is_some_and(|f| f >= self.num_fingers()) {
            return Applied::OtherNode;
        }
        if let (Some(finger), Some(seq), Some(sent)) =
            (message_finger(message), message_seq(message), last_seq_sent)
        {
            // Wrapping lag: a seq from the future (never sent) is a huge lag, also refused.
            if sent.wrapping_sub(seq) > check.max_seq_lag {
                self.suspect[finger] = true;
                return Applied::Stale;
            }
        }
        match *message {
            Message::JointPosition(p) => {
                let f = usize::from(p.finger.index());
                let outside = p.q_rad.iter().enumerate().any(|(j, &q)| {
                    // A hand without this joint's range reads nothing here as plausible.
                    check.limits.get(JOINTS_PER_NODE * f + j).is_none_or(|l| {
                        !(l.lower_rad - check.margin_rad..=l.upper_rad + check.margin_rad).contains(&q)
                    })
                });
                if outside {
                    self.suspect[f] = true;
                    return Applied::Implausible;
                }
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
            Message::Heartbeat(h) if usize::from(h.node) < self.num_fingers() => {
                let f = usize::from(h.node);
                let repeats = match self.heartbeat[f] {
                    Some(last) if last.counter == h.counter => last.repeats + 1,
                    _ => 0,
                };
                let sign = match self.heartbeat[f] {
                    _ if h.state == NodeState::Booting => Some(RestartSign::BootUp),
                    Some(last) if h.counter.wrapping_sub(last.counter) > HEARTBEAT_MAX_STEP => {
                        Some(RestartSign::CounterJump { from: last.counter, to: h.counter })
                    }
                    Some(last) if last.state == NodeState::Enabled && h.state == NodeState::Ready => {
                        Some(RestartSign::EnableLost)
                    }
                    _ => None,
                };
                if let Some(sign) = sign {
                    self.restarted[f].get_or_insert(sign);
                }
                self.heartbeat[f] =
                    Some(HeartbeatSeen { at: now, counter: h.counter, state: h.state, repeats });
                self.fault[f] |= h.state == NodeState::Fault;
            }
            Message::JointCommand(_) | Message::Heartbeat(_) => return Applied::Ignored,
        }
        Applied::Kept
    }

    /// Which fingers sent a stale or implausible frame since the last call; clears the flags.
    pub fn take_suspects(&mut self) -> Vec<bool> {
        let n = self.suspect.len();
        std::mem::replace(&mut self.suspect, vec![false; n])
    }

    /// The first node that showed a sign of a restart since the last [`Self::clear_restarts`],
    /// with the sign.
    pub fn restart(&self) -> Option<(usize, RestartSign)> {
        self.restarted.iter().enumerate().find_map(|(f, sign)| sign.map(|s| (f, s)))
    }

    /// Forgets the restarts seen so far (start-up takes the nodes as they are once they answer).
    pub fn clear_restarts(&mut self) {
        self.restarted.iter_mut().for_each(|r| *r = None);
    }

    /// The first node whose heartbeat is missing for longer than `timeout` (or never came),
    /// or whose counter repeated more than `max_repeats` times in a row.
    pub fn heartbeat_problem(
        &self,
        now: Instant,
        timeout: Duration,
        max_repeats: u32,
    ) -> Option<HeartbeatProblem> {
        self.heartbeat.iter().enumerate().find_map(|(f, seen)| match seen {
            None => Some(HeartbeatProblem::Missing { finger: f }),
            Some(s) if now.saturating_duration_since(s.at) > timeout => {
                Some(HeartbeatProblem::Missing { finger: f })
            }
            Some(s) if s.repeats > max_repeats => {
                Some(HeartbeatProblem::Stuck { finger: f, counter: s.counter })
            }
            Some(_) => None,
        })
    }

    /// Time of each finger's latest joint position.
    pub fn position_times(&self) -> Vec<Option<Instant>> {
        self.q_at.clone()
    }

    /// Every joint's position, in the hand's joint order, once every finger has reported.
    pub fn q_rad(&self) -> Option<Vec<f32>> {
        joined(&self.q_rad)
    }

    /// Every joint's target the nodes reported holding, once every finger has reported them.
    pub fn q_target_rad(&self) -> Option<Vec<f32>> {
        joined(&self.q_target_rad)
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
    pub fn contacts(&self) -> Vec<Option<FingertipReading>> {
        self.tip_position_m
            .iter()
            .zip(&self.tip_normal)
            .map(|(p, n)| match (p, n) {
                (Some((position_m, force_n)), Some((normal, true))) => {
                    Some(FingertipReading { position_m: *position_m, normal: *normal, force_n: *force_n })
                }
                _ => None,
            })
            .collect()
    }

    pub fn any_fault(&self) -> bool {
        self.fault.iter().any(|&f| f)
    }
}

/// Each node's three joints, node after node; `None` while a node is missing.
fn joined(per_node: &[Option<[f32; 3]>]) -> Option<Vec<f32>> {
    let mut q = Vec::with_capacity(JOINTS_PER_NODE * per_node.len());
    for node in per_node {
        q.extend_from_slice(&(*node)?);
    }
    Some(q)
}

/// Why a node's heartbeat is not trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeartbeatProblem {
    Missing { finger: usize },
    Stuck { finger: usize, counter: u8 },
}

/// The finger a node frame is about (`None` for commands and the host's heartbeat).
fn message_finger(m: &Message) -> Option<usize> {
    let finger = match m {
        Message::Fault(x) => x.finger,
        Message::JointPosition(x) => x.finger,
        Message::JointVelocity(x) => x.finger,
        Message::JointEffort(x) => x.finger,
        Message::TipContact(x) => x.finger,
        Message::TipNormal(x) => x.finger,
        Message::JointTarget(x) => x.finger,
        Message::JointCommand(_) | Message::Heartbeat(_) => return None,
    };
    Some(usize::from(finger.index()))
}

/// The seq a node frame echoes (the last command it applied). Faults are kept whatever
/// their seq: a fault is never ignored as stale.
fn message_seq(m: &Message) -> Option<u8> {
    match m {
        Message::JointPosition(x) => Some(x.seq),
        Message::JointVelocity(x) => Some(x.seq),
        Message::JointEffort(x) => Some(x.seq),
        Message::TipNormal(x) => Some(x.seq),
        Message::JointTarget(x) => Some(x.seq),
        Message::Fault(_) | Message::TipContact(_) | Message::JointCommand(_) | Message::Heartbeat(_) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{FingerId, Heartbeat, JointPosition, TipContact, TipNormal};

    fn check() -> Plausibility {
        Plausibility {
            limits: vec![JointLimit { lower_rad: -0.5, upper_rad: 0.5 }; 15],
            margin_rad: 0.1,
            max_seq_lag: 2,
        }
    }

    #[test]
    fn positions_complete_only_when_every_finger_reported_and_ages_track_the_oldest() {
        let mut s = HandState::new(NodeLayout::VGE15);
        let t0 = Instant::now();
        for f in 0..4 {
            let finger = FingerId::new(f).expect("finger");
            s.apply(
                &Message::JointPosition(JointPosition { finger, q_rad: [0.1; 3], status: 1, seq: 1 }),
                t0,
                &check(),
                Some(1),
            );
        }
        assert!(s.q_rad().is_none());
        assert!(s.oldest_position_age(t0).is_none());
        let later = t0 + Duration::from_millis(30);
        let finger = FingerId::new(4).expect("finger");
        s.apply(
            &Message::JointPosition(JointPosition { finger, q_rad: [0.2; 3], status: 3, seq: 1 }),
            later,
            &check(),
            None,
        );
        assert_eq!(s.q_rad().map(|q| q[14]), Some(0.2));
        assert_eq!(s.oldest_position_age(later), Some(Duration::from_millis(30)));
        assert!(s.fault[4] && s.any_fault());
    }

    #[test]
    fn a_contact_counts_only_while_the_tip_reports_it() {
        let mut s = HandState::new(NodeLayout::VGE15);
        let now = Instant::now();
        let finger = FingerId::new(2).expect("finger");
        s.apply(
            &Message::TipContact(TipContact { finger, position_m: [0.06, 0.0, 0.0], force_n: 3.0 }),
            now,
            &check(),
            None,
        );
        assert!(s.contacts()[2].is_none());
        s.apply(
            &Message::TipNormal(TipNormal { finger, normal: [-1.0, 0.0, 0.0], in_contact: true, seq: 0 }),
            now,
            &check(),
            None,
        );
        assert_eq!(s.contacts()[2].map(|c| c.force_n), Some(3.0));
        s.apply(
            &Message::TipNormal(TipNormal { finger, normal: [-1.0, 0.0, 0.0], in_contact: false, seq: 0 }),
            now,
            &check(),
            None,
        );
        assert!(s.contacts()[2].is_none());
    }

    #[test]
    fn stale_seqs_and_impossible_joint_positions_are_refused_counted_and_flag_the_finger() {
        let mut s = HandState::new(NodeLayout::VGE15);
        let now = Instant::now();
        let finger = FingerId::new(3).expect("finger");
        let position = |q: f32, seq: u8| {
            Message::JointPosition(JointPosition { finger, q_rad: [0.0, q, 0.0], status: 1, seq })
        };
        assert_eq!(
            s.apply(&position(0.55, 10), now, &check(), Some(12)),
            Applied::Kept,
            "lag 2, inside the margin"
        );
        assert_eq!(s.apply(&position(0.0, 9), now, &check(), Some(12)), Applied::Stale, "lag 3");
        assert_eq!(s.apply(&position(0.0, 13), now, &check(), Some(12)), Applied::Stale, "never sent");
        assert_eq!(s.apply(&position(3.2767, 12), now, &check(), Some(12)), Applied::Implausible);
        assert_eq!(s.apply(&position(-0.61, 12), now, &check(), Some(12)), Applied::Implausible);
        assert_eq!(s.q_rad[3], Some([0.0, 0.55, 0.0]), "only the plausible reading was kept");
        assert_eq!(s.take_suspects(), [false, false, false, true, false]);
        assert_eq!(s.take_suspects(), [false; 5], "taking clears");
        // Node 5 is on the bus's id range but not on vge15.
        let other = Message::JointPosition(JointPosition {
            finger: FingerId::new(5).expect("a node id"),
            q_rad: [0.0; 3],
            status: 1,
            seq: 12,
        });
        assert_eq!(s.apply(&other, now, &check(), Some(12)), Applied::OtherNode);
        assert_eq!(s.apply(&heartbeat_frame(6, 1, 0), now, &check(), None), Applied::OtherNode);
        assert_eq!(s.take_suspects(), [false; 5]);
        // Wrap-around: seq 255 is one behind 0.
        assert_eq!(s.apply(&position(0.0, 255), now, &check(), Some(0)), Applied::Kept);
    }

    #[test]
    fn heartbeats_missing_late_or_stuck_are_problems() {
        let mut s = HandState::new(NodeLayout::VGE15);
        let t0 = Instant::now();
        let timeout = Duration::from_millis(300);
        assert_eq!(s.heartbeat_problem(t0, timeout, 2), Some(HeartbeatProblem::Missing { finger: 0 }));
        let beat = |node, counter| Message::Heartbeat(Heartbeat { node, state: NodeState::Enabled, counter });
        for node in 0..5 {
            s.apply(&beat(node, 0), t0, &check(), None);
        }
        assert_eq!(s.heartbeat_problem(t0, timeout, 2), None);
        assert_eq!(
            s.heartbeat_problem(t0 + Duration::from_millis(301), timeout, 2),
            Some(HeartbeatProblem::Missing { finger: 0 })
        );
        for _ in 0..3 {
            s.apply(&beat(2, 0), t0, &check(), None);
        }
        assert_eq!(
            s.heartbeat_problem(t0, timeout, 2),
            Some(HeartbeatProblem::Stuck { finger: 2, counter: 0 })
        );
        s.apply(&beat(2, 1), t0, &check(), None);
        assert_eq!(s.heartbeat_problem(t0, timeout, 2), None);
        s.apply(
            &Message::Heartbeat(Heartbeat { node: 4, state: NodeState::Fault, counter: 1 }),
            t0,
            &check(),
            None,
        );
        assert!(s.fault[4], "a node in state fault is a fault");
    }

    /// A heartbeat as it is on the wire: id 0x700 + node, byte 0 the state, byte 1 the counter.
    fn heartbeat_frame(node: u8, state: u8, counter: u8) -> Message {
        Message::decode(0x700 + u16::from(node), &[state, counter, 0, 0, 0, 0, 0, 0]).expect("a heartbeat")
    }

    #[test]
    fn a_heartbeat_counter_that_starts_again_is_a_restart_and_lost_beats_are_not() {
        let mut s = HandState::new(NodeLayout::VGE15);
        let t0 = Instant::now();
        // Ready (1), then enabled (2): counters 250, 251, 253 (one lost), wrapping to 2 (three lost).
        for (state, counter) in [(1, 250), (2, 251), (2, 253), (2, 254), (2, 255), (2, 2)] {
            s.apply(&heartbeat_frame(3, state, counter), t0, &check(), None);
        }
        assert_eq!(s.restart(), None, "steps of 1 to 5, across the wrap, are lost beats");
        s.apply(&heartbeat_frame(3, 2, 8), t0, &check(), None);
        assert_eq!(s.restart(), Some((3, RestartSign::CounterJump { from: 2, to: 8 })), "six beats missing");
        s.clear_restarts();
        s.apply(&heartbeat_frame(3, 2, 9), t0, &check(), None);
        // The node restarted and counts from 0 again, its boot-up heartbeat lost.
        s.apply(&heartbeat_frame(3, 2, 0), t0, &check(), None);
        s.apply(&heartbeat_frame(3, 2, 1), t0, &check(), None);
        assert_eq!(s.restart(), Some((3, RestartSign::CounterJump { from: 9, to: 0 })));
        assert_eq!(
            s.restarted[3].map(|r| r.to_string()).as_deref(),
            Some("heartbeat counter went from 9 to 0")
        );
    }

    #[test]
    fn a_boot_up_heartbeat_or_a_forgotten_enable_is_a_restart() {
        let mut s = HandState::new(NodeLayout::VGE15);
        let t0 = Instant::now();
        // The boot-up message of node 1 (state 0 booting, counter 0), then ready.
        s.apply(&heartbeat_frame(1, 0, 0), t0, &check(), None);
        assert_eq!(s.restart(), Some((1, RestartSign::BootUp)));
        s.apply(&heartbeat_frame(1, 1, 1), t0, &check(), None);
        s.clear_restarts();
        // Enabled, then fault: a fault, not a restart.
        s.apply(&heartbeat_frame(1, 2, 2), t0, &check(), None);
        s.apply(&heartbeat_frame(1, 3, 3), t0, &check(), None);
        assert_eq!(s.restart(), None);
        assert!(s.fault[1]);
        // Node 4 restarts at counter 252: back to 0 is a step of 4, like lost beats, but its
        // boot-up message gives it away.
        s.apply(&heartbeat_frame(4, 2, 252), t0, &check(), None);
        s.apply(&heartbeat_frame(4, 0, 0), t0, &check(), None);
        assert_eq!(s.restart(), Some((4, RestartSign::BootUp)));
        s.clear_restarts();
        // And with that message lost, its next beat (counter 1: a step of 5 from 252) says
        // ready where it was enabled.
        s.apply(&heartbeat_frame(4, 2, 251), t0, &check(), None);
        s.apply(&heartbeat_frame(4, 2, 252), t0, &check(), None);
        s.clear_restarts();
        s.apply(&heartbeat_frame(4, 1, 1), t0, &check(), None);
        s.apply(&heartbeat_frame(4, 0, 2), t0, &check(), None);
        assert_eq!(s.restart(), Some((4, RestartSign::EnableLost)), "the first sign is kept");
    }
}
