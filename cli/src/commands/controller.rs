//! `vge controller`: one sub-skill controller alone on the simulated hand.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use vge_controllers::rollout::{self, ControllerKind, RolloutOptions};
use vge_sim::ObjectShape;

/// Roll out one sub-skill controller alone on the simulated hand.
///
/// IGM (in-grasp manipulation: contact-force QP + rotation), CS (contact switching: a
/// detach/re-attach trajectory of one finger) or FG (both). Prints mean return,
/// mean_rotation_rad (object rotation about z per episode), mean fingertip contacts,
/// drops (episodes ended early), the success rate and the controller's cost per call.
#[derive(Debug, Args)]
pub struct ControllerArgs {
    /// The controller: igm, cs or fg.
    #[arg(long, value_name = "igm|cs|fg", value_parser = parse_controller_kind)]
    kind: ControllerKind,
    /// The object in the hand: cube, sphere, cylinder, dodecahedron, icosahedron or
    /// hexagonal-prism.
    #[arg(long, default_value_t = ObjectShape::Cube)]
    object: ObjectShape,
    /// Episodes to roll out.
    #[arg(long, default_value_t = 10)]
    episodes: usize,
    /// Seed of the grasp, noise and perturbation draws (episode k uses seed + k).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Episode length in seconds of sim time [default: 10, or with --config the success
    /// test's `run.eval_episode_s`].
    #[arg(long)]
    episode_s: Option<f32>,
    /// Randomise the initial grasp per episode (pose noise, rad); 0 starts every
    /// episode from the same grasp [default: 0.02, or with --config the success test's
    /// `run.eval_grasp_noise_rad`].
    #[arg(long)]
    grasp_noise_rad: Option<f32>,
    /// Experiment config (TOML) whose [env] the controller runs in (object mass and friction,
    /// motors, hand orientation, finger collisions, grasp), as the success test runs it:
    /// without the training disturbances (sensor noise, pushes, randomisation, drop
    /// penalty); CS's trajectory is `vge.horizon` steps. `--object` replaces its object.
    #[arg(long)]
    config: Option<PathBuf>,
    /// The hand, without --config: a shipped hand (vge15, allegro) or an MJCF file. The
    /// object is the one its file is sized for.
    #[arg(long, default_value = "vge15", conflicts_with = "config")]
    hand: String,
    /// Override a config key, e.g. `--set env.object_mass_kg=0.4` (repeatable): of --config,
    /// or without it of the default config on --hand.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Print one JSON line instead of a summary.
    #[arg(long)]
    json: bool,
}

fn parse_controller_kind(s: &str) -> Result<ControllerKind, String> {
    s.parse().map_err(|_| format!("unknown controller `{s}` (one of: igm, cs, fg)"))
}

pub fn run(args: ControllerArgs) -> anyhow::Result<()> {
    let ControllerArgs {
        kind,
        object,
        episodes,
        seed,
        episode_s,
        grasp_noise_rad,
        config,
        hand,
        overrides,
        json,
    } = args;
    let mut options = RolloutOptions::default();
    let (mut default_episode_s, mut default_grasp_noise_rad) = (10.0, 0.02);
    let config = match &config {
        Some(path) => {
            let config = vge_run::config::load_config(path, &overrides)?;
            (default_episode_s, default_grasp_noise_rad) =
                (config.run.eval_episode_s, config.run.eval_grasp_noise_rad);
            config
        }
        // The default task on --hand (its own object), with the overrides over it: a --set
        // is never dropped for want of a file.
        None => {
            vge_sim::hands::load(&hand).with_context(|| format!("--hand {hand}"))?;
            let mut config = vge_run::config::Config::default();
            config.env.hand = hand;
            for assignment in &overrides {
                vge_run::config::apply_override(&mut config, assignment)?;
            }
            config.validate()?;
            config
        }
    };
    let env = vge_run::eval::without_training_disturbances(&config.env_config(0)?);
    options.cs = config.cs_config(&env);
    options.env = env;
    let episode_s = episode_s.unwrap_or(default_episode_s);
    let grasp_noise_rad = grasp_noise_rad.unwrap_or(default_grasp_noise_rad);
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
    anyhow::ensure!(grasp_noise_rad.is_finite() && grasp_noise_rad >= 0.0, "--grasp-noise-rad must be >= 0");
    options.env = vge_run::eval::success_test_env(&options.env, episode_s, grasp_noise_rad);
    let summary = rollout::run_with(kind, object, episodes, seed, &options, |i, e| {
        if !json {
            eprintln!(
                "episode {}/{episodes}: return {:.3}, rotation {:.3} rad, {:.2} contacts{}",
                i + 1,
                e.episode_return,
                e.rotation_rad,
                e.mean_contacts,
                if e.dropped { ", ended early" } else { "" }
            );
        }
    })?;
    if json {
        println!("{}", summary.to_json_line());
    } else {
        println!("{summary}");
    }
    Ok(())
}
