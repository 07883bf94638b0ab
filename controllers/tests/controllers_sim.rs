//! The controllers on the real simulator (rapier world, clarabel QP), seeded: IGM turns the
//! cube, CS breaks and remakes a contact, FG does both; on vge15 (five fingers of three
//! joints) and on the Allegro (four of four). Short episodes keep the suite fast.

use std::sync::Arc;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vge_controllers::rollout::{self, ControllerKind, RolloutOptions, run_episode};
use vge_controllers::{
    Controller, ControllerInput, CsConfig, CsController, FgController, IgmConfig, IgmController,
};
use vge_hand::Hand;
use vge_sim::{Env, EnvConfig, ObjectShape};

/// The default env (vge15) with a little grasp-pose noise so that seeds differ.
fn env_config(steps: usize) -> EnvConfig {
    let mut c = EnvConfig { episode_length_steps: steps, ..EnvConfig::default() };
    c.grasp.pose_noise_rad = 0.02;
    c
}

fn allegro() -> Arc<Hand> {
    vge_sim::hands::load("allegro").expect("the shipped Allegro")
}

/// The Allegro's env: its start grasp on its 65 mm cube, with the same grasp-pose noise.
fn allegro_config(steps: usize) -> EnvConfig {
    let mut c = EnvConfig::for_hand(allegro()).expect("the Allegro has a servo on every joint");
    c.episode_length_steps = steps;
    c.grasp.pose_noise_rad = 0.02;
    c
}

/// One IGM episode: (rotation, fewest contacts, dropped).
fn igm_run(env_config: EnvConfig, config: IgmConfig, seed: u64) -> (f32, usize, bool) {
    let mut env = Env::new(env_config).expect("env");
    let mut igm = IgmController::new(Arc::clone(&env.config().hand), config);
    let mut min_contacts = usize::MAX;
    let stats = run_episode(&mut env, &mut igm, seed, |t, _| min_contacts = min_contacts.min(t.contacts))
        .expect("episode");
    assert_eq!(stats.no_action_steps, 0, "IGM had no action on some steps");
    (stats.rotation_rad, min_contacts, stats.dropped)
}

#[test]
fn igm_turns_the_cube_both_ways_within_three_seconds() {
    let steps = 60; // 3 s at 20 Hz
    for seed in 0..3 {
        for (sign, config) in [(1.0f32, IgmConfig::default()), (-1.0, IgmConfig::default().reversed())] {
            let (rotation, min_contacts, dropped) = igm_run(env_config(steps), config, seed);
            println!("IGM seed {seed} do {sign:+}: rotation {rotation:+.3} rad, min contacts {min_contacts}");
            assert!(!dropped, "seed {seed}: dropped");
            assert!(min_contacts >= 3, "seed {seed}: {min_contacts} contacts");
            assert!(sign * rotation > 0.2, "seed {seed} sign {sign}: rotation {rotation}");
        }
    }
}

/// One switching trajectory of CS on seed `seed`, then `hold` steps of zero action.
struct CsTrial {
    /// The switching finger's contact broke at some step.
    broke: bool,
    /// It broke and touched again at the end.
    remade: bool,
    /// The env did not terminate (no drop).
    alive: bool,
    /// Fewest contacts of the other fingers while the switching finger was off.
    others_min_while_off: usize,
    /// Contacts per step.
    counts: Vec<usize>,
    finger: usize,
}

impl CsTrial {
    fn succeeded(&self) -> bool {
        self.broke && self.remade && self.alive
    }
}

/// `None` when CS cannot start on the grasp the reset made (too few contacts).
fn cs_trial(env_config: EnvConfig, config: CsConfig, seed: u64, hold: usize) -> Option<CsTrial> {
    let steps = config.horizon_steps + hold;
    let mut env = Env::new(EnvConfig { episode_length_steps: steps, ..env_config }).expect("env");
    env.reset(seed).expect("reset");
    let joints = env.config().hand.num_joints();
    let mut cs = CsController::new(Arc::clone(&env.config().hand), config);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    cs.reset(&mut rng);
    let input = ControllerInput::from_privileged(env.privileged().expect("state"));
    let first = cs.act(&input, &mut rng).ok()?;
    let finger = cs.switching_finger().expect("a finger was chosen");
    let mut t = CsTrial {
        broke: false,
        remade: false,
        alive: true,
        others_min_while_off: usize::MAX,
        counts: vec![],
        finger,
    };
    let mut in_contact_now = false;
    for step in 0..steps {
        let action = if step == 0 {
            first.clone()
        } else if step < config.horizon_steps {
            let input = ControllerInput::from_privileged(env.privileged().expect("state"));
            cs.act(&input, &mut rng).expect("CS follows its trajectory")
        } else {
            vec![0.0; joints]
        };
        assert_eq!(action.len(), joints);
        let r = env.step(&action).expect("step");
        in_contact_now = r.info.tip_contacts[finger];
        t.broke |= !in_contact_now;
        if !in_contact_now {
            t.others_min_while_off = t.others_min_while_off.min(r.info.num_tip_contacts);
        }
        t.counts.push(r.info.num_tip_contacts);
        if r.terminated {
            t.alive = false;
            break;
        }
    }
    t.remade = t.broke && in_contact_now;
    Some(t)
}

