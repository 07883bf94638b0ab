//! What every finger node owes the bus besides its joint state (docs/can-protocol.md,
//! Semantics): a heartbeat at 10 Hz, the enable state it reports, and the command timeout.
//! Both emulators use it, so they behave as the protocol says a real node does.
//!
//! - **enable:** a finger is enabled by a command with the enable flag and disabled by one
//!   without; its position status and heartbeat say which.
//! - **command timeout:** an enabled finger that receives no command for `command_timeout`
//!   latches fault `command_timeout` (a fault frame, the status fault bit, heartbeat state
//!   fault) and holds: it applies no targets until a disabled command (the host's start-up
//!   query) clears the fault.
//! - **boot-up:** a node's first heartbeat says state booting with counter 0 (its boot-up
//!   message); its next ones count on from 1. A node restarted mid-run
//!   ([`NodeSupervisor::restart_node`], or planned with [`RestartPlan`]) does the same:
//!   disabled, its fault cleared, its counter from 0, as a joint controller that rebooted.

use std::time::{Duration, Instant};

use crate::heartbeat::HeartbeatClock;
use crate::protocol::{
    Fault, FaultCode, FingerId, HEARTBEAT_PERIOD_MS, Heartbeat, JointCommand, Message, NodeLayout, NodeState,
    ProtocolError, RawFrame, STATUS_ENABLED, STATUS_FAULT,
};

/// A node restart to emulate: `node` reboots right after it applied its
/// `after_enabled_commands`-th enabled command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RestartPlan {
    pub node: FingerId,
    pub after_enabled_commands: u64,
}

/// The protocol duties of a hand's finger nodes (vge15: five).
#[derive(Debug, Clone)]
pub struct NodeSupervisor {
    nodes: NodeLayout,
    command_timeout: Duration,
    enabled: Vec<bool>,
    fault: Vec<Option<FaultCode>>,
    last_command: Vec<Option<Instant>>,
    last_seq: Vec<u8>,
    /// The heartbeat schedule; each node counts its own beats.
    heartbeats: HeartbeatClock,
    counters: Vec<u8>,
    /// Nodes whose boot-up heartbeat is due at the next poll.
    booting: Vec<bool>,
    enabled_commands: Vec<u64>,
    restart_plan: Option<RestartPlan>,
    /// Command-timeout faults raised so far (one per finger and occurrence).
    pub command_timeouts: u64,
    pub heartbeats_sent: u64,
    /// Node restarts emulated so far.
    pub restarts: u64,
}

impl NodeSupervisor {
    /// The nodes of `nodes`, booting at `now`: disabled, their boot-up heartbeats due at once,
    /// the regular ones a period later.
    pub fn new(nodes: NodeLayout, command_timeout: Duration, now: Instant) -> Self {
        let n = nodes.num_fingers();
        Self {
            nodes,
            command_timeout,
            enabled: vec![false; n],
            fault: vec![None; n],
            last_command: vec![None; n],
            last_seq: vec![0; n],
            heartbeats: HeartbeatClock::new(now + Duration::from_millis(u64::from(HEARTBEAT_PERIOD_MS))),
            counters: vec![0; n],
            booting: vec![true; n],
            enabled_commands: vec![0; n],
            restart_plan: None,
            command_timeouts: 0,
            heartbeats_sent: 0,
            restarts: 0,
        }
    }

    /// Restarts `plan.node` once it has applied `plan.after_enabled_commands` enabled commands.
    pub fn plan_restart(&mut self, plan: RestartPlan) {
        self.restart_plan = Some(plan);
    }

    /// Reboots `finger`'s node: it forgets its enable state, fault and commands, and sends its
    /// boot-up heartbeat at the next poll, counting from 0 again.
    pub fn restart_node(&mut self, finger: FingerId) {
        if !self.nodes.has(finger) {
            return;
        }
        let f = finger.slot();
        self.enabled[f] = false;
        self.fault[f] = None;
        self.last_command[f] = None;
        self.counters[f] = 0;
        self.booting[f] = true;
        self.restarts += 1;
    }

    /// Takes in a command for its finger at `now`; returns whether the node applies its
    /// targets (`false` while a fault is latched: the finger holds, and for a node the hand
    /// does not have). A disabled command disables the finger and clears a latched fault.
    pub fn on_command(&mut self, cmd: &JointCommand, now: Instant) -> bool {
        if !self.nodes.has(cmd.finger) {
            return false;
        }
        let f = cmd.finger.slot();
        self.last_command[f] = Some(now);
        self.last_seq[f] = cmd.seq;
        if !cmd.enable {
            self.enabled[f] = false;
            self.fault[f] = None;
            return true;
        }
        if self.fault[f].is_some() {
            return false;
        }
        self.enabled[f] = true;
        self.enabled_commands[f] += 1;
        if let Some(plan) = self.restart_plan
            && plan.node == cmd.finger
            && plan.after_enabled_commands == self.enabled_commands[f]
        {
            // The command was applied; the node reboots right after.
            self.restart_plan = None;
            self.restart_node(cmd.finger);
        }
        true
    }

