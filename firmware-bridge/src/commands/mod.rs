//! The subcommands, one module each, and what they share: the loop's and the simulated hand's
//! options, real-time scheduling, signals, and the hand chosen.

pub mod allegro;
pub mod bench;
pub mod emulate;
pub mod run;

use std::io::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use vge_bridge::control_loop;
#[cfg(feature = "sim")]
use vge_sim::ObjectShape;
use vge_sim::action::DEFAULT_MAX_ACTION_RAD;

/// What `--object` parses into. Without the simulator the flag is still accepted, so that a
/// command line meant for it is refused by [`no_sim`] with the reason, not as a stray flag.
#[cfg(feature = "sim")]
pub type ObjectArg = ObjectShape;
#[cfg(not(feature = "sim"))]
pub type ObjectArg = String;

/// The simulated hand's episode, for `run --backend sim` and `emulate --model sim`.
#[derive(Debug, Args)]
pub struct SimHandArgs {
    /// Object in the simulated hand (`run --backend sim`, `emulate --model sim`): cube,
    /// sphere, cylinder, dodecahedron, icosahedron or hexagonal-prism, of the size the hand's
    /// description names (vge15: 10 cm; the Allegro: 65 mm). `emulate --hand allegro` and
    /// `run --hand allegro --hold` hold their 65 mm cube.
    #[arg(long, default_value = "cube")]
    pub object: ObjectArg,
    /// Seed of the simulated hand's episode.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Which hand `run` drives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HandArg {
    /// A hand on vge's own protocol, with the joint limits of its description: a shipped
    /// hand's name (`vge15`) or an MJCF file's path.
    Own(String),
    /// vge15 on vge's own protocol, with the joint limits of a hand file.
    Vge15File(PathBuf),
    /// The Allegro Hand v4 over its own protocol.
    Allegro,
}

/// `--hand`: a shipped hand's name, an MJCF hand description (`.xml`), or a hand file's path
/// (TOML: vge15's joint limits replaced).
pub fn parse_hand(s: &str) -> Result<HandArg, String> {
    Ok(match s {
        "allegro" => HandArg::Allegro,
        "" => {
            return Err(
                "a hand's name (vge15, allegro), an MJCF file (.xml) or a hand file's path".to_owned()
            );
        }
        name if vge_sim::hands::shipped_names().contains(&name) => HandArg::Own(name.to_owned()),
        path if path.ends_with(".xml") => HandArg::Own(path.to_owned()),
        path => HandArg::Vge15File(PathBuf::from(path)),
    })
}

/// Which hand `emulate` emulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum HandName {
    /// vge's own 15-joint hand: five finger nodes speaking vge's protocol.
    Vge15,
    /// The Allegro Hand v4 speaking its own protocol.
    Allegro,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Backend {
    /// The simulated hand, in process.
    Sim,
    /// A hand on a SocketCAN interface (`--iface`).
    Can,
}

#[derive(Debug, Args)]
pub struct LoopArgs {
    /// Control rate in Hz (default: the rate the policy was trained at; with --hand allegro
    /// the rate of the targets, 20 Hz, while the torque loop runs at the hand's 333 Hz).
    #[arg(long)]
    pub rate: Option<f64>,
    /// Seconds to run; 0 runs until Ctrl-C.
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// Stop after this many control steps (stop reason `steps`; with --hand allegro, torque
    /// sets), or at --duration if that comes first: a run of a fixed length whatever the
    /// host's speed.
    #[arg(long)]
    pub steps: Option<u64>,
    /// Largest joint-target change per step (rad), enforced whatever the policy says.
    #[arg(long, default_value_t = DEFAULT_MAX_ACTION_RAD)]
    pub max_delta_rad: f32,
    /// Periods without fresh joint state before the watchdog stops the loop (default 5 of the
    /// control rate; with --hand allegro 10 of the hand's 3 ms periods). Any other problem
    /// that persists this many periods (stale or implausible state, a failing policy, an
    /// overloaded bus, unsent commands) halts too.
    #[arg(long)]
    pub watchdog_periods: Option<u32>,
    /// Seconds start-up waits for the hand's first answers (every node's state; with --hand
    /// allegro the info answer and four position frames) before it gives up (default 5, with
    /// --hand allegro 2). A slow virtual bus, e.g. a loaded emulator, may need more.
    #[arg(long)]
    pub startup_timeout_s: Option<f64>,
    /// Seconds without a node's heartbeat before the loop halts (heartbeat_lost; vge15).
    #[arg(long, default_value_t = 0.5)]
    pub heartbeat_timeout_s: f64,
    /// Commands a node's frame may lag behind the latest one (its seq) and still count as the
    /// finger's state; an older frame is dropped and counted as stale (1-127; vge15). The
    /// default 3 is 0.15 s at 20 Hz; a slow link to the nodes may need more.
    #[arg(long, default_value_t = control_loop::DEFAULT_MAX_SEQ_LAG, value_parser = clap::value_parser!(u8).range(1..=127))]
    pub max_seq_lag: u8,
    /// Print one JSON line of statistics instead of a summary.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub realtime: RealtimeArgs,
}

#[derive(Debug, Clone, Copy, Args)]
pub struct RealtimeArgs {
    /// Run the loop under SCHED_FIFO at this priority (1-99) where permitted (root or
    /// CAP_SYS_NICE); without permission a warning is printed and the loop runs as usual.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub realtime_priority: Option<i32>,
    /// Pin the loop thread to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
}

impl RealtimeArgs {
    pub fn apply(self) {
        if self.realtime_priority.is_none() && self.cpu.is_none() {
            return;
        }
        let outcome =
            vge_bridge::realtime::make_current_thread_realtime(self.realtime_priority.unwrap_or(1), self.cpu);
        if self.realtime_priority.is_some() {
            match outcome.fifo {
                Ok(p) => note!("vge-bridge: SCHED_FIFO priority {p}"),
                Err(e) => {
                    note!("vge-bridge: warning: SCHED_FIFO refused ({e}); running with normal scheduling")
                }
            }
        }
        match outcome.pinned {
            Some(Ok(cpu)) => note!("vge-bridge: pinned to CPU {cpu}"),
            Some(Err(e)) => note!("vge-bridge: warning: pinning refused ({e})"),
            None => {}
        }
    }
}

/// A flag raised by Ctrl-C or SIGTERM, so loops stop cleanly.
pub fn stop_on_signal() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    Ok(stop)
}

pub fn positive_seconds(name: &str, s: f64, zero_ok: bool) -> anyhow::Result<Option<Duration>> {
    if !s.is_finite() || s < 0.0 || (s == 0.0 && !zero_ok) {
        bail!("--{name} must be a positive number of seconds, got {s}");
    }
    if s == 0.0 {
        return Ok(None);
    }
    Duration::try_from_secs_f64(s).map(Some).map_err(|_| anyhow::anyhow!("--{name} = {s} s is too long"))
}

/// Why a command that needs the simulator cannot run in this build (`run` asks before it
/// loads anything; the stand-ins compiled in its place refuse too).
pub fn no_sim(what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} needs the simulator, and this vge-bridge was built without it (cargo feature `sim`, on \
         by default): it drives real hands only, with `run --backend can` and `emulate --model lag`. \
         Rebuild with the default features for the simulated hand"
    )
}
