//! The cores a training run uses, fitted while it trains to the cores that other processes
//! leave idle, and how it splits them between libtorch's threads and the envs.
//!
//! libtorch's parallel regions end at a barrier that waits for every worker: when another
//! process keeps a core busy, the worker that shares that core runs only in the scheduler's
//! turns, and each of an update's hundreds of small regions waits for it. Two threads beside
//! one busy core then train several times slower than one thread (docs/training.md,
//! "Training speed"), and a thread count chosen once at the start cannot follow a machine
//! whose other jobs come and go. [`ThreadGovernor`] measures, every [`PERIOD`], how many cores
//! the machine's other processes kept busy (all the cores' busy time from `/proc/stat`, read
//! by [`vge_run::cpu_use`] as `vge bench cores` reads it, less this process's own CPU time)
//! and uses the idle rest, between 1 and the configured count.
//!
//! With two cores or more the envs can step on one of them while the updates run on the
//! others, or step on all of them between the updates. Which is faster depends on the
//! networks' width and the CPU (at 256 x 256 two-thread updates won, at 128 x 128 the overlap,
//! docs/results/time-to-gait/), so the governor times both ([`SchedulePick`]) and keeps the
//! faster, timing them again every [`REPICK`]. The loop's schedule makes both train the same
//! run bit for bit (crate::train, "Schedule"), so only the speed depends on the pick.

use std::sync::atomic::{AtomicU8, Ordering};
use std::time::{Duration, Instant};

use vge_run::cpu_use::Jiffies;

use crate::cpu_time::process_cpu_s;

/// The environment variable that keeps the thread count fixed at the configured one
/// (`VGE_FIXED_THREADS=1`), e.g. to measure what adapting gains.
pub const FIXED_THREADS_ENV: &str = "VGE_FIXED_THREADS";

/// The environment variable that keeps the envs stepping on rayon's pool between the
/// updates, never on a core of their own beside them (`VGE_SERIAL_LOOP=1`). The run's
/// results are the same either way.
pub const SERIAL_LOOP_ENV: &str = "VGE_SERIAL_LOOP";

/// Whether governors adapt: unset (0), yes (1), no (2).
static ADAPTING: AtomicU8 = AtomicU8::new(0);

/// How governors made from now on schedule the envs ([`Overlap`] as a number; 0: unset).
static OVERLAP: AtomicU8 = AtomicU8::new(0);

/// Turns adapting on or off for the governors made from now on in this process (`vge bench
/// train` measures both); without a call, [`FIXED_THREADS_ENV`] decides.
pub fn set_adapting(adapt: bool) {
    ADAPTING.store(if adapt { 1 } else { 2 }, Ordering::Relaxed);
}

/// Where the envs step when the loop has two cores or more.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overlap {
    /// Whichever of the two schedules the governor timed faster (training's default).
    Fastest,
    /// On a core of their own, beside the updates.
    Always,
    /// On every core, between the updates.
    Never,
}

/// Sets how the governors made from now on in this process schedule the envs (`vge bench
/// train` measures each); without a call, [`Overlap::Fastest`] unless [`SERIAL_LOOP_ENV`].
pub fn set_overlap(overlap: Overlap) {
    let code = match overlap {
        Overlap::Fastest => 1,
        Overlap::Always => 2,
        Overlap::Never => 3,
    };
    OVERLAP.store(code, Ordering::Relaxed);
}

/// An environment switch that is on when set to anything but empty or "0".
fn switched_on(name: &str) -> bool {
    std::env::var_os(name).is_some_and(|v| !v.is_empty() && v != "0")
}

fn adapting() -> bool {
    match ADAPTING.load(Ordering::Relaxed) {
        1 => true,
        2 => false,
        _ => !switched_on(FIXED_THREADS_ENV),
    }
}

fn overlap_setting() -> Overlap {
    match OVERLAP.load(Ordering::Relaxed) {
        1 => Overlap::Fastest,
        2 => Overlap::Always,
        3 => Overlap::Never,
        _ if switched_on(SERIAL_LOOP_ENV) => Overlap::Never,
        _ => Overlap::Fastest,
    }
}

