//! The learner's part of a run's memory: its replay buffer and networks, estimated from the
//! sizes that set them before anything is allocated. The run's other parts (envs, episodes,
//! evaluations) are vge-run's estimate ([`vge_run::config::Config::memory_estimate`]);
//! [`vge_run::config::Config::check_fits_memory`] bounds the two together.

use vge_run::config::Config;

/// The learner's largest allocations for `config`: (the keys that set them, bytes).
pub fn learner_memory_estimate(config: &Config) -> Result<Vec<(&'static str, u64)>, vge_sim::SimError> {
    let env = config.env_config(0)?;
    let (obs, act) = (env.observation_layout().dim() as u64, env.hand.num_joints() as u64);
    // A transition: obs, next obs, action, BC action, and 4 scalars, as f32.
    let replay = (config.sac.buffer_size as u64).saturating_mul((2 * obs + 2 * act + 4) * 4);
    // The actor and twin critics with their targets, Adam's moments and gradients (about
    // 12 copies of the parameters), and a minibatch's activations through them (about 24
    // f32 per unit and row: forward and backward passes of five networks).
    let widths: Vec<u64> = std::iter::once(obs + act)
        .chain(config.sac.hidden.iter().map(|&h| h.max(0) as u64))
        .chain(std::iter::once(act))
        .collect();
    let params = widths.windows(2).fold(0u64, |sum, w| sum.saturating_add(w[0].saturating_mul(w[1])));
    let units = widths.iter().fold(0u64, |sum, &w| sum.saturating_add(w));
    let nets = params
        .saturating_mul(12 * 4)
        .saturating_add((config.sac.batch as u64).saturating_mul(units).saturating_mul(24 * 4));
    Ok(vec![("sac.buffer_size", replay), ("sac.hidden, sac.batch", nets)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_replay_buffer_and_networks_grow_with_their_sizes_and_a_typo_is_refused() {
        let config = Config::default();
        let parts = learner_memory_estimate(&config).expect("estimate");
        assert_eq!(
            parts.iter().map(|(k, _)| *k).collect::<Vec<_>>(),
            ["sac.buffer_size", "sac.hidden, sac.batch"]
        );
        let mut bigger = config.clone();
        bigger.sac.buffer_size *= 2;
        bigger.sac.batch *= 2;
        let grown = learner_memory_estimate(&bigger).expect("estimate");
        assert_eq!(grown[0].1, 2 * parts[0].1);
        assert!(grown[1].1 > parts[1].1);
        // 10^12 transitions: refused whatever the machine, naming the key.
        bigger.sac.buffer_size = 1_000_000_000_000;
        let err = bigger
            .check_fits_memory(&learner_memory_estimate(&bigger).expect("estimate"))
            .expect_err("refused")
            .to_string();
        assert!(err.contains("sac.buffer_size") && err.contains("more than the 1.10 TB"), "{err}");
    }
}
