//! Throughput of the simulator, for `vge bench sim --json`.
//!
//! Both figures step the default task (grasp held, small deterministic pseudo-random
//! actions, automatic reset on termination or truncation, reset time included).
//!
//! The single-world figure is also given per second of the thread's own CPU time (Linux),
//! which other processes on the same core do not inflate: on a loaded machine the wall-clock
//! figure measures the machine's load as much as the simulator.

use std::time::Instant;

use rayon::prelude::*;

use crate::env::{Env, EnvConfig};
use crate::error::SimError;

/// What to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchSettings {
    /// Environment configuration (rates, object, ...).
    pub env: EnvConfig,
    /// Control steps timed per world.
    pub steps_per_world: usize,
    /// Worlds in the vectorized run.
    pub num_worlds: usize,
    /// Threads of the vectorized run (0: all cores).
    pub threads: usize,
}

impl Default for BenchSettings {
    fn default() -> Self {
        Self { env: EnvConfig::default(), steps_per_world: 2_000, num_worlds: 8, threads: 0 }
    }
}

/// Measured figures.
#[derive(Debug, Clone, PartialEq)]
pub struct SimBench {
    /// Settings used.
    pub settings: BenchSettings,
    /// Threads actually used by the vectorized run.
    pub threads_used: usize,
    /// Control steps per second, one world on one thread.
    pub control_steps_per_s_single: f64,
    /// Control steps per second of the thread's CPU time, one world (None where the OS does
    /// not say: [`thread_cpu_s`]).
    pub control_steps_per_cpu_s_single: Option<f64>,
    /// Control steps per second summed over all worlds, on `threads_used` threads.
    pub control_steps_per_s_vec: f64,
    /// Physics steps per second, one world.
    pub physics_steps_per_s_single: f64,
    /// Resets during the single-world run (drops and time limits).
    pub resets_single: usize,
    /// Drops (terminations) during the single-world run: with `resets_single` and
    /// `mean_tip_contacts_single`, whether the grasp held, to set beside another simulator's.
    pub drops_single: usize,
    /// Fingertips touching the object, averaged over the single-world run's control steps.
    pub mean_tip_contacts_single: f64,
}

impl SimBench {
    /// `control_steps_per_s_vec / control_steps_per_s_single`.
    #[must_use]
    pub fn speedup(&self) -> f64 {
        self.control_steps_per_s_vec / self.control_steps_per_s_single
    }

    /// Simulated seconds per wall-clock second, one world on one thread (control steps over
    /// the control rate): the figure to compare with another simulator at another rate.
    #[must_use]
    pub fn sim_seconds_per_s(&self) -> f64 {
        self.control_steps_per_s_single / f64::from(self.settings.env.control_hz)
    }

    /// One JSON line with the figures and the settings.
    #[must_use]
    pub fn to_json_line(&self) -> String {
        let e = &self.settings.env;
        serde_json::json!({
            "bench": "sim",
            "control_steps_per_s_single": self.control_steps_per_s_single,
            "control_steps_per_s_vec": self.control_steps_per_s_vec,
            "control_steps_per_cpu_s_single": self.control_steps_per_cpu_s_single,
            "sim_seconds_per_cpu_s": self.control_steps_per_cpu_s_single.map(|c| c / f64::from(e.control_hz)),
            "speedup": self.speedup(),
            "sim_seconds_per_s": self.sim_seconds_per_s(),
            "sim_seconds_per_s_vec": self.control_steps_per_s_vec / f64::from(e.control_hz),
            "physics_steps_per_s_single": self.physics_steps_per_s_single,
            "resets_single": self.resets_single,
            "drops_single": self.drops_single,
            "mean_tip_contacts": self.mean_tip_contacts_single,
            "num_worlds": self.settings.num_worlds,
            "threads": self.threads_used,
            "steps_per_world": self.settings.steps_per_world,
            "control_hz": e.control_hz,
            "physics_hz": e.physics.physics_hz,
            "solver_iterations": e.physics.solver_iterations,
            "physics_steps_per_control": e.physics_steps_per_control(),
            "object": e.object.shape.name(),
        })
        .to_string()
    }
}