/// Loop iterations timed per schedule when picking: a few hundred milliseconds each at
/// today's sizes, long against a thread switch, short against a run.
pub const PICK_ITERATIONS: u32 = 40;

/// How long a pick holds before both schedules are timed again (the machine's other work
/// and the run's phase, warm-up or updates, change what is faster).
pub const REPICK: Duration = Duration::from_secs(60);

/// Times the two schedules one after the other, [`PICK_ITERATIONS`] iterations each (the
/// first iteration after a switch not counted), and names the faster.
#[derive(Debug, Clone, PartialEq)]
pub struct SchedulePick {
    /// The schedule being timed: true, the envs beside the updates.
    pub overlap: bool,
    counted: u32,
    skip_next: bool,
    /// Mean seconds per iteration of the serial schedule, once timed.
    serial_s: Option<f64>,
    sum_s: f64,
}

impl SchedulePick {
    /// Starts timing with the serial schedule.
    pub fn start() -> Self {
        Self { overlap: false, counted: 0, skip_next: true, serial_s: None, sum_s: 0.0 }
    }

    /// Counts one iteration of the schedule being timed; returns the faster schedule (true:
    /// overlap) once both are timed.
    pub fn record(&mut self, iteration_s: f64) -> Option<bool> {
        if std::mem::take(&mut self.skip_next) {
            return None;
        }
        self.sum_s += iteration_s;
        self.counted += 1;
        if self.counted < PICK_ITERATIONS {
            return None;
        }
        let mean_s = self.sum_s / f64::from(self.counted);
        match self.serial_s {
            None => {
                *self =
                    Self { overlap: true, counted: 0, skip_next: true, serial_s: Some(mean_s), sum_s: 0.0 };
                None
            }
            Some(serial_s) => Some(mean_s < serial_s),
        }
    }
}

/// Where the governor stands on the envs' schedule.
#[derive(Debug, Clone, PartialEq)]
enum Schedule {
    /// Fewer than two cores, or no choice to make.
    Fixed(bool),
    Picking(SchedulePick),
    Picked {
        overlap: bool,
        at: Instant,
    },
}

/// How often the cores' use is measured: long enough for the kernel's 100 Hz counters to
/// resolve a tenth of a core, short against a run's minutes.
pub const PERIOD: Duration = Duration::from_secs(2);

/// One reading of the machine's counters.
#[derive(Debug, Clone, Copy)]
struct Reading {
    at: Instant,
    /// Busy and total jiffies summed over every core, and the number of cores.
    jiffies: Jiffies,
    /// This process's CPU time, all threads (s).
    own_cpu_s: f64,
}

/// The cores the loop uses, between 1 and `max_cores`, re-measured every [`PERIOD`] against
/// the machine's other work ([`Self::adapt`]), where the envs step with two or more, and
/// libtorch's thread count that follows from both.
#[derive(Debug)]
pub struct ThreadGovernor {
    max_cores: i32,
    cores: i32,
    adapts: bool,
    setting: Overlap,
    schedule: Schedule,
    last: Option<Reading>,
}

impl ThreadGovernor {
    /// Starts at libtorch's current thread count (what the run asked for: `sac.threads`), the
    /// most cores it will use; the first [`Self::adapt`] after a [`PERIOD`] corrects it. It
    /// never adapts when that is one, or where adapting is off ([`set_adapting`],
    /// [`FIXED_THREADS_ENV`]). Sets libtorch's threads ([`Self::libtorch_threads`]).
    pub fn start() -> Self {
        let asked = tch::get_num_threads().max(1);
        let mut governor = Self {
            max_cores: asked,
            cores: asked,
            adapts: asked > 1 && adapting(),
            setting: overlap_setting(),
            schedule: Schedule::Fixed(false),
            last: read(),
        };
        governor.schedule = governor.fresh_schedule();
        tch::set_num_threads(governor.libtorch_threads());
        governor
    }

    /// The schedule for the cores now: picked again from the start.
    fn fresh_schedule(&self) -> Schedule {
        match self.setting {
            _ if self.cores < 2 => Schedule::Fixed(false),
            Overlap::Always => Schedule::Fixed(true),
            Overlap::Never => Schedule::Fixed(false),
            Overlap::Fastest => Schedule::Picking(SchedulePick::start()),
        }
    }

