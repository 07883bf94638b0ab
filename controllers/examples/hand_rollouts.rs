//! Rolls IGM, CS and FG out alone on a hand's start grasp and prints each rollout's figures
//! (rotation, drops, contact switches): how the controllers fare on a hand other than vge15.
//! First the same episodes with zero action, the baseline a controller's drops compare with.
//!
//! `cargo run --release -p vge-controllers --example hand_rollouts -- allegro 20 [STEPS] [NOISE]`
//! (a shipped hand's name or an MJCF path; episodes; steps per episode, default 400 = 20 s;
//! the grasp's pose noise in rad, default 0.02 as the controllers' tests use, so that the
//! episodes differ: without it every IGM episode from a hand's start grasp is the same).

use std::process::ExitCode;

use vge_controllers::rollout::{self, ControllerKind, RolloutOptions};
use vge_controllers::{Controller, ControllerError, ControllerInput, CsConfig, IgmConfig};
use vge_sim::{Env, EnvConfig, ObjectShape};

/// Holds the targets where they are.
#[derive(Debug)]
struct ZeroAction;

impl Controller for ZeroAction {
    fn name(&self) -> &'static str {
        "zero"
    }

    fn reset(&mut self, _rng: &mut dyn rand::Rng) {}

    fn act(
        &mut self,
        input: &ControllerInput,
        _rng: &mut dyn rand::Rng,
    ) -> Result<Vec<f32>, ControllerError> {
        Ok(vec![0.0; input.q_rad.len()])
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let hand_name = args.first().map_or("allegro", String::as_str);
    let parse = |i: usize, default: usize| args.get(i).map_or(Ok(default), |s| s.parse::<usize>());
    let noise = args.get(3).map_or(Ok(0.02), |s| s.parse::<f32>());
    let (Ok(episodes), Ok(steps), Ok(noise)) = (parse(1, 20), parse(2, 400), noise) else {
        eprintln!("usage: hand_rollouts [HAND] [EPISODES] [STEPS] [POSE_NOISE_RAD]");
        return ExitCode::FAILURE;
    };
    let run = || -> Result<(), Box<dyn std::error::Error>> {
        let hand = vge_sim::hands::load(hand_name)?;
        let mut env = EnvConfig::for_hand(hand)?;
        env.episode_length_steps = steps;
        env.grasp.pose_noise_rad = noise;
        let cs = CsConfig::for_env(&env);
        let mut hold = Env::new(env.clone())?;
        let (mut drops, mut rotation_rad) = (0, 0.0);
        for i in 0..episodes {
            let stats = rollout::run_episode(&mut hold, &mut ZeroAction, i as u64, |_, _| {})?;
            drops += usize::from(stats.dropped);
            rotation_rad += stats.rotation_rad / episodes as f32;
        }
        println!(
            "hand {hand_name}, zero action: drops {drops} of {episodes}, mean rotation about z {rotation_rad:.3} rad"
        );
        let options = RolloutOptions { env, igm: IgmConfig::default(), cs };
        for kind in ControllerKind::ALL {
            let summary = rollout::run(kind, ObjectShape::Cube, episodes, 0, &options)?;
            println!(
                "hand {hand_name}, {steps} steps per episode, grasp pose noise {noise} rad\n{summary}\n{}",
                summary.to_json_line()
            );
        }
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hand_rollouts: {e}");
            ExitCode::FAILURE
        }
    }
}