#[test]
fn cs_breaks_and_remakes_one_contact_in_most_trials() {
    let config = CsConfig::for_env(&env_config(1));
    let mut ok = 0;
    for seed in 0..20 {
        let t = cs_trial(env_config(1), config, seed, 5).expect("CS acts on a five-finger grasp");
        ok += usize::from(t.succeeded());
        println!(
            "CS seed {seed} finger {}: broke {} remade {} held {} contacts {:?}",
            t.finger, t.broke, t.remade, t.alive, t.counts
        );
    }
    println!("CS: {ok}/20 switches succeeded");
    assert!(ok >= 16, "only {ok}/20 switches succeeded");
}

// ---------------------------------------------------------------- vge15's CS as it was

/// CS as it was written for the 15-joint hand before hands were files: joint `3 f + j`,
/// the fixed `[roll, flex_prox, flex_dist]` profile (detach `[v_r, -v_f, 0]`, attach
/// `[0, v_f, 0]`), every finger in contact a candidate, roll limits +-0.5 rad and flexion
/// -0.3..1.6 rad. The reference the derived profile must equal on vge15, bit for bit.
struct Vge15CsAsBefore {
    config: CsConfig,
    plan: Option<(usize, f32, f32, usize)>,
}

impl Vge15CsAsBefore {
    fn act(&mut self, input: &ControllerInput, rng: &mut dyn rand::Rng) -> Option<Vec<f32>> {
        let c = self.config;
        let (finger, roll_v, flex, h) = match self.plan {
            Some(p) => p,
            None => {
                let in_contact = input.fingers_in_contact();
                if in_contact.len() < c.min_remaining_contacts + 1 {
                    return None;
                }
                let finger = in_contact[rng.random_range(0..in_contact.len())];
                let roll_speed = rng.random_range(c.speed_min_rad_s..=c.speed_max_rad_s);
                let flex_speed = rng.random_range(c.speed_min_rad_s..=c.speed_max_rad_s);
                let roll = input.q_target_rad[3 * finger];
                let sign = if roll.abs() > 0.05 {
                    -roll.signum()
                } else if rng.random_bool(0.5) {
                    1.0
                } else {
                    -1.0
                };
                (finger, sign * roll_speed, flex_speed, 0)
            }
        };
        let open = ((c.open_fraction * c.horizon_steps as f32).round() as usize).clamp(1, c.horizon_steps);
        let v = if h < open { [roll_v, -flex, 0.0] } else { [0.0, flex, 0.0] };
        let mut delta = [0.0f32; 15];
        for (j, vj) in v.iter().enumerate() {
            delta[3 * finger + j] = vj * c.control_period_s;
        }
        self.plan = (h + 1 < c.horizon_steps).then_some((finger, roll_v, flex, h + 1));
        Some(
            (0..15)
                .map(|j| {
                    let (lo, hi) = if j % 3 == 0 { (-0.5f32, 0.5f32) } else { (-0.3, 1.6) };
                    let t = input.q_target_rad[j];
                    (t + delta[j]).clamp(lo.min(t), hi.max(t)) - t
                })
                .collect(),
        )
    }
}

#[test]
fn vge15_cs_actions_are_those_of_the_fixed_profile_bit_for_bit() {
    let hand = vge_sim::hands::vge15().expect("vge15");
    let names = ["roll", "flex_prox", "flex_dist"];
    for (f, finger) in hand.fingers().iter().enumerate() {
        for (j, name) in names.iter().enumerate() {
            assert_eq!(hand.joints()[3 * f + j].name, format!("{}.{name}", finger.name));
        }
    }
    // Long episodes, so that switches that fail and leave four contacts are included.
    let steps = 300;
    let mut compared = 0usize;
    for seed in 0..6 {
        let mut env = Env::new(env_config(steps)).expect("env");
        env.reset(seed).expect("reset");
        let config = CsConfig::for_env(env.config());
        let mut cs = CsController::new(Arc::clone(&hand), config);
        let mut before = Vge15CsAsBefore { config, plan: None };
        let mut rng_new = ChaCha8Rng::seed_from_u64(seed);
        let mut rng_old = ChaCha8Rng::seed_from_u64(seed);
        for _ in 0..steps {
            let input = ControllerInput::from_privileged(env.privileged().expect("state"));
            let new = cs.act(&input, &mut rng_new).ok();
            let old = before.act(&input, &mut rng_old);
            let bits =
                |a: &Option<Vec<f32>>| a.as_ref().map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
            assert_eq!(bits(&new), bits(&old), "seed {seed} step {compared}");
            compared += 1;
            let r = env.step(&new.unwrap_or_else(|| vec![0.0; 15])).expect("step");
            if r.terminated {
                break;
            }
        }
    }
    println!("{compared} CS actions equal to the fixed profile's, bit for bit");
}