/// Time this thread has spent on a CPU (s), from `CLOCK_THREAD_CPUTIME_ID` (Linux); `None`
/// elsewhere. Not `/proc/thread-self/schedstat`: that figure lags the running time slice by up
/// to a scheduler tick, which a short bench would read as CPU time it never spent.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
#[must_use]
pub fn thread_cpu_s() -> Option<f64> {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec through a valid pointer to a local.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    (rc == 0).then_some(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9)
}

/// Time this thread has spent on a CPU (s): not measured outside Linux.
#[cfg(not(target_os = "linux"))]
#[must_use]
pub fn thread_cpu_s() -> Option<f64> {
    None
}

/// Deterministic small action for step `k` of world `w` (a SplitMix-style hash).
fn action(w: usize, k: usize, joints: usize, max: f32) -> Vec<f32> {
    (0..joints)
        .map(|j| {
            let mut x = (w as u64) << 40 ^ (k as u64) << 8 ^ j as u64;
            x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
            x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            x ^= x >> 31;
            let u = (x >> 40) as f32 / (1u64 << 24) as f32;
            0.2 * max * (2.0 * u - 1.0)
        })
        .collect()
}

/// The first world's actions for `steps` control steps at `max_action_rad`, as rows of
/// `joints` little-endian f32: the table the Python loops that are timed against this
/// bench (scripts/bench_mujoco.py, python/examples/bench_loop.py) replay, written here so that
/// no second copy of the hash has to agree with this one.
#[must_use]
pub fn first_world_actions_f32_le(steps: usize, joints: usize, max_action_rad: f32) -> Vec<u8> {
    (0..steps).flat_map(|k| action(0, k, joints, max_action_rad)).flat_map(f32::to_le_bytes).collect()
}

/// How the grasp fared over a [`drive`].
#[derive(Debug, Clone, Copy, Default)]
struct Held {
    resets: usize,
    drops: usize,
    tip_contacts: usize,
}

/// Runs `steps` control steps on `env`, resetting when an episode ends.
fn drive(env: &mut Env, w: usize, steps: usize) -> Result<Held, SimError> {
    let max = env.config().max_action_rad;
    let joints = env.config().hand.num_joints();
    let mut held = Held::default();
    let mut seed = w as u64 * 1_000_003;
    env.reset(seed)?;
    for k in 0..steps {
        let r = env.step(&action(w, k, joints, max))?;
        held.tip_contacts += r.info.num_tip_contacts;
        if r.terminated || r.truncated {
            seed += 1;
            held.resets += 1;
            held.drops += usize::from(r.terminated);
            env.reset(seed)?;
        }
    }
    Ok(held)
}

