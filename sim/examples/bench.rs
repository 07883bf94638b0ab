//! The simulator's speed and grasp under physics settings that `vge bench sim` does not take:
//!
//! `cargo run --release -p vge-sim --example bench -- [--hand HAND] [--steps N] [--rounds R]
//! [--push-n F] [--sweep | control_hz physics_hz iterations prediction_m]`
//!
//! One world on one thread per setting, the bench's pseudo-random target walk
//! (`vge_sim::bench`); one JSON line per setting and round with its speed and how the grasp
//! held (drops, mean fingertips on the object). `--sweep` runs the default physics and the
//! variants below, alternating them round by round so that a loaded machine slows them alike;
//! the figures measure settings before any is adopted (the default is not changed here).
//! `--push-n F` adds the robustness test's pushes to the walk (a force of F newtons in a random
//! direction, redrawn with probability 0.1 per control step), under which a weaker grasp drops.

use vge_sim::bench::{BenchSettings, run};
use vge_sim::{EnvConfig, PerturbationConfig, PhysicsConfig};

/// A physics variant: its name and how it changes the default.
type Variant = (&'static str, fn(&mut EnvConfig));

const VARIANTS: [Variant; 8] = [
    ("default (120 Hz x 4)", |_| {}),
    ("120 Hz x 3 iterations", |e| e.physics.solver_iterations = 3),
    ("120 Hz x 2 iterations", |e| e.physics.solver_iterations = 2),
    ("60 Hz x 8 iterations", |e| set_rate(e, 60.0, 8)),
    ("60 Hz x 4 iterations", |e| set_rate(e, 60.0, 4)),
    ("240 Hz x 2 iterations", |e| set_rate(e, 240.0, 2)),
    ("prediction 2 mm", |e| e.physics.contact_prediction_distance_m = 0.002),
    ("prediction 1 mm", |e| e.physics.contact_prediction_distance_m = 0.001),
];

fn set_rate(env: &mut EnvConfig, physics_hz: f32, iterations: usize) {
    env.physics = PhysicsConfig { physics_hz, solver_iterations: iterations, ..env.physics };
}

fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let (mut hand, mut steps, mut rounds, mut sweep, mut numbers) =
        ("vge15".to_owned(), 2_000, 1, false, vec![]);
    let mut push_n = 0.0f32;
    while let Some(a) = args.next() {
        let mut value = |what: &str| args.next().ok_or(format!("{what} needs a value"));
        match a.as_str() {
            "--hand" => hand = value("--hand")?,
            "--steps" => steps = value("--steps")?.parse().map_err(|e| format!("--steps: {e}"))?,
            "--rounds" => rounds = value("--rounds")?.parse().map_err(|e| format!("--rounds: {e}"))?,
            "--push-n" => push_n = value("--push-n")?.parse().map_err(|e| format!("--push-n: {e}"))?,
            "--sweep" => sweep = true,
            n => numbers.push(n.parse::<f32>().map_err(|e| format!("{n}: {e}"))?),
        }
    }
    let mut base = EnvConfig::for_hand(vge_sim::hands::load(&hand).map_err(|e| e.to_string())?)
        .map_err(|e| e.to_string())?;
    if push_n > 0.0 {
        base.perturbation =
            PerturbationConfig { force_magnitude_n: push_n, change_probability: 0.1, ..Default::default() };
    }
    let variants: Vec<(String, EnvConfig)> = if sweep {
        VARIANTS
            .iter()
            .map(|(name, change)| {
                let mut env = base.clone();
                change(&mut env);
                ((*name).to_owned(), env)
            })
            .collect()
    } else if let [c, p, it, pd] = numbers[..] {
        let mut env = base.clone();
        env.control_hz = c;
        set_rate(&mut env, p, it as usize);
        env.physics.contact_prediction_distance_m = pd;
        vec![("given".to_owned(), env)]
    } else {
        vec![("default".to_owned(), base.clone())]
    };
    for round in 1..=rounds {
        for (name, env) in &variants {
            let prediction_m = env.physics.contact_prediction_distance_m;
            let settings =
                BenchSettings { env: env.clone(), steps_per_world: steps, num_worlds: 1, threads: 1 };
            let line = match run(&settings) {
                Ok(b) => {
                    let mut json: serde_json::Value =
                        serde_json::from_str(&b.to_json_line()).map_err(|e| e.to_string())?;
                    json["hand"] = hand.clone().into();
                    json["variant"] = name.clone().into();
                    json["round"] = round.into();
                    json["contact_prediction_distance_m"] = prediction_m.into();
                    json["push_n"] = push_n.into();
                    json.to_string()
                }
                Err(e) => {
                    serde_json::json!({"hand": hand, "variant": name, "error": e.to_string()}).to_string()
                }
            };
            println!("{line}");
        }
    }
    Ok(())
}
