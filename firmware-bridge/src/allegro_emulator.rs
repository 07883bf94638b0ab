//! An emulated Allegro Hand v4 on a CAN link, answering as the real one does
//! (docs/allegro-protocol.md): info, serial, position, temperature and status requests
//! answered at once; once a period is set, the four position frames every period (and the
//! temperatures every temperature period); torques applied to the joints while the servos are
//! on; servos off leave the joints limp.
//!
//! The joints are an [`AllegroPlant`]: the simulated hand holding its cube (`allegro_sim`,
//! with the `sim` feature), or anything else that turns torques into positions (the tests'
//! simple inertias).
//!
//! Time: the emulator advances its plant in steps of simulated milliseconds, one step per
//! report due (3 ms once the period is set, 10 ms while nothing is due), each at its wall-clock
//! deadline. When the host it runs on falls behind by more than a step, the emulator does not
//! catch up with a burst of frames: it starts its schedule again from now (and counts a late
//! step), so its simulated time runs slower than the wall clock rather than unevenly. The host
//! loop then sees what a real hand never sends, a late set, and reports it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::allegro_link::{AllegroLink, AllegroReceived};
use crate::protocol::allegro::{
    AllegroConfig, AllegroFrame, Command, Finger, FingerPosition, FingerTemperature, Handedness, Info,
    JOINTS_PER_FINGER, NUM_JOINTS, Report, Request, Serial, SetPeriod, Status,
};
use crate::transport::TransportError;

/// The emulated joints and what they touch.
pub trait AllegroPlant {
    /// Advances `ms` milliseconds of simulated time. With `servo_on` the joints are driven by
    /// `tau_nm` (held the whole step); without, they are limp.
    fn step(&mut self, servo_on: bool, tau_nm: &[f32; NUM_JOINTS], ms: u32);
    /// Joint angles now (rad, CAN order).
    fn q_rad(&self) -> [f32; NUM_JOINTS];
    /// Joint temperatures now (deg C).
    fn temperatures_c(&self) -> [i8; NUM_JOINTS] {
        [30; NUM_JOINTS]
    }
}

/// Who the emulated hand says it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmulatedHand {
    pub cfg: AllegroConfig,
    pub info: Info,
    pub serial: Serial,
}

impl Default for EmulatedHand {
    /// A right v4 hand (hardware 4.0, firmware 3.18, 12 V torque scale) at device 0.
    fn default() -> Self {
        Self {
            cfg: AllegroConfig::V4,
            info: Info {
                hardware_version: 0x0400,
                firmware_version: 0x0312,
                hand: Handedness::Right,
                palm_temperature_c: 30,
                status: Status { bits: 0 },
            },
            serial: Serial { ascii: *b"VGEEMU01" },
        }
    }
}

/// What the emulated hand received, sent and did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AllegroEmulatorStats {
    /// Commands decoded (requests included).
    pub commands: u64,
    pub requests_answered: u64,
    pub torque_frames: u64,
    /// Torque frames with a joint's count beyond that joint's clip: a host that lets such a
    /// frame out is broken (vge's encoder clips).
    pub torques_beyond_clip: u64,
    pub servo_ons: u64,
    pub servo_offs: u64,
    pub period_sets: u64,
    /// Sets of four position frames sent periodically.
    pub position_sets: u64,
    pub temperature_frames: u64,
    /// Frames that are no command to this hand (another device's, wrong lengths, reports).
    pub ignored_frames: u64,
    /// Steps that started more than a step late (the schedule restarted; see the module).
    pub late_steps: u64,
    /// Simulated time (ms).
    pub sim_ms: u64,
}

/// The hand's side of the protocol around a plant.
#[derive(Debug)]
pub struct AllegroHandEmulator<P: AllegroPlant> {
    hand: EmulatedHand,
    plant: P,
    servo_on: bool,
    tau_nm: [f32; NUM_JOINTS],
    period: SetPeriod,
    next_position_ms: Option<u64>,
    next_temperature_ms: Option<u64>,
    next_status_ms: Option<u64>,
    pub stats: AllegroEmulatorStats,
}

/// The longest step while no report is due: how finely limp joints are simulated.
const IDLE_STEP_MS: u64 = 10;
/// Frames taken in before a step at most: a flood of frames must not stop the hand's clock.
const MAX_FRAMES_PER_STEP: usize = 256;

impl<P: AllegroPlant> AllegroHandEmulator<P> {
    /// A hand with its servos off and no periodic report, as one powers up.
    pub fn new(hand: EmulatedHand, plant: P) -> Self {
        Self {
            hand,
            plant,
            servo_on: false,
            tau_nm: [0.0; NUM_JOINTS],
            period: SetPeriod::OFF,
            next_position_ms: None,
            next_temperature_ms: None,
            next_status_ms: None,
            stats: AllegroEmulatorStats::default(),
        }
    }