/// FG's figures, reported. FG is not drop-free on the env; with the tuned IGM and CS it
/// dropped the cube in 7 of 10 seeded 5 s episodes (4 of them within 2 s), so this test
/// asserts what holds (it turns the cube the right way on average while it switches
/// contacts, and drops it in at most half the episodes) and prints the drops.
#[test]
fn fg_turns_the_cube_while_it_switches_contacts_and_drops_it_in_at_most_half_the_episodes() {
    // FG = IGM + CS: IGM turns the object about +z while CS takes one finger off and puts
    // it back (a detach and re-attach per H = 50 steps). 6 s episodes from noisy grasps.
    let options = RolloutOptions { env: env_config(120), ..RolloutOptions::default() };
    let summary = rollout::run(ControllerKind::Fg, ObjectShape::Cube, 4, 0, &options).expect("rollout");
    println!("{summary}");
    // FG alone is not robust (the paper's point: the learner must do better); it may drop
    // the cube now and then, not mostly.
    assert!(summary.drops * 2 <= summary.episodes, "{summary}");
    assert!(summary.mean_contacts >= 3.0, "{summary}");
    assert!(summary.mean_rotation_rad > 0.05, "turns the cube the right way: {summary}");
    assert!(summary.mean_contact_switches >= 1.0, "completes contact switches: {summary}");
}

#[test]
fn rollout_summaries_and_cost_per_call() {
    let options = RolloutOptions { env: env_config(40), ..RolloutOptions::default() }; // 2 s
    for kind in ControllerKind::ALL {
        let s = rollout::run(kind, ObjectShape::Cube, 2, 7, &options).expect("rollout");
        println!("{}", s.to_json_line());
        assert_eq!(s.episodes, 2);
        assert!(s.controller_median_us.is_finite() && s.controller_median_us > 0.0);
        let line = s.to_json_line();
        for key in [
            "\"mean_return\":",
            "\"mean_rotation_rad\":",
            "\"mean_contacts\":",
            "\"drops\":",
            "\"success_rate\":",
        ] {
            assert!(line.contains(key), "{line}");
        }
        assert!(!line.contains('\n'));
        // Two seconds cannot turn the cube a full 2π: no episode passes the success test.
        assert_eq!(s.success_rate, 0.0, "{line}");
    }
    assert!(rollout::run(ControllerKind::Igm, ObjectShape::Cube, 0, 0, &options).is_err());
    assert_eq!("FG".parse::<ControllerKind>(), Ok(ControllerKind::Fg));
}

#[test]
fn controller_kind_serialises_as_configs_spell_it() {
    // The trainer's configs say `controller = "fg"`; their hashes depend on this spelling.
    for kind in ControllerKind::ALL {
        let json = serde_json::to_string(&kind).expect("serialise");
        assert_eq!(json, format!("\"{}\"", kind.name()));
        assert_eq!(serde_json::from_str::<ControllerKind>(&json).expect("deserialise"), kind);
    }
    assert!(serde_json::from_str::<ControllerKind>("\"FG\"").is_err(), "case-sensitive, as configs were");
}

// ---------------------------------------------------------------- the Allegro

#[test]
fn allegro_igm_turns_the_cube_about_z_without_a_drop_in_two_seconds() {
    let steps = 40; // 2 s at 20 Hz
    for seed in 0..3 {
        for (sign, config) in [(1.0f32, IgmConfig::default()), (-1.0, IgmConfig::default().reversed())] {
            let (rotation, min_contacts, dropped) = igm_run(allegro_config(steps), config, seed);
            println!(
                "Allegro IGM seed {seed} do {sign:+}: rotation {rotation:+.3} rad, min contacts {min_contacts}"
            );
            assert!(!dropped, "seed {seed}: dropped");
            assert!(min_contacts >= 3, "seed {seed}: {min_contacts} contacts");
            assert!(sign * rotation > 0.05, "seed {seed} sign {sign}: rotation {rotation}");
        }
    }
}

