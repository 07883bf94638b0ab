//! The hand's finger nodes emulated by the simulator, speaking the CAN protocol: what
//! `vge-bridge emulate` puts on a bus and what `vge-bridge run --backend sim` drives. The env's
//! hand sets how many nodes there are (vge15: five); a hand the protocol cannot carry is
//! refused ([`ProtocolHand::of`]).
//!
//! Lockstep: when enabled joint commands with one sequence number have arrived for all the
//! fingers, the simulator advances one control period towards those targets and every node
//! reports its state. Disabled commands (the bridge's start-up query) are answered without
//! advancing time. The sensor frames carry what the env observes (noise included), so the
//! bridge rebuilds the env's own observation, up to the protocol's quantisation. The node
//! duties (heartbeats, enable state, command timeout) are [`NodeSupervisor`]'s: a faulted
//! finger's commands are not applied, so the lockstep holds.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use std::ops::Range;

use thiserror::Error;
use vge_sim::{Env, EnvConfig, SimError};

use crate::node_supervisor::NodeSupervisor;
use crate::protocol::*;
use crate::protocol_hand::{ProtocolHand, ProtocolHandError};
use crate::report::SimHandSummary;
use crate::transport::{Received, Transport, TransportError};

#[derive(Debug, Error)]
pub enum SimHandError {
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("recording: {0}")]
    Recording(#[from] vge_sim::RecordingError),
    #[error(transparent)]
    Hand(#[from] ProtocolHandError),
    #[error("the env's observation has no slice {0}")]
    Layout(&'static str),
}

/// Frames the emulated nodes saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServeStats {
    pub frames_in: u64,
    pub frames_out: u64,
    /// Malformed frames or unknown ids: counted and ignored.
    pub bad_frames: u64,
    /// Command-timeout faults the nodes raised.
    pub command_timeouts: u64,
    pub heartbeats_sent: u64,
    /// Node restarts emulated (`hand.nodes.plan_restart`).
    pub restarts: u64,
}

/// Answers the bridge on `transport` until `stop` is raised or nothing arrives for
/// `idle_timeout` (the bridge has gone).
pub fn serve<T: Transport>(
    transport: &mut T,
    hand: &mut SimHand,
    idle_timeout: Duration,
    stop: &AtomicBool,
) -> Result<ServeStats, SimHandError> {
    let mut stats = ServeStats::default();
    let mut last_frame = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        for frame in hand.nodes.poll(now)? {
            transport.send(&frame)?;
            stats.frames_out += 1;
        }
        if now.saturating_duration_since(last_frame) >= idle_timeout {
            break;
        }
        let wait = hand.nodes.until_due(now, Duration::from_millis(20));
        let Some(received) = transport.recv(wait)? else { continue };
        last_frame = Instant::now();
        stats.frames_in += 1;
        let message = match received {
            Received::Frame(f) => Message::decode_frame(&f),
            Received::Malformed { .. } | Received::Error { .. } => Err(ProtocolError::UnknownId(0)),
        };
        let Ok(message) = message else {
            stats.bad_frames += 1;
            continue;
        };
        for frame in hand.on_message(&message, last_frame)? {
            transport.send(&frame)?;
            stats.frames_out += 1;
        }
    }
    stats.command_timeouts = hand.nodes.command_timeouts;
    stats.heartbeats_sent = hand.nodes.heartbeats_sent;
    stats.restarts = hand.nodes.restarts;
    Ok(stats)
}

/// Where the readings the nodes report sit in the env's (full) observation.
#[derive(Debug, Clone)]
struct Slices {
    q: Range<usize>,
    contact_position: Range<usize>,
    contact_normal: Range<usize>,
    contact_force: Range<usize>,
}