    /// Whether the envs step on a core of their own beside the updates now.
    pub fn overlaps(&self) -> bool {
        match &self.schedule {
            Schedule::Fixed(overlap) | Schedule::Picked { overlap, .. } => *overlap,
            Schedule::Picking(pick) => pick.overlap,
        }
    }

    /// libtorch's threads: every core the loop uses, less the envs' own when they overlap.
    pub fn libtorch_threads(&self) -> i32 {
        if self.overlaps() { self.cores - 1 } else { self.cores }
    }

    /// Takes the wall time of one loop iteration with updates (the loop leaves out its
    /// warm-up): while picking, it times the schedule in force; a pick older than [`REPICK`]
    /// starts another.
    pub fn iteration_took(&mut self, iteration_s: f64) {
        let before = self.overlaps();
        match &mut self.schedule {
            Schedule::Fixed(_) => return,
            Schedule::Picking(pick) => {
                if let Some(overlap) = pick.record(iteration_s) {
                    self.schedule = Schedule::Picked { overlap, at: Instant::now() };
                }
            }
            Schedule::Picked { at, .. } => {
                if at.elapsed() >= REPICK {
                    self.schedule = Schedule::Picking(SchedulePick::start());
                }
            }
        }
        if self.overlaps() != before {
            tch::set_num_threads(self.libtorch_threads());
        }
    }

    /// Measures and sets the cores (and libtorch's threads) when a [`PERIOD`] has passed since
    /// the last measurement (else a clock read); returns the new count of cores when it
    /// changed. A change of cores picks the envs' schedule again.
    pub fn adapt(&mut self) -> Option<i32> {
        if !self.adapts {
            return None;
        }
        let due = self.last.is_none_or(|last| last.at.elapsed() >= PERIOD);
        if !due {
            return None;
        }
        let now = read()?;
        let fit = self.last.and_then(|last| threads_that_fit(&last, &now, self.max_cores));
        self.last = Some(now);
        let fit = fit?;
        if fit == self.cores {
            return None;
        }
        self.cores = fit;
        self.schedule = self.fresh_schedule();
        tch::set_num_threads(self.libtorch_threads());
        Some(fit)
    }
}

/// The cores other processes used between two readings, taken from the cores' busy time
/// less this process's own, and the threads that fit beside them (idle cores rounded half down, 1 to
/// `max_threads`). None when the counters did not advance.
fn threads_that_fit(before: &Reading, after: &Reading, max_threads: i32) -> Option<i32> {
    let wall_s = (after.at - before.at).as_secs_f64();
    let counted = after.jiffies.since(&before.jiffies)?;
    if wall_s <= 0.0 || after.jiffies.cores != before.jiffies.cores {
        return None;
    }
    let all_busy = counted.busy_cores()?;
    let cores = counted.cores as f64;
    let own = ((after.own_cpu_s - before.own_cpu_s) / wall_s).clamp(0.0, cores);
    let others = (all_busy - own).max(0.0);
    // Rounded half down: half a core of someone else's work already costs a thread.
    let idle = cores - others;
    Some((((idle + 0.5).ceil() - 1.0) as i32).clamp(1, max_threads))
}

