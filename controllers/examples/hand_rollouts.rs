//! Rolls IGM, CS and FG out alone on a hand's start grasp and prints each rollout's figures
//! (rotation, drops, contact switches): how the controllers fare on a hand other than vge15.
//!
//! `cargo run --release -p vge-controllers --example hand_rollouts -- allegro 20 [steps]`
//! (a shipped hand's name or an MJCF path; episodes; steps per episode, default 400 = 20 s).

use std::process::ExitCode;

use vge_controllers::rollout::{self, ControllerKind, RolloutOptions};
use vge_controllers::{CsConfig, IgmConfig};
use vge_sim::{EnvConfig, ObjectShape};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let hand_name = args.first().map_or("allegro", String::as_str);
    let parse = |i: usize, default: usize| args.get(i).map_or(Ok(default), |s| s.parse::<usize>());
    let (Ok(episodes), Ok(steps)) = (parse(1, 20), parse(2, 400)) else {
        eprintln!("usage: hand_rollouts [HAND] [EPISODES] [STEPS]");
        return ExitCode::FAILURE;
    };
    let run = || -> Result<(), Box<dyn std::error::Error>> {
        let hand = vge_sim::hands::load(hand_name)?;
        let mut env = EnvConfig::for_hand(hand)?;
        env.episode_length_steps = steps;
        let cs = CsConfig::for_env(&env);
        let options = RolloutOptions { env, igm: IgmConfig::default(), cs };
        for kind in ControllerKind::ALL {
            let summary = rollout::run(kind, ObjectShape::Cube, episodes, 0, &options)?;
            println!("hand {hand_name}, {steps} steps per episode\n{summary}\n{}", summary.to_json_line());
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