    /// The status byte of the finger's position frames.
    pub fn status(&self, finger: FingerId) -> u8 {
        let f = finger.slot();
        let enabled = if self.enabled.get(f).copied().unwrap_or(false) { STATUS_ENABLED } else { 0 };
        let fault = if self.fault.get(f).is_some_and(Option::is_some) { STATUS_FAULT } else { 0 };
        enabled | fault
    }

    /// The nodes supervised.
    pub fn nodes(&self) -> NodeLayout {
        self.nodes
    }

    /// Whether any finger has a fault latched.
    pub fn any_fault(&self) -> bool {
        self.fault.iter().any(Option::is_some)
    }

    /// Frames due at `now`: a fault frame for each enabled finger whose command timed out
    /// (it is then disabled and holds), and every node's heartbeat once per period.
    pub fn poll(&mut self, now: Instant) -> Result<Vec<RawFrame>, ProtocolError> {
        let mut frames = Vec::new();
        for finger in self.nodes.fingers() {
            let f = finger.slot();
            let silent_for = self.last_command[f].map(|t| now.saturating_duration_since(t));
            if self.enabled[f]
                && self.fault[f].is_none()
                && silent_for.is_some_and(|d| d > self.command_timeout)
            {
                self.fault[f] = Some(FaultCode::CommandTimeout);
                self.enabled[f] = false;
                self.command_timeouts += 1;
                let ms = silent_for.map_or(0, |d| d.as_millis());
                let fault = Fault {
                    finger,
                    code: FaultCode::CommandTimeout,
                    joint: None,
                    value: i16::try_from(ms).unwrap_or(i16::MAX),
                    seq: self.last_seq[f],
                };
                frames.push(Message::Fault(fault).encode()?);
            }
        }
        let regular = self.heartbeats.tick(now).is_some();
        for finger in self.nodes.fingers() {
            let f = finger.slot();
            let state = match (self.booting[f], self.fault[f], self.enabled[f]) {
                (true, _, _) => NodeState::Booting,
                (false, Some(_), _) => NodeState::Fault,
                (false, None, true) => NodeState::Enabled,
                (false, None, false) => NodeState::Ready,
            };
            if !(regular || self.booting[f]) {
                continue;
            }
            self.booting[f] = false;
            let beat = Heartbeat { node: finger.index(), state, counter: self.counters[f] };
            frames.push(Message::Heartbeat(beat).encode()?);
            self.counters[f] = self.counters[f].wrapping_add(1);
            self.heartbeats_sent += 1;
        }
        Ok(frames)
    }