#[derive(Debug)]
pub struct SimHand {
    env: Env,
    hand: ProtocolHand,
    slices: Slices,
    obs: Vec<f32>,
    pending: Vec<Option<JointCommand>>,
    /// The run's accounting, as every episode loop of vge keeps it ([`vge_sim::episode`]).
    tracker: vge_sim::EpisodeTracker,
    terminated: bool,
    dropped: bool,
    /// The nodes' protocol duties; `serve` polls it for heartbeats and timeouts.
    pub nodes: NodeSupervisor,
    /// Where each step is recorded (`run --record`), if anywhere.
    recorder: Option<vge_sim::EpisodeRecorder>,
}

impl SimHand {
    /// Builds the env and resets it with `seed` (the grasp is found by closing the fingers).
    /// An enabled finger that gets no command for `command_timeout` faults and holds.
    pub fn new(config: EnvConfig, seed: u64, command_timeout: Duration) -> Result<Self, SimHandError> {
        let hand = ProtocolHand::of(&config.hand)?;
        let layout = config.observation_layout();
        let slice = |name: &'static str| layout.range(name).ok_or(SimHandError::Layout(name));
        let slices = Slices {
            q: slice("q_rad")?,
            contact_position: slice("contact_position_m")?,
            contact_normal: slice("contact_normal")?,
            contact_force: slice("contact_force_n")?,
        };
        let mut env = Env::new(config)?;
        let (obs, _) = env.reset(seed)?;
        let tracker = env.episode_tracker()?;
        let nodes = NodeSupervisor::new(hand.nodes, command_timeout, Instant::now());
        Ok(Self {
            env,
            pending: vec![None; hand.num_fingers()],
            hand,
            slices,
            obs,
            tracker,
            terminated: false,
            dropped: false,
            nodes,
            recorder: None,
        })
    }

    /// The hand the nodes belong to.
    pub fn hand(&self) -> &ProtocolHand {
        &self.hand
    }

    /// Records every step from now on into `path` ([`vge_sim::recording`]); the actions
    /// recorded are the joint-target changes the commands asked for.
    pub fn record_to(&mut self, path: &std::path::Path) -> Result<(), SimHandError> {
        self.recorder = Some(vge_sim::EpisodeRecorder::create(path, self.env.config())?);
        Ok(())
    }

    /// Completes the recording [`Self::record_to`] began, if any: the steps it holds.
    pub fn finish_recording(&mut self) -> Result<Option<u64>, SimHandError> {
        Ok(self.recorder.take().map(vge_sim::EpisodeRecorder::finish).transpose()?)
    }

    pub fn env(&self) -> &Env {
        &self.env
    }

    pub fn summary(&self) -> SimHandSummary {
        SimHandSummary::new(&self.tracker.outcome(self.terminated), self.dropped)
    }

    /// Takes one message received at `now`; returns the frames the nodes send in reply.
    pub fn on_message(&mut self, message: &Message, now: Instant) -> Result<Vec<RawFrame>, SimHandError> {
        let Message::JointCommand(cmd) = *message else { return Ok(Vec::new()) };
        if !self.nodes.on_command(&cmd, now) {
            // A faulted finger holds: its command does not count towards the next step.
            return Ok(Vec::new());
        }
        // The supervisor takes no command for a node the hand does not have.
        if !cmd.enable {
            // A query: this finger's node answers for itself, state then held targets.
            let finger = cmd.finger;
            let mut frames = self.state_frames(&[finger], cmd.seq)?;
            let f = JOINTS_PER_NODE * finger.slot();
            let q_target = self.q_target_rad();
            let q_target_rad = std::array::from_fn(|j| q_target.get(f + j).copied().unwrap_or(0.0));
            frames.push(Message::JointTarget(JointTarget { finger, q_target_rad, seq: cmd.seq }).encode()?);
            return Ok(frames);
        }
        let Some(slot) = self.pending.get_mut(cmd.finger.slot()) else { return Ok(Vec::new()) };
        *slot = Some(cmd);
        let complete = self.pending.iter().all(|p| p.is_some_and(|p| p.seq == cmd.seq));
        if !complete {
            return Ok(Vec::new());
        }
        let current = self.q_target_rad();
        let mut action = vec![0.0f32; self.hand.num_joints()];
        for p in self.pending.iter().flatten() {
            let base = p.finger.slot() * JOINTS_PER_NODE;
            for j in 0..JOINTS_PER_NODE {
                action[base + j] = p.q_target_rad[j] - current.get(base + j).copied().unwrap_or(0.0);
            }
        }
        self.pending.iter_mut().for_each(|p| *p = None);
        let result = self.env.step(&action)?;
        self.tracker.record(
            result.reward,
            result.info.object_rotation_rad,
            &result.info.tip_contacts,
            result.info.tip_slip_m,
        );
        self.terminated |= result.terminated;
        self.dropped |= result.info.dropped;
        if let Some(recorder) = &mut self.recorder {
            recorder.record_step(&self.env, &action, &result)?;
        }
        self.obs = result.obs;
        let all: Vec<FingerId> = self.hand.nodes.fingers().collect();
        self.state_frames(&all, cmd.seq)
    }