    pub fn plant(&self) -> &P {
        &self.plant
    }

    pub fn servo_on(&self) -> bool {
        self.servo_on
    }

    /// The torques the joints get now (zero with the servos off).
    pub fn torques_nm(&self) -> [f32; NUM_JOINTS] {
        if self.servo_on { self.tau_nm } else { [0.0; NUM_JOINTS] }
    }

    /// The periods last set.
    pub fn period(&self) -> SetPeriod {
        self.period
    }

    fn status(&self) -> Status {
        Status { bits: self.hand.info.status.bits | if self.servo_on { Status::SERVO_ON } else { 0 } }
    }

    fn push(&mut self, report: Report, out: &mut Vec<AllegroFrame>) {
        // A position outside the i16 range (a plant that blew up) cannot be sent: the host
        // sees the set missing, as from a hand whose joint stopped reporting.
        if let Ok(frame) = report.encode(&self.hand.cfg) {
            out.push(frame);
        }
    }

    fn position(&self, finger: Finger) -> Report {
        let q = self.plant.q_rad();
        let mut q_rad = [0.0; JOINTS_PER_FINGER];
        for (j, v) in q_rad.iter_mut().enumerate() {
            *v = q[finger.joint_index(j)];
        }
        Report::Position(FingerPosition { finger, q_rad })
    }

    fn temperature(&self, finger: Finger) -> Report {
        let t = self.plant.temperatures_c();
        let mut temperature_c = [0; JOINTS_PER_FINGER];
        for (j, v) in temperature_c.iter_mut().enumerate() {
            *v = t[finger.joint_index(j)];
        }
        Report::Temperature(FingerTemperature { finger, temperature_c })
    }

    /// Handles one received frame; answers go to `out`.
    pub fn handle(&mut self, frame: &AllegroFrame, out: &mut Vec<AllegroFrame>) {
        let Ok(command) = Command::decode_frame(&self.hand.cfg, frame) else {
            self.stats.ignored_frames += 1;
            return;
        };
        self.stats.commands += 1;
        let now = self.stats.sim_ms;
        match command {
            Command::ServoOn => {
                self.servo_on = true;
                self.stats.servo_ons += 1;
            }
            Command::ServoOff => {
                self.servo_on = false;
                // Servo on again starts from zero torque, not from what was last commanded.
                self.tau_nm = [0.0; NUM_JOINTS];
                self.stats.servo_offs += 1;
            }
            Command::SetTorque(t) => {
                self.stats.torque_frames += 1;
                let limits = self.hand.cfg.torque.pwm_limit[usize::from(t.finger.index())];
                let counts = frame.payload().chunks_exact(2).map(|b| i16::from_le_bytes([b[0], b[1]]));
                if counts.zip(limits).any(|(c, limit)| c.unsigned_abs() > limit.unsigned_abs()) {
                    self.stats.torques_beyond_clip += 1;
                }
                // Applied while the servos are on; kept for then otherwise, as a hand does not
                // move on torques it was sent with its servos off.
                if self.servo_on {
                    for (j, tau) in t.tau_nm.iter().enumerate() {
                        self.tau_nm[t.finger.joint_index(j)] = *tau;
                    }
                }
            }
            Command::SetPeriod(p) => {
                self.stats.period_sets += 1;
                self.period = p;
                let due = |ms: u16| (ms > 0).then(|| now + u64::from(ms));
                self.next_position_ms = due(p.position_ms);
                self.next_temperature_ms = due(p.temperature_ms);
                self.next_status_ms = due(p.status_ms);
            }
            Command::Request(r) => {
                self.stats.requests_answered += 1;
                let answer = match r {
                    Request::Info => Report::Info(Info { status: self.status(), ..self.hand.info }),
                    Request::Serial => Report::Serial(self.hand.serial),
                    Request::Position(f) => self.position(f),
                    Request::Temperature(f) => self.temperature(f),
                    Request::Status => Report::Status(self.status()),
                };
                self.push(answer, out);
            }
        }
    }

    /// Simulated milliseconds until the next report is due (at most [`IDLE_STEP_MS`]).
    pub fn next_step_ms(&self) -> u64 {
        let now = self.stats.sim_ms;
        [self.next_position_ms, self.next_temperature_ms, self.next_status_ms]
            .into_iter()
            .flatten()
            .map(|due| due.saturating_sub(now))
            .fold(IDLE_STEP_MS, u64::min)
            .max(1)
    }

