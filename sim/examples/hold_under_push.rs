//! How long a frozen grasp holds the cube under the robustness test's random forces (redrawn
//! with probability 0.1 per control step; each component N(0, f²), or of magnitude f in a
//! random direction): the limit of what a policy gains by holding still, on all five
//! fingertips or on the four or three a gait keeps while fingers are away, and how much a
//! firmer squeeze helps.
//!
//! Each grasp lifts the listed fingers (proximal flexion opened 0.4 rad over 8 steps), then
//! closes every other finger's proximal flexion by SQUEEZE rad over 8 steps, then holds the
//! targets still.
//!
//!   cargo run --release -p vge-sim --example hold_under_push [EPISODES] [SQUEEZE_RAD...]
use vge_sim::{Env, EnvConfig, PerturbationConfig};

/// vge15's joints (the default env's hand), three per finger.
const NUM_JOINTS: usize = 15;

/// Steps of each phase (lift, then squeeze); the targets are frozen afterwards.
const PHASE_STEPS: usize = 8;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let episodes: u64 = args.next().map_or(Ok(6), |a| a.parse())?;
    let squeezes: Vec<f32> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    let squeezes = if squeezes.is_empty() { vec![0.0, 0.2, 0.4] } else { squeezes };
    let weight_n = 1.4715_f32;
    // Fingers 0-4 (0: the thumb); none lifted keeps five fingertips, one four, two three.
    let lifted_sets: [&[usize]; 5] = [&[], &[2], &[0], &[1, 3], &[0, 2]];
    println!(
        "lifted fingers, squeeze (rad), force (N, std per axis or magnitude): episodes held 30 s, mean time held (s)"
    );
    for lifted in lifted_sets {
        for &squeeze_rad in &squeezes {
            for (fraction, magnitude) in [(0.5_f32, false), (1.0, false), (0.5, true), (1.0, true)] {
                let mut config = EnvConfig { episode_length_steps: 600, ..EnvConfig::default() };
                config.grasp.pose_noise_rad = 0.02;
                let force_n = fraction * weight_n;
                config.perturbation = PerturbationConfig { change_probability: 0.1, ..Default::default() };
                if magnitude {
                    config.perturbation.force_magnitude_n = force_n;
                } else {
                    config.perturbation.force_std_n = force_n;
                }
                let (mut held, mut steps_total) = (0, 0usize);
                for seed in 0..episodes {
                    let mut env = Env::new(config.clone())?;
                    env.reset(seed)?;
                    let mut steps = 0;
                    loop {
                        let mut action = [0.0_f32; NUM_JOINTS];
                        for finger in 0..NUM_JOINTS / 3 {
                            let proximal = 3 * finger + 1;
                            if steps < PHASE_STEPS && lifted.contains(&finger) {
                                action[proximal] = -0.05;
                            } else if (PHASE_STEPS..2 * PHASE_STEPS).contains(&steps)
                                && !lifted.contains(&finger)
                            {
                                action[proximal] = squeeze_rad / PHASE_STEPS as f32;
                            }
                        }
                        let r = env.step(&action)?;
                        steps += 1;
                        if r.terminated || r.truncated {
                            held += usize::from(!r.terminated);
                            break;
                        }
                    }
                    steps_total += steps;
                }
                println!(
                    "{lifted:?} {squeeze_rad:.2} {force_n:.2} {}: {held}/{episodes} {:.1}",
                    if magnitude { "magnitude" } else { "std" },
                    steps_total as f32 / episodes as f32 / config.control_hz
                );
            }
        }
    }
    Ok(())
}