#[test]
fn allegro_cs_lifts_one_finger_off_and_back_while_the_other_three_hold() {
    let config = CsConfig::for_env(&allegro_config(1));
    // The first 10 seeds whose grasp has all four fingertips on the cube (the noisy grasp
    // leaves one off now and then, and CS then has no finger to spare).
    let (mut trials, mut ok) = (0, 0);
    for seed in 0..20 {
        let Some(t) = cs_trial(allegro_config(1), config, seed, 5) else {
            println!("Allegro CS seed {seed}: fewer than four contacts after the grasp");
            continue;
        };
        let success = t.succeeded() && t.others_min_while_off >= 3;
        println!(
            "Allegro CS seed {seed} finger {}: broke {} remade {} held {} others while off >= {} contacts {:?}",
            t.finger, t.broke, t.remade, t.alive, t.others_min_while_off, t.counts
        );
        assert_ne!(t.finger, 3, "seed {seed}: lifted the thumb, the only finger opposing the others");
        ok += usize::from(success);
        trials += 1;
        if trials == 10 {
            break;
        }
    }
    println!("Allegro CS: {ok}/{trials} switches succeeded");
    assert_eq!(trials, 10, "too few grasps with four contacts");
    assert!(ok >= 8, "only {ok}/{trials} switches succeeded");
}

#[test]
fn allegro_fg_acts_with_one_finite_entry_per_joint() {
    let env_config = allegro_config(60);
    let hand = Arc::clone(&env_config.hand);
    assert_eq!(hand.num_joints(), 16);
    let mut env = Env::new(env_config.clone()).expect("env");
    let mut fg = FgController::new(hand, IgmConfig::default(), CsConfig::for_env(&env_config));
    let mut acted = 0;
    let stats = run_episode(&mut env, &mut fg, 1, |t, _| {
        assert_eq!(t.action.len(), 16);
        assert!(t.action.iter().all(|v| v.is_finite()), "{:?}", t.action);
        acted += usize::from(t.acted);
    })
    .expect("episode");
    println!("Allegro FG: {stats:?}");
    assert!(acted * 2 >= stats.steps, "FG acted on {acted} of {} steps", stats.steps);
}

/// A controller alone on the Allegro as `vge controller --hand allegro` runs it (episodes
/// from the file's grasp with 0.02 rad pose noise, seeds 0..), with CS's settings changed,
/// for trying a per-hand setting over many seeds, e.g. `VGE_KIND=cs VGE_CS_OPEN_FRACTION=0.45
/// cargo test --release -p vge-controllers --test integration allegro_controller_figures
/// -- --ignored --nocapture` (also `VGE_EPISODES` (20), `VGE_EPISODE_S` (30), `VGE_SEED` (0,
/// the first episode's), `VGE_CS_HORIZON`, `VGE_CS_SPEED_MAX`).
#[test]
#[ignore = "a measurement, not a check"]
fn allegro_controller_figures() {
    let var = |name: &str| std::env::var(name).ok().and_then(|s| s.parse::<f32>().ok());
    let kind: ControllerKind =
        std::env::var("VGE_KIND").unwrap_or_else(|_| "fg".into()).parse().expect("kind");
    let episodes = var("VGE_EPISODES").unwrap_or(20.0) as usize;
    let seed = std::env::var("VGE_SEED").ok().and_then(|s| s.parse::<u64>().ok()).unwrap_or(0);
    let steps = (var("VGE_EPISODE_S").unwrap_or(30.0) * 20.0).round() as usize;
    let env = allegro_config(steps);
    let mut cs = CsConfig::for_env(&env);
    if let Some(f) = var("VGE_CS_OPEN_FRACTION") {
        cs.open_fraction = f;
    }
    if let Some(h) = var("VGE_CS_HORIZON") {
        cs.horizon_steps = h as usize;
    }
    if let Some(v) = var("VGE_CS_SPEED_MAX") {
        cs.speed_max_rad_s = v;
    }
    println!("{kind} on the Allegro, {episodes} x {steps} steps from seed {seed}, CS {cs:?}");
    let options = RolloutOptions { env, igm: IgmConfig::default(), cs };
    let summary = rollout::run_with(kind, ObjectShape::Cube, episodes, seed, &options, |i, e| {
        println!(
            "episode {i}: rotation {:+.3} rad, switches {}, contacts {:.2}, {}",
            e.rotation_rad,
            e.contact_switches,
            e.mean_contacts,
            if e.dropped { format!("dropped at step {}", e.steps) } else { "held".to_owned() }
        );
    })
    .expect("rollout");
    println!("{}", summary.to_json_line());
}
