//! Everything of a run that is not a tensor: the loop's counters, its generator and metric
//! windows, saved as the checkpoint's `state.toml` and restored on resume.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::TrainError;
use super::clock::RunCost;
use super::metrics::Window;
use crate::behaviour::BehaviourStats;

/// The loop's counters (what [`TrainState`] saves besides the generator and the stats).
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Counters {
    pub step: u64,
    pub episodes: u64,
    /// Fractional updates owed (`utd` per env step).
    pub updates_due: f64,
    pub window: Window,
    /// The window of the last metrics row (what progress reports).
    pub last_window: Window,
}

/// `state.toml`. The behaviour statistics stay flat fields so that the file reads on its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct TrainState {
    step: u64,
    episodes: u64,
    updates_due: f64,
    rng_seed_hex: String,
    rng_stream: u64,
    rng_word_pos: String,
    config_hash: String,
    stats_steps: u64,
    stats_controller_steps: u64,
    stats_controller_queries: u64,
    stats_controller_no_action: u64,
    stats_selections: u64,
    stats_controller_selected: u64,
    stats_p_psi_sum: f64,
    window: Window,
    last_window: Window,
    pub has_replay: bool,
    /// Wall time of the sessions up to this checkpoint (s).
    #[serde(default)]
    pub wall_s: f64,
    /// CPU time of those sessions (s); absent from checkpoints of a vge that did not count
    /// it, and then unknown for the rest of the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_s: Option<f64>,
}

impl TrainState {
    pub fn capture(
        c: &Counters,
        rng: &ChaCha8Rng,
        config_hash: &str,
        s: &BehaviourStats,
        has_replay: bool,
        cost: RunCost,
    ) -> Self {
        let rng_seed_hex: String = rng.get_seed().iter().map(|b| format!("{b:02x}")).collect();
        Self {
            step: c.step,
            episodes: c.episodes,
            updates_due: c.updates_due,
            rng_seed_hex,
            rng_stream: rng.get_stream(),
            rng_word_pos: rng.get_word_pos().to_string(),
            config_hash: config_hash.to_owned(),
            stats_steps: s.steps,
            stats_controller_steps: s.controller_steps,
            stats_controller_queries: s.controller_queries,
            stats_controller_no_action: s.controller_no_action,
            stats_selections: s.selections,
            stats_controller_selected: s.controller_selected,
            stats_p_psi_sum: s.p_psi_sum,
            window: c.window.clone(),
            last_window: c.last_window.clone(),
            has_replay,
            wall_s: cost.wall_s,
            cpu_s: cost.cpu_s,
        }
    }

    /// What the sessions up to this checkpoint cost. Checkpoints of a vge that wrote neither
    /// field read as 0 s of wall time (as before) and unknown CPU time, which stays unknown
    /// for the rest of the run.
    pub fn cost(&self) -> RunCost {
        RunCost { wall_s: self.wall_s, cpu_s: self.cpu_s }
    }

    pub fn counters(&self) -> Counters {
        Counters {
            step: self.step,
            episodes: self.episodes,
            updates_due: self.updates_due,
            window: self.window.clone(),
            last_window: self.last_window.clone(),
        }
    }

    pub fn behaviour_stats(&self) -> BehaviourStats {
        BehaviourStats {
            steps: self.stats_steps,
            controller_steps: self.stats_controller_steps,
            controller_queries: self.stats_controller_queries,
            controller_no_action: self.stats_controller_no_action,
            selections: self.stats_selections,
            controller_selected: self.stats_controller_selected,
            p_psi_sum: self.stats_p_psi_sum,
        }
    }

    /// The run's generator exactly where the checkpoint left it.
    pub fn rng(&self) -> Result<ChaCha8Rng, TrainError> {
        let bad = || TrainError::Resume("corrupt generator state in state.toml".to_owned());
        if self.rng_seed_hex.len() != 64 {
            return Err(bad());
        }
        let mut seed = [0u8; 32];
        for (i, b) in seed.iter_mut().enumerate() {
            *b = self
                .rng_seed_hex
                .get(2 * i..2 * i + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(bad)?;
        }
        let mut rng = ChaCha8Rng::from_seed(seed);
        rng.set_stream(self.rng_stream);
        rng.set_word_pos(self.rng_word_pos.parse::<u128>().map_err(|_| bad())?);
        Ok(rng)
    }
}

#[cfg(test)]
mod tests {
    use rand::Rng;

    use super::*;

    #[test]
    fn the_generator_comes_back_where_it_was_and_corruption_is_refused() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let _ = rng.next_u64();
        let cost = RunCost { wall_s: 1.0, cpu_s: Some(0.5) };
        let state =
            TrainState::capture(&Counters::default(), &rng, "h", &BehaviourStats::default(), false, cost);
        let text = toml::to_string(&state).expect("serialises");
        let back: TrainState = toml::from_str(&text).expect("parses");
        assert_eq!(back.cost(), cost);
        // A checkpoint of a vge that did not count CPU time resumes with it unknown.
        let older: TrainState = toml::from_str(&text.replace("cpu_s = 0.5\n", "")).expect("parses");
        assert_eq!(older.cost(), RunCost { wall_s: 1.0, cpu_s: None });
        assert_eq!(back.rng().expect("restores").next_u64(), rng.next_u64());
        let mut bad = back.clone();
        bad.rng_seed_hex.replace_range(0..2, "zz");
        assert!(matches!(bad.rng(), Err(TrainError::Resume(_))));
        bad.rng_seed_hex = "é".repeat(32);
        assert!(bad.rng().is_err(), "non-ASCII must not panic on slicing");
    }
}