    /// Advances the plant `ms` milliseconds and sends the reports then due.
    pub fn advance(&mut self, ms: u64, out: &mut Vec<AllegroFrame>) {
        let tau = self.torques_nm();
        self.plant.step(self.servo_on, &tau, u32::try_from(ms).unwrap_or(u32::MAX));
        self.stats.sim_ms += ms;
        let now = self.stats.sim_ms;
        let due = |next: &mut Option<u64>, period_ms: u16| match *next {
            Some(t) if t <= now => {
                // The next one a period after this one was due (not after now): no drift.
                *next = Some((t + u64::from(period_ms)).max(now + 1));
                true
            }
            _ => false,
        };
        if due(&mut self.next_position_ms, self.period.position_ms) {
            self.stats.position_sets += 1;
            for f in Finger::ALL {
                let r = self.position(f);
                self.push(r, out);
            }
        }
        if due(&mut self.next_temperature_ms, self.period.temperature_ms) {
            for f in Finger::ALL {
                self.stats.temperature_frames += 1;
                let r = self.temperature(f);
                self.push(r, out);
            }
        }
        if due(&mut self.next_status_ms, self.period.status_ms) {
            let s = Report::Status(self.status());
            self.push(s, out);
        }
    }
}

/// Runs `emulator` on `link` in real time until no frame has arrived for `idle_timeout`, or
/// `stop` is raised.
pub fn serve<L: AllegroLink, P: AllegroPlant>(
    link: &mut L,
    emulator: &mut AllegroHandEmulator<P>,
    idle_timeout: Duration,
    stop: &AtomicBool,
) -> Result<(), TransportError> {
    let mut out = Vec::new();
    let mut last_frame = Instant::now();
    let mut last_step = Instant::now();
    loop {
        if stop.load(Ordering::Relaxed) || last_frame.elapsed() > idle_timeout {
            return Ok(());
        }
        let step_ms = emulator.next_step_ms();
        let step = Duration::from_millis(step_ms);
        let deadline = last_step + step;
        // Wait for frames until the step is due, answering each at once; then, due or late,
        // take in everything already queued, so that a late step still applies every command
        // sent before it (a backlog would apply torques ever later).
        let wait = deadline.saturating_duration_since(Instant::now());
        let mut taken = 0;
        while let Some(received) = link.recv(if taken == 0 { wait } else { Duration::ZERO })? {
            last_frame = Instant::now();
            taken += 1;
            match received {
                AllegroReceived::Frame(f) => emulator.handle(&f, &mut out),
                AllegroReceived::Malformed { .. } | AllegroReceived::Error { .. } => {
                    emulator.stats.ignored_frames += 1;
                }
            }
            send_all(link, &mut out)?;
            if taken >= MAX_FRAMES_PER_STEP {
                break;
            }
        }
        let now = Instant::now();
        if now < deadline {
            continue;
        }
        emulator.advance(step_ms, &mut out);
        send_all(link, &mut out)?;
        // Late by more than a step: start the schedule again from now (see the module).
        last_step = if now.duration_since(deadline) > step {
            emulator.stats.late_steps += 1;
            now
        } else {
            deadline
        };
    }
}