    /// The joint targets the env holds (zeros before its first reset).
    fn q_target_rad(&self) -> Vec<f32> {
        self.env.privileged().map_or_else(|| vec![0.0; self.hand.num_joints()], |s| s.q_target_rad.clone())
    }

    /// The state frames of `fingers`' nodes, from the latest observation.
    fn state_frames(&self, fingers: &[FingerId], seq: u8) -> Result<Vec<RawFrame>, SimHandError> {
        let state = self.env.privileged();
        let n_joints = self.hand.num_joints();
        let dq = self.env.world().map(|w| w.joint_velocities()).unwrap_or_else(|| vec![0.0; n_joints]);
        let q_target = self.q_target_rad();
        let servos = &self.env.config().servos;
        let s = &self.slices;
        // Readings by index into the observation: 0 where it has none (never, for the env's
        // own full layout).
        let at = |i: usize| self.obs.get(i).copied().unwrap_or(0.0);
        let mut frames = Vec::with_capacity(fingers.len() * 5);
        for &finger in fingers.iter().filter(|f| self.hand.nodes.has(**f)) {
            let f = finger.slot();
            let joint = |j: usize| JOINTS_PER_NODE * f + j;
            let q: [f32; 3] = std::array::from_fn(|j| at(s.q.start + joint(j)));
            // Effort: the servo law's stiffness term, capped as the motors are (an estimate:
            // the simulator does not expose the applied motor torque).
            let tau: [f32; 3] = std::array::from_fn(|j| {
                let k = joint(j);
                let servo = servos.get(k);
                let (kp, cap) = servo.map_or((0.0, 0.0), |s| (s.kp_nm_per_rad, s.torque_cap_nm));
                (kp * (q_target.get(k).copied().unwrap_or(0.0) - at(s.q.start + k))).clamp(-cap, cap)
            });
            let p: [f32; 3] = std::array::from_fn(|j| at(s.contact_position.start + 3 * f + j));
            let n: [f32; 3] = std::array::from_fn(|j| at(s.contact_normal.start + 3 * f + j));
            let force_n = at(s.contact_force.start + f);
            let in_contact = state.is_some_and(|s| s.contacts.get(f).is_some_and(Option::is_some));
            let messages = [
                Message::JointPosition(JointPosition {
                    finger,
                    q_rad: q,
                    status: self.nodes.status(finger),
                    seq,
                }),
                Message::JointVelocity(JointVelocity {
                    finger,
                    dq_radps: std::array::from_fn(|j| {
                        dq.get(joint(j)).copied().unwrap_or(0.0).clamp(-32.0, 32.0)
                    }),
                    seq,
                }),
                Message::JointEffort(JointEffort { finger, tau_nm: tau, seq }),
                Message::TipContact(TipContact { finger, position_m: p, force_n: force_n.clamp(0.0, 65.0) }),
                Message::TipNormal(TipNormal {
                    finger,
                    normal: n.map(|c| c.clamp(-1.0, 1.0)),
                    in_contact,
                    seq,
                }),
            ];
            for m in messages {
                frames.push(m.encode()?);
            }
        }
        Ok(frames)
    }
}
