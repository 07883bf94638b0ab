//! `vge bench train`: env steps per second of real training (a config's envs, behaviour
//! policy, replay and updates) after its warm-up, with the phase split of that time; and the
//! same beside another process that keeps one core busy, where libtorch's worker threads
//! wait for a core (docs/training.md, "Training speed").

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use vge_run::config::Config;

use thiserror::Error;

use crate::learner::threads::Overlap;
use crate::train::{self, PhaseTimes, TrainError};

#[derive(Debug, Error)]
pub enum BenchTrainError {
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error("the benchmark run ended at step {ended_at} before {steps} steps past the warm-up")]
    TooShort { ended_at: u64, steps: u64 },
    #[error("starting the process that keeps a core busy (sh): {0}")]
    Burner(std::io::Error),
}

/// One measured run: `steps` env steps after the warm-up at `threads` libtorch threads.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainBench {
    /// `sac.threads` of the run.
    pub threads: i32,
    /// A thread kept one core busy for the whole run.
    pub beside_busy_core: bool,
    /// libtorch's threads followed the idle cores ([`crate::learner::ThreadGovernor`]); else
    /// they stayed at `threads`.
    pub adaptive_threads: bool,
    /// Where the envs stepped with two cores or more ([`Overlap`]).
    pub overlap: Overlap,
    /// Env steps and updates in the measured window (after the warm-up).
    pub env_steps: u64,
    pub updates: u64,
    /// Where the window's wall time went (`total_s`: the window's wall time).
    pub phases: PhaseTimes,
}

impl TrainBench {
    pub fn steps_per_s(&self) -> f64 {
        self.env_steps as f64 / self.phases.total_s.max(1e-9)
    }

    pub fn updates_per_s(&self) -> f64 {
        self.updates as f64 / self.phases.update_s.max(1e-9)
    }

    /// The window's time outside the named phases (metrics rows, progress, the loop).
    pub fn other_s(&self) -> f64 {
        let p = &self.phases;
        (p.total_s - p.sim_s - p.behaviour_s - p.learner_s - p.update_s - p.eval_s - p.checkpoint_s).max(0.0)
    }

    /// `(name, seconds)` of each phase: simulation, controllers with their Q queries, the
    /// actor's behaviour actions, updates, the rest.
    pub fn split(&self) -> [(&'static str, f64); 5] {
        let p = &self.phases;
        [
            ("sim", p.sim_s),
            ("controllers", p.behaviour_s),
            ("actor", p.learner_s),
            ("update", p.update_s),
            ("other", self.other_s() + p.eval_s + p.checkpoint_s),
        ]
    }
}

/// `config` as the benchmark runs it: `threads` libtorch threads, no periodic evaluation,
/// checkpoint or held-out score, no replay buffer saved at the end, and steps enough that the
/// benchmark's stop, not the budget, ends it.
pub fn bench_config(config: &Config, threads: i32, steps: u64) -> Config {
    let mut c = config.clone();
    c.sac.threads = threads;
    c.run.eval_interval = 0;
    c.run.checkpoint_interval = 0;
    c.run.score_episodes = 0;
    c.run.save_replay = false;
    c.init_from = None;
    c.total_steps = c.sac.warmup + steps + 2 * c.num_envs as u64;
    c
}

/// Another process that keeps one core busy until dropped (a shell's empty loop): the other
/// job of a shared machine. A process, not a thread of this one, so that the run's thread
/// governor counts it as someone else's work, as it would count another job.
struct CoreBurner(std::process::Child);

impl CoreBurner {
    fn start() -> std::io::Result<Self> {
        std::process::Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .stdin(std::process::Stdio::null())
            .spawn()
            .map(Self)
    }
}

impl Drop for CoreBurner {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The difference of two phase snapshots of one session.
fn phases_between(start: &PhaseTimes, end: &PhaseTimes) -> PhaseTimes {
    PhaseTimes {
        learner_s: end.learner_s - start.learner_s,
        behaviour_s: end.behaviour_s - start.behaviour_s,
        sim_s: end.sim_s - start.sim_s,
        update_s: end.update_s - start.update_s,
        sim_beside_updates_s: end.sim_beside_updates_s - start.sim_beside_updates_s,
        eval_s: end.eval_s - start.eval_s,
        checkpoint_s: end.checkpoint_s - start.checkpoint_s,
        total_s: end.total_s - start.total_s,
    }
}

/// A scratch run folder under the system's temporary directory, removed when dropped.
struct ScratchDir(PathBuf);

impl ScratchDir {
    fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("vge-bench-train-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        Self(dir)
    }

    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// How one benchmark run trains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchRun {
    /// `sac.threads`.
    pub threads: i32,
    /// Env steps measured after the warm-up.
    pub steps: u64,
    pub beside_busy_core: bool,
    /// Whether libtorch's threads follow the idle cores (training's default) or stay fixed.
    pub adaptive_threads: bool,
    /// Where the envs step with two cores or more: the faster schedule (training's default),
    /// beside the updates, or between them.
    pub overlap: Overlap,
}

/// Trains `config` (see [`bench_config`]) in a scratch folder through its warm-up and then
/// `steps` env steps, beside a busy core when asked, and reports that window.
pub fn run(config: &Config, how: BenchRun) -> Result<TrainBench, BenchTrainError> {
    let BenchRun { threads, steps, beside_busy_core, adaptive_threads, overlap } = how;
    crate::learner::threads::set_adapting(adaptive_threads);
    crate::learner::threads::set_overlap(overlap);
    let config = bench_config(config, threads, steps);
    let warmup = config.sac.warmup;
    let scratch = ScratchDir::new(&format!("{threads}-{}", u8::from(beside_busy_core)));
    let stop = AtomicBool::new(false);
    let mut start: Option<(u64, u64, PhaseTimes)> = None;
    let mut end: Option<(u64, u64, PhaseTimes)> = None;
    let burner = beside_busy_core.then(CoreBurner::start).transpose().map_err(BenchTrainError::Burner)?;
    let summary = train::train(&config, scratch.path(), false, &stop, &mut |p| {
        if p.step < warmup || end.is_some() {
            return;
        }
        match start {
            None => start = Some((p.step, p.updates, p.times)),
            Some((first, _, _)) if p.step >= first + steps => {
                end = Some((p.step, p.updates, p.times));
                stop.store(true, Ordering::SeqCst);
            }
            Some(_) => {}
        }
    })?;
    drop(burner);
    let (Some(start), Some(end)) = (start, end) else {
        return Err(BenchTrainError::TooShort { ended_at: summary.steps, steps });
    };
    Ok(TrainBench {
        threads,
        beside_busy_core,
        adaptive_threads,
        overlap,
        env_steps: end.0 - start.0,
        updates: end.1 - start.1,
        phases: phases_between(&start.2, &end.2),
    })
}