/// Sends and empties `out`. A full transmit queue drops the frame, as a hand's controller
/// would drop a report it cannot get onto the bus; the host notices a missing set.
fn send_all<L: AllegroLink>(link: &mut L, out: &mut Vec<AllegroFrame>) -> Result<(), TransportError> {
    for frame in out.drain(..) {
        match link.send(&frame) {
            Ok(()) | Err(TransportError::TxQueueFull { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// A plant of 16 independent joints, each an inertia with viscous damping and a spring to
/// `rest_rad` (gravity's stand-in), stopped at its range: for tests of the loop without the
/// physics engine.
#[derive(Debug, Clone)]
pub struct InertiaPlant {
    pub q_rad: [f32; NUM_JOINTS],
    pub dq_radps: [f32; NUM_JOINTS],
    pub rest_rad: [f32; NUM_JOINTS],
    pub inertia_kg_m2: f32,
    pub damping_nms_per_rad: f32,
    pub spring_nm_per_rad: f32,
    pub range_rad: [(f32, f32); NUM_JOINTS],
}

impl InertiaPlant {
    /// Joints at `q_rad` at rest there, with the Allegro's armature-like inertia and joint
    /// damping, no spring.
    pub fn at(q_rad: [f32; NUM_JOINTS]) -> Self {
        Self {
            q_rad,
            dq_radps: [0.0; NUM_JOINTS],
            rest_rad: q_rad,
            inertia_kg_m2: 2e-4,
            damping_nms_per_rad: 0.1,
            spring_nm_per_rad: 0.0,
            range_rad: [(-2.5, 2.5); NUM_JOINTS],
        }
    }
}

impl AllegroPlant for InertiaPlant {
    fn step(&mut self, servo_on: bool, tau_nm: &[f32; NUM_JOINTS], ms: u32) {
        // Semi-implicit Euler in 0.1 ms substeps: stable for these inertias and gains.
        let dt = 1e-4f32;
        for _ in 0..ms * 10 {
            for (k, tau_k) in tau_nm.iter().enumerate() {
                let drive = if servo_on { *tau_k } else { 0.0 };
                let tau = drive
                    - self.damping_nms_per_rad * self.dq_radps[k]
                    - self.spring_nm_per_rad * (self.q_rad[k] - self.rest_rad[k]);
                self.dq_radps[k] += tau / self.inertia_kg_m2 * dt;
                self.q_rad[k] += self.dq_radps[k] * dt;
                let (lo, hi) = self.range_rad[k];
                if self.q_rad[k] < lo || self.q_rad[k] > hi {
                    self.q_rad[k] = self.q_rad[k].clamp(lo, hi);
                    self.dq_radps[k] = 0.0;
                }
            }
        }
    }

    fn q_rad(&self) -> [f32; NUM_JOINTS] {
        self.q_rad
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::allegro::{STARTUP_COMMANDS, SetTorque};

    fn emulator() -> AllegroHandEmulator<InertiaPlant> {
        AllegroHandEmulator::new(EmulatedHand::default(), InertiaPlant::at([0.1; NUM_JOINTS]))
    }

    fn send(e: &mut AllegroHandEmulator<InertiaPlant>, c: Command) -> Vec<Report> {
        let mut out = Vec::new();
        e.handle(&c.encode(&AllegroConfig::V4).expect("encodes"), &mut out);
        out.iter().map(|f| Report::decode_frame(&AllegroConfig::V4, f).expect("a report")).collect()
    }

    #[test]
    fn answers_the_start_up_and_reports_every_period_once_set() {
        let mut e = emulator();
        let mut answers = Vec::new();
        for c in STARTUP_COMMANDS {
            answers.extend(send(&mut e, c));
        }
        assert!(matches!(answers[0], Report::Info(i) if i.hardware_major() == 4 && !i.status.servo_on()));
        assert!(matches!(answers[1], Report::Serial(s) if s.as_str() == Some("VGEEMU01")));
        assert_eq!(answers.len(), 2);
        assert!(e.servo_on());
        assert_eq!(e.next_step_ms(), 3);
        let mut out = Vec::new();
        for _ in 0..10 {
            e.advance(e.next_step_ms(), &mut out);
        }
        assert_eq!((e.stats.sim_ms, e.stats.position_sets, out.len()), (30, 10, 40));
        let ids: Vec<u16> = out[..4].iter().map(AllegroFrame::id).collect();
        assert_eq!(ids, [0x080, 0x084, 0x088, 0x08C]);
        // Temperatures every 500 ms.
        out.clear();
        while e.stats.sim_ms < 1000 {
            e.advance(e.next_step_ms(), &mut out);
        }
        assert_eq!(e.stats.temperature_frames, 8);
        assert!(
            matches!(send(&mut e, Command::Request(Request::Status))[..], [Report::Status(s)] if s.servo_on())
        );
    }

    #[test]
    fn torques_move_the_joints_only_with_the_servos_on_and_clips_are_checked() {
        let mut e = emulator();
        let push = Command::SetTorque(SetTorque { finger: Finger::Ring, tau_nm: [0.0, 0.2, 0.0, 0.0] });
        send(&mut e, push);
        e.advance(10, &mut Vec::new());
        assert_eq!(e.plant().q_rad[9], 0.1, "servos off: limp, the torque is not applied");
        send(&mut e, Command::ServoOn);
        send(&mut e, push);
        e.advance(10, &mut Vec::new());
        assert!(e.plant().q_rad[9] > 0.11, "ring joint 1 pushed: {}", e.plant().q_rad[9]);
        assert_eq!(e.plant().q_rad[8], 0.1);
        send(&mut e, Command::ServoOff);
        assert_eq!(e.torques_nm(), [0.0; NUM_JOINTS]);
        assert_eq!(e.stats.torques_beyond_clip, 0);
        // A frame beyond the clip (made by hand: vge's encoder cannot make one).
        let mut out = Vec::new();
        let raw = AllegroFrame::data(0x180, &[0xE8, 0x03, 0, 0, 0, 0, 0, 0]).expect("frame");
        e.handle(&raw, &mut out);
        assert_eq!(e.stats.torques_beyond_clip, 1);
        // Another device's frame and a report are not commands to this hand.
        e.handle(&AllegroFrame::data(0x101, &[]).expect("frame"), &mut out);
        e.handle(&AllegroFrame::data(0x080, &[0; 8]).expect("frame"), &mut out);
        assert_eq!(e.stats.ignored_frames, 2);
        assert!(out.is_empty());
    }
}