/// The machine's counters now, over every core; None where the OS does not give them (a
/// governor that cannot measure keeps the thread count it has).
fn read() -> Option<Reading> {
    let jiffies = Jiffies::read(|_| true).ok()?;
    Some(Reading { at: Instant::now(), jiffies, own_cpu_s: process_cpu_s()? })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learner::{self, Batch, LearnerConfig, standard_normal};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// The actor's parameters after `updates` updates of the default learner (TD3, 256x256)
    /// on seeded batches, at `threads` libtorch threads.
    fn actor_after_updates(threads: i32, updates: usize) -> Vec<Vec<f32>> {
        tch::set_num_threads(threads);
        let config = LearnerConfig::for_hand(&vge_run::config::Config::default()).expect("default hand");
        let (obs, act) = (config.net.obs_dim, config.net.act_dim);
        let mut learner = learner::build_seeded(config, tch::Device::Cpu, 7).expect("learner");
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..updates {
            let batch = Batch::new(
                standard_normal(&mut rng, 256, obs),
                standard_normal(&mut rng, 256, act).tanh() * 0.05,
                standard_normal(&mut rng, 256, 1),
                standard_normal(&mut rng, 256, obs),
                standard_normal(&mut rng, 256, 1).gt(1.5).to_kind(tch::Kind::Float),
            );
            learner.update(&batch);
        }
        let mut named: Vec<(String, tch::Tensor)> = learner.actor_vs().variables().into_iter().collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        named.into_iter().map(|(_, t)| Vec::<f32>::try_from(t.flatten(0, -1)).expect("f32")).collect()
    }

    /// What lets the governor change the thread count mid-run and keep a seed's run the same
    /// bit for bit: at the update's sizes, libtorch's kernels split the work between threads
    /// without changing any sum's order.
    #[test]
    fn updates_compute_the_same_bits_at_one_and_two_threads() {
        let before = tch::get_num_threads();
        let one = actor_after_updates(1, 6);
        let two = actor_after_updates(2, 6);
        tch::set_num_threads(before);
        assert_eq!(one.len(), two.len());
        for (a, b) in one.iter().zip(&two) {
            assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()), "a parameter differs");
        }
    }

    fn reading(at: Instant, busy: u64, total: u64, own_cpu_s: f64) -> Reading {
        Reading { at, jiffies: Jiffies { busy, total, cores: 2 }, own_cpu_s }
    }

    #[test]
    fn another_process_on_one_of_two_cores_leaves_one_thread() {
        let t0 = Instant::now();
        let t1 = t0 + Duration::from_secs(2);
        // 2 s on 2 cores = 400 jiffies, all busy: 2 core-seconds of it this process's own
        // (two spinning threads) would leave room for two; 2 of another process's, for one.
        let before = reading(t0, 1000, 5000, 10.0);
        assert_eq!(threads_that_fit(&before, &reading(t1, 1400, 5400, 14.0), 2), Some(2));
        assert_eq!(threads_that_fit(&before, &reading(t1, 1400, 5400, 12.0), 2), Some(1));
        // Half a core of someone else's work already costs the second thread.
        assert_eq!(threads_that_fit(&before, &reading(t1, 1300, 5400, 12.0), 2), Some(1));
        assert_eq!(threads_that_fit(&before, &reading(t1, 1280, 5400, 12.0), 2), Some(2));
        // Never more than asked, never fewer than one.
        assert_eq!(threads_that_fit(&before, &reading(t1, 1000, 5400, 10.0), 1), Some(1));
        assert_eq!(threads_that_fit(&before, &reading(t1, 1400, 5400, 10.0), 2), Some(1));
        // Counters that did not advance say nothing.
        assert_eq!(threads_that_fit(&before, &reading(t1, 1000, 5000, 10.0), 2), None);
    }

    #[test]
    fn the_pick_times_serial_then_overlap_and_names_the_faster() {
        let mut pick = SchedulePick::start();
        assert!(!pick.overlap, "timing starts with the serial schedule");
        // The first iteration after a switch is not counted: a slow one changes nothing.
        assert_eq!(pick.record(9.0), None);
        for _ in 0..PICK_ITERATIONS - 1 {
            assert_eq!(pick.record(0.020), None);
        }
        assert_eq!(pick.record(0.020), None, "serial timed, overlap next");
        assert!(pick.overlap);
        assert_eq!(pick.record(9.0), None);
        for _ in 0..PICK_ITERATIONS - 1 {
            assert_eq!(pick.record(0.015), None);
        }
        assert_eq!(pick.record(0.015), Some(true));
        // The other way round: serial is faster.
        let mut pick = SchedulePick::start();
        let picked: Vec<Option<bool>> = (0..2 * (PICK_ITERATIONS + 1))
            .map(|k| pick.record(if k <= PICK_ITERATIONS { 0.010 } else { 0.012 }))
            .collect();
        assert_eq!(picked.last(), Some(&Some(false)));
        assert!(picked[..picked.len() - 1].iter().all(Option::is_none));
    }
}
