//! The hand's five nodes emulated by the simulator, speaking the CAN protocol: what
//! `vge-bridge emulate` puts on a bus and what `vge-bridge run --backend sim` drives.
//!
//! Lockstep: when enabled joint commands with one sequence number have arrived for all five
//! fingers, the simulator advances one control period towards those targets and every node
//! reports its state. Disabled commands (the bridge's start-up query) are answered without
//! advancing time. The sensor frames carry what the env observes (noise included), so the
//! bridge rebuilds the env's own observation, up to the protocol's quantisation. The node
//! duties (heartbeats, enable state, command timeout) are [`NodeSupervisor`]'s: a faulted
//! finger's commands are not applied, so the lockstep holds.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use thiserror::Error;
use vge_sim::observation::{OBS_CONTACT_FORCE, OBS_CONTACT_NORMAL, OBS_CONTACT_POSITION, OBS_DIM, OBS_Q};
use vge_sim::{Env, EnvConfig, NUM_JOINTS, SimError};

use crate::node_supervisor::NodeSupervisor;
use crate::protocol::*;
use crate::report::SimHandSummary;
use crate::transport::{Received, Transport, TransportError};

const FINGERS: usize = NUM_FINGERS as usize;

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

#[derive(Debug)]
pub struct SimHand {
    env: Env,
    obs: [f32; OBS_DIM],
    pending: [Option<JointCommand>; FINGERS],
    /// The run's accounting, as every episode loop of vge keeps it ([`vge_sim::episode`]).
    tracker: vge_sim::EpisodeTracker,
    terminated: bool,
    /// The nodes' protocol duties; `serve` polls it for heartbeats and timeouts.
    pub nodes: NodeSupervisor,
    /// Where each step is recorded (`run --record`), if anywhere.
    recorder: Option<vge_sim::EpisodeRecorder>,
}

impl SimHand {
    /// Builds the env and resets it with `seed` (the grasp is found by closing the fingers).
    /// An enabled finger that gets no command for `command_timeout` faults and holds.
    pub fn new(config: EnvConfig, seed: u64, command_timeout: Duration) -> Result<Self, SimHandError> {
        let mut env = Env::new(config)?;
        let (obs, _) = env.reset(seed)?;
        let tracker = env.episode_tracker()?;
        Ok(Self {
            env,
            obs,
            pending: [None; FINGERS],
            tracker,
            terminated: false,
            nodes: NodeSupervisor::new(command_timeout, Instant::now()),
            recorder: None,
        })
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
        let o = self.tracker.outcome(self.terminated);
        SimHandSummary {
            steps: o.length as u64,
            rotation_rad: o.rotation_rad as f32,
            total_reward: o.episode_return as f32,
            terminated: o.terminated,
            mean_tip_contacts: o.mean_contacts as f32,
            contact_switches: o.contact_switches,
        }
    }

    /// Takes one message received at `now`; returns the frames the nodes send in reply.
    pub fn on_message(&mut self, message: &Message, now: Instant) -> Result<Vec<RawFrame>, SimHandError> {
        let Message::JointCommand(cmd) = *message else { return Ok(Vec::new()) };
        if !self.nodes.on_command(&cmd, now) {
            // A faulted finger holds: its command does not count towards the next step.
            return Ok(Vec::new());
        }
        if !cmd.enable {
            // A query: this finger's node answers for itself, state then held targets.
            let finger = cmd.finger;
            let mut frames = self.state_frames(&[finger], cmd.seq)?;
            let q_target = self.env.privileged().map(|s| s.q_target_rad).unwrap_or([0.0; 15]);
            let f = 3 * usize::from(finger.index());
            let q_target_rad = [q_target[f], q_target[f + 1], q_target[f + 2]];
            frames.push(Message::JointTarget(JointTarget { finger, q_target_rad, seq: cmd.seq }).encode()?);
            return Ok(frames);
        }
        self.pending[usize::from(cmd.finger.index())] = Some(cmd);
        let complete = self.pending.iter().all(|p| p.is_some_and(|p| p.seq == cmd.seq));
        if !complete {
            return Ok(Vec::new());
        }
        let current = self.env.privileged().map(|s| s.q_target_rad).unwrap_or([0.0; 15]);
        let mut action = [0.0f32; 15];
        for p in self.pending.iter().flatten() {
            let base = usize::from(p.finger.index()) * 3;
            for j in 0..3 {
                action[base + j] = p.q_target_rad[j] - current[base + j];
            }
        }
        self.pending = [None; FINGERS];
        let result = self.env.step(&action)?;
        self.obs = result.obs;
        self.tracker.record(result.reward, result.info.object_rotation_z_rad, result.info.tip_contacts);
        self.terminated |= result.terminated;
        if let Some(recorder) = &mut self.recorder {
            recorder.record_step(&self.env, &action, &result)?;
        }
        let all: Vec<FingerId> = FingerId::all().collect();
        self.state_frames(&all, cmd.seq)
    }

    /// The state frames of `fingers`' nodes, from the latest observation.
    fn state_frames(&self, fingers: &[FingerId], seq: u8) -> Result<Vec<RawFrame>, SimHandError> {
        let state = self.env.privileged();
        let dq = self.env.world().map(|w| w.joint_velocities()).unwrap_or_else(|| vec![0.0; NUM_JOINTS]);
        let q_target = state.map(|s| s.q_target_rad).unwrap_or([0.0; NUM_JOINTS]);
        let hand = &self.env.config().hand;
        let kp = self.env.config().physics.motor_stiffness_nm_per_rad;
        let caps = hand.torque_caps_nm();
        let mut frames = Vec::with_capacity(FINGERS * 5);
        for &finger in fingers {
            let f = usize::from(finger.index());
            let q: [f32; 3] = std::array::from_fn(|j| self.obs[OBS_Q.start + 3 * f + j]);
            // Effort: the motor law's stiffness term, capped as the motors are (an estimate:
            // the simulator does not expose the applied motor torque).
            let tau: [f32; 3] = std::array::from_fn(|j| {
                let k = 3 * f + j;
                (kp * (q_target[k] - self.obs[OBS_Q.start + k])).clamp(-caps[k], caps[k])
            });
            let p: [f32; 3] = std::array::from_fn(|j| self.obs[OBS_CONTACT_POSITION.start + 3 * f + j]);
            let n: [f32; 3] = std::array::from_fn(|j| self.obs[OBS_CONTACT_NORMAL.start + 3 * f + j]);
            let force_n = self.obs[OBS_CONTACT_FORCE.start + f];
            let in_contact = state.is_some_and(|s| s.contacts[f].is_some());
            let messages = [
                Message::JointPosition(JointPosition {
                    finger,
                    q_rad: q,
                    status: self.nodes.status(finger),
                    seq,
                }),
                Message::JointVelocity(JointVelocity {
                    finger,
                    dq_radps: std::array::from_fn(|j| dq[3 * f + j].clamp(-32.0, 32.0)),
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