/// Measures one world on the calling thread, then `num_worlds` worlds across a rayon pool.
pub fn run(settings: &BenchSettings) -> Result<SimBench, SimError> {
    settings.env.validate()?;
    if settings.num_worlds == 0 || settings.steps_per_world == 0 {
        return Err(SimError::InvalidConfig("bench needs worlds and steps".to_owned()));
    }
    let mut env = Env::new(settings.env.clone())?;
    drive(&mut env, 0, 20)?; // warm-up
    let cpu_before = thread_cpu_s();
    let t = Instant::now();
    let held = drive(&mut env, 0, settings.steps_per_world)?;
    let single_s = t.elapsed().as_secs_f64();
    let cpu_s = thread_cpu_s().zip(cpu_before).map(|(after, before)| after - before).filter(|s| *s > 0.0);
    let control_steps_per_s_single = settings.steps_per_world as f64 / single_s;

    let mut builder = rayon::ThreadPoolBuilder::new();
    if settings.threads > 0 {
        builder = builder.num_threads(settings.threads);
    }
    let pool = builder.build().map_err(|e| SimError::InvalidConfig(format!("thread pool: {e}")))?;
    let threads_used = pool.current_num_threads();
    let mut envs =
        (0..settings.num_worlds).map(|_| Env::new(settings.env.clone())).collect::<Result<Vec<_>, _>>()?;
    let t = Instant::now();
    pool.install(|| {
        envs.par_iter_mut()
            .enumerate()
            .map(|(w, env)| drive(env, w, settings.steps_per_world).map(|_| ()))
            .collect::<Result<Vec<()>, _>>()
    })?;
    let vec_s = t.elapsed().as_secs_f64();
    let control_steps_per_s_vec = (settings.num_worlds * settings.steps_per_world) as f64 / vec_s;
    Ok(SimBench {
        settings: settings.clone(),
        threads_used,
        control_steps_per_s_single,
        control_steps_per_cpu_s_single: cpu_s.map(|s| settings.steps_per_world as f64 / s),
        control_steps_per_s_vec,
        physics_steps_per_s_single: control_steps_per_s_single
            * settings.env.physics_steps_per_control() as f64,
        resets_single: held.resets,
        drops_single: held.drops,
        mean_tip_contacts_single: held.tip_contacts as f64 / settings.steps_per_world as f64,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_written_action_table_is_the_first_worlds_actions_row_by_row() {
        let max = EnvConfig::default().max_action_rad;
        let joints = 15;
        let bytes = first_world_actions_f32_le(3, joints, max);
        assert_eq!(bytes.len(), 3 * joints * 4);
        let floats: Vec<f32> =
            bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        for (k, row) in floats.chunks_exact(joints).enumerate() {
            assert_eq!(row, action(0, k, joints, max), "row {k}");
            assert!(row.iter().all(|a| a.abs() <= 0.2 * max), "row {k}: {row:?}");
        }
        // Rows differ: the table is not one action repeated.
        assert_ne!(floats[..joints], floats[joints..2 * joints]);
    }

    #[test]
    fn a_short_run_reports_simulated_seconds_per_second_at_its_control_rate() {
        // Not the default 20 Hz; a divisor of the 120 Hz physics rate.
        let env = EnvConfig { control_hz: 30.0, ..EnvConfig::default() };
        let settings = BenchSettings { env, steps_per_world: 20, num_worlds: 2, threads: 1 };
        let r = run(&settings).unwrap();
        assert!(r.control_steps_per_s_single > 0.0);
        assert!((r.sim_seconds_per_s() * 30.0 - r.control_steps_per_s_single).abs() < 1e-9);
        let json: serde_json::Value = serde_json::from_str(&r.to_json_line()).unwrap();
        assert_eq!(json["sim_seconds_per_s"].as_f64(), Some(r.sim_seconds_per_s()));
        assert_eq!(json["control_hz"].as_f64(), Some(30.0));
        assert!(json["sim_seconds_per_s_vec"].as_f64().unwrap() > 0.0);
        // The grasp holds through the short walk: no drop, most fingertips on the cube.
        assert_eq!(r.drops_single, 0);
        assert!(r.drops_single <= r.resets_single);
        assert!(r.mean_tip_contacts_single >= 3.0, "{} fingertips", r.mean_tip_contacts_single);
        assert_eq!(json["mean_tip_contacts"].as_f64(), Some(r.mean_tip_contacts_single));
        // Linux says how much CPU time the walk took (no timing asserted: a loaded machine
        // may stretch either clock).
        if cfg!(target_os = "linux") {
            let cpu = r.control_steps_per_cpu_s_single.expect("Linux reports thread CPU time");
            assert!(cpu.is_finite() && cpu > 0.0, "{cpu} per CPU s");
            assert_eq!(json["control_steps_per_cpu_s_single"].as_f64(), Some(cpu));
        }
    }
}