    /// How long until [`Self::poll`] has something to send, at most `cap` (a receive timeout).
    pub fn until_due(&self, now: Instant, cap: Duration) -> Duration {
        if self.booting.iter().any(|&b| b) {
            return Duration::ZERO;
        }
        self.heartbeats.until_due(now, cap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::ids;

    fn cmd(finger: u8, enable: bool, seq: u8) -> JointCommand {
        JointCommand { finger: FingerId::new(finger).expect("finger"), q_target_rad: [0.0; 3], enable, seq }
    }

    fn decode(frames: &[RawFrame]) -> Vec<Message> {
        frames.iter().map(|f| Message::decode_frame(f).expect("valid frame")).collect()
    }

    #[test]
    fn heartbeats_every_period_with_a_counter_and_the_enable_state() {
        let t0 = Instant::now();
        let mut s = NodeSupervisor::new(NodeLayout::VGE15, Duration::from_millis(500), t0);
        let first = decode(&s.poll(t0).expect("frames"));
        assert_eq!(first.len(), 5);
        assert!(
            matches!(
                first[0],
                Message::Heartbeat(Heartbeat { node: 0, state: NodeState::Booting, counter: 0 })
            ),
            "the boot-up message"
        );
        assert!(s.poll(t0 + Duration::from_millis(50)).expect("frames").is_empty(), "not due yet");
        assert!(s.on_command(&cmd(2, true, 1), t0 + Duration::from_millis(60)));
        let second = decode(&s.poll(t0 + Duration::from_millis(100)).expect("frames"));
        assert!(matches!(
            second[2],
            Message::Heartbeat(Heartbeat { state: NodeState::Enabled, counter: 1, .. })
        ));
        assert!(matches!(
            second[1],
            Message::Heartbeat(Heartbeat { state: NodeState::Ready, counter: 1, .. })
        ));
        assert_eq!(s.status(FingerId::new(2).expect("finger")), STATUS_ENABLED);
        s.on_command(&cmd(2, false, 2), t0 + Duration::from_millis(110));
        assert_eq!(s.status(FingerId::new(2).expect("finger")), 0, "a disabled command disables");
    }

    #[test]
    fn a_planned_restart_reboots_one_node_after_its_nth_enabled_command() {
        let t0 = Instant::now();
        let mut s = NodeSupervisor::new(NodeLayout::VGE15, Duration::from_millis(500), t0);
        let node = FingerId::new(2).expect("finger");
        s.plan_restart(RestartPlan { node, after_enabled_commands: 3 });
        s.poll(t0).expect("boot-up messages");
        let mut t = t0;
        for seq in 1..=3 {
            t += Duration::from_millis(100);
            s.on_command(&cmd(1, true, seq), t);
            assert!(s.on_command(&cmd(2, true, seq), t), "the third command is applied too");
            assert_eq!(s.restarts, u64::from(seq == 3));
            let beats = decode(&s.poll(t).expect("frames"));
            if seq < 3 {
                assert_eq!(s.status(node), STATUS_ENABLED);
                assert!(matches!(beats[2], Message::Heartbeat(Heartbeat { state: NodeState::Enabled, .. })));
            } else {
                assert_eq!(s.status(node), 0, "the rebooted node is disabled");
                // Node 2's boot-up message (counter from 0), the others' regular beats.
                assert!(matches!(
                    beats[2],
                    Message::Heartbeat(Heartbeat { node: 2, state: NodeState::Booting, counter: 0 })
                ));
                assert!(matches!(
                    beats[1],
                    Message::Heartbeat(Heartbeat { node: 1, state: NodeState::Enabled, counter: 3 })
                ));
            }
        }
        // The next beat counts on from 1, ready; the plan does not fire again.
        let beats = decode(&s.poll(t + Duration::from_millis(100)).expect("frames"));
        assert!(matches!(
            beats[2],
            Message::Heartbeat(Heartbeat { state: NodeState::Ready, counter: 1, .. })
        ));
        s.on_command(&cmd(2, true, 4), t + Duration::from_millis(110));
        s.on_command(&cmd(2, true, 5), t + Duration::from_millis(120));
        s.on_command(&cmd(2, true, 6), t + Duration::from_millis(130));
        assert_eq!(s.restarts, 1);
    }

    #[test]
    fn an_enabled_finger_without_commands_latches_command_timeout_and_holds_until_disabled() {
        let t0 = Instant::now();
        let mut s = NodeSupervisor::new(NodeLayout::VGE15, Duration::from_millis(200), t0);
        s.poll(t0).expect("first heartbeats");
        let finger = FingerId::new(1).expect("finger");
        s.on_command(&cmd(1, true, 7), t0);
        s.on_command(&cmd(3, false, 7), t0);
        // Within the timeout: nothing but heartbeats.
        assert!(
            s.poll(t0 + Duration::from_millis(150)).expect("frames").iter().all(|f| f.id >= ids::HEARTBEAT)
        );
        let frames = s.poll(t0 + Duration::from_millis(250)).expect("frames");
        let faults: Vec<_> = decode(&frames)
            .into_iter()
            .filter_map(|m| if let Message::Fault(f) = m { Some(f) } else { None })
            .collect();
        assert_eq!(faults.len(), 1, "only the enabled finger times out");
        assert_eq!((faults[0].finger, faults[0].code, faults[0].seq), (finger, FaultCode::CommandTimeout, 7));
        assert_eq!(faults[0].value, 250, "milliseconds without a command");
        assert_eq!(s.status(finger), STATUS_FAULT);
        assert_eq!(s.command_timeouts, 1);
        // Latched: enabled commands are not applied, and the fault is not raised twice.
        assert!(!s.on_command(&cmd(1, true, 8), t0 + Duration::from_millis(260)));
        assert!(
            s.poll(t0 + Duration::from_millis(900)).expect("frames").iter().all(|f| f.id >= ids::HEARTBEAT)
        );
        assert_eq!(s.command_timeouts, 1);
        // A disabled command (the host querying again) clears it.
        assert!(s.on_command(&cmd(1, false, 9), t0 + Duration::from_millis(950)));
        assert!(s.on_command(&cmd(1, true, 10), t0 + Duration::from_millis(960)));
        assert_eq!(s.status(finger), STATUS_ENABLED);
    }

    #[test]
    fn a_hand_of_other_size_beats_for_its_own_nodes_and_ignores_the_rest() {
        let t0 = Instant::now();
        let nodes = NodeLayout::new(2).expect("two nodes");
        let mut s = NodeSupervisor::new(nodes, Duration::from_millis(500), t0);
        let beats = decode(&s.poll(t0).expect("frames"));
        assert_eq!(beats.len(), 2);
        assert!(!s.on_command(&cmd(2, true, 1), t0), "node 2 is not this hand's");
        assert_eq!(s.status(FingerId::new(2).expect("node id")), 0);
        assert!(s.on_command(&cmd(1, true, 1), t0));
    }
}
