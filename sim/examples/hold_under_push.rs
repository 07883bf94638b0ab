//! How long the initial grasp holds the cube, with the finger targets frozen, under the
//! robustness test's random forces (each component N(0, f²), redrawn with probability 0.1
//! per control step): the limit of what a policy gains by holding still.
//!
//!   cargo run --release -p vge-sim --example hold_under_push [EPISODES]
use vge_sim::{Env, EnvConfig, NUM_JOINTS, PerturbationConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let episodes: u64 = std::env::args().nth(1).map_or(Ok(10), |a| a.parse())?;
    let weight_n = 1.4715_f32;
    println!("force std per axis (N), episodes held 30 s, mean time to drop (s)");
    for fraction in [0.0_f32, 0.25, 0.5, 0.75, 1.0] {
        let mut config = EnvConfig { episode_length_steps: 600, ..EnvConfig::default() };
        config.grasp.pose_noise_rad = 0.02;
        config.perturbation =
            PerturbationConfig { force_std_n: fraction * weight_n, change_probability: 0.1 };
        let (mut held, mut steps_total) = (0, 0usize);
        for seed in 0..episodes {
            let mut env = Env::new(config.clone())?;
            env.reset(seed)?;
            let mut steps = 0;
            loop {
                let r = env.step(&[0.0; NUM_JOINTS])?;
                steps += 1;
                if r.terminated || r.truncated {
                    held += usize::from(!r.terminated);
                    break;
                }
            }
            steps_total += steps;
        }
        println!(
            "{:.3} {held}/{episodes} {:.1}",
            fraction * weight_n,
            steps_total as f32 / episodes as f32 / config.control_hz
        );
    }
    Ok(())
}
