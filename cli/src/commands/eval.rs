//! `vge eval`: the success test of a policy file (or a finished run's final policy) on
//! vge-runtime in the simulator, on one object or several, with its gait diagram or a
//! recording of the first episode for the Rerun viewer.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use vge_sim::{EnvConfig, ObjectShape};

/// The episodes of the success test (`vge eval`, `vge robustness`).
#[derive(Debug, Clone, Copy, Args)]
pub struct EpisodeArgs {
    /// The object in the hand: cube, sphere, cylinder, dodecahedron, icosahedron or
    /// hexagonal-prism (no training object: it tests a policy on a shape it never saw).
    #[arg(long, default_value_t = ObjectShape::Cube)]
    pub object: ObjectShape,
    /// Seed of the grasp, noise and perturbation draws (episode k uses seed + k).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Episode length in seconds of sim time.
    #[arg(long, default_value_t = vge_run::eval::SUCCESS_TEST_EPISODE_S)]
    pub episode_s: f32,
    /// Uniform noise (+-rad) on the initial grasp's roll and closing angles; 0 starts
    /// every episode from the same grasp (then, without sensor noise or perturbations,
    /// all episodes are the same).
    #[arg(long, default_value_t = vge_run::eval::SUCCESS_TEST_GRASP_NOISE_RAD)]
    pub grasp_noise_rad: f32,
}

/// Evaluate a policy file on vge-runtime in the simulator (the success test): mean
/// return, rotation, contact switches, drops and success rate.
///
/// The defaults are the success test that training's evaluations and `vge plot` use:
/// 20 episodes of 30 s from initial grasps randomised by +-0.02 rad; an episode succeeds
/// when the object turns >= 2 pi about z without a drop, and a seed has learned when its
/// policy succeeds in >= 50% of them. Episodes run side by side on all cores.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// The policy file (`DIR/policy.vgep` of a training run, or `vge export`'s output).
    #[arg(long, required_unless_present = "run")]
    policy: Option<PathBuf>,
    /// Instead of --policy: score a finished training run's final policy again, with its
    /// config and the very episodes of its `final-eval.json`, by this vge's success test, and
    /// print the stored figures beside the new ones (for runs scored by an older vge). A run
    /// on several objects is scored on each of them.
    #[arg(long, conflicts_with_all = ["policy", "plot", "record", "noise_q_rad", "noise_normal_frac", "noise_position_m", "perturb_force_n", "perturb_magnitude_n", "objects"])]
    run: Option<PathBuf>,
    /// With --run: replace the run's `final-eval.json` by the new score.
    #[arg(long, requires = "run")]
    write: bool,
    /// Episodes to run (the success test uses 20).
    #[arg(long, default_value_t = vge_run::eval::SUCCESS_TEST_EPISODES)]
    episodes: usize,
    #[command(flatten)]
    episode: EpisodeArgs,
    /// Instead of --object: the success test on each of these objects, `all` (the paper's
    /// five: cube, sphere, cylinder, dodecahedron, icosahedron) or a comma-separated list
    /// (e.g. `cube,hexagonal-prism`, the prism being no training object): --episodes episodes
    /// per object, every object on the same seeds; one row per object and the overall
    /// figures (all episodes pooled). With --plot F.png: one gait diagram per object,
    /// F-<object>.png, and all of them, one under the other, in F.png.
    #[arg(long, value_name = "all|NAME,NAME,...", value_parser = parse_object_list, conflicts_with_all = ["object", "record"])]
    objects: Option<ObjectList>,
    /// Gaussian noise on observed joint positions (rad).
    #[arg(long, default_value_t = 0.0)]
    noise_q_rad: f32,
    /// Noise on contact normals, as a fraction of their length.
    #[arg(long, default_value_t = 0.0)]
    noise_normal_frac: f32,
    /// Gaussian noise on contact positions (m).
    #[arg(long, default_value_t = 0.0)]
    noise_position_m: f32,
    /// Random external force on the object, std per axis (N).
    #[arg(long, default_value_t = 0.0)]
    perturb_force_n: f32,
    /// Instead: a random external force of this magnitude (N) in a random direction.
    #[arg(long, default_value_t = 0.0, conflicts_with = "perturb_force_n")]
    perturb_magnitude_n: f32,
    /// Also draw the gait diagram of the first episode (seed --seed) into this PNG: each
    /// finger's contact over time above the object's rotation.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Also record the first episode (seed --seed) into this file (JSON Lines): each finger
    /// link's pose and the object's, the fingertip and link contact points with their normal
    /// forces, the actions (one per joint) and the reward, one line per control step. See it in the Rerun
    /// viewer with the Python package: `python -m vge.recording F.jsonl --spawn` (or `-o F.rrd`;
    /// `pip install ./python rerun-sdk`).
    #[arg(long, value_name = "F.jsonl")]
    record: Option<PathBuf>,
    /// Print the report as one JSON object (the fields of `final-eval.json`) instead of a
    /// summary.
    #[arg(long)]
    json: bool,
    /// Also score the success test with the object upright: an episode passes it only if it
    /// succeeds and the axis the object turned about overall leans at most RAD from z (the
    /// tilt printed beside the rotation). A tumble about a tilted axis can turn the object
    /// 2 pi about z and pass the success test; it fails this one. For example 0.35 (20 deg):
    /// the shipped vge15 gait turns the cube about an axis about 5 deg from z, the shipped
    /// Allegro policy about 65 deg. With --json: `max_tilt_rad` and `upright_success_rate`.
    #[arg(long, value_name = "RAD", value_parser = parse_max_tilt_rad)]
    max_tilt_rad: Option<f64>,
    /// The hand to run the policy on, in place of the one its file records (a shipped
    /// hand's name or an MJCF file: a policy of a hand vge does not ship is run so). The
    /// hand's orientation and the observation the policy takes come from the file.
    #[arg(long, value_name = "NAME|FILE.xml")]
    hand: Option<String>,
}

/// The objects of `vge eval --objects`.
#[derive(Debug, Clone)]
pub struct ObjectList(Vec<ObjectShape>);

fn parse_object_list(s: &str) -> Result<ObjectList, String> {
    vge_run::eval::parse_objects(s).map(ObjectList)
}

/// A bound on the turning axis's tilt: 0 to pi/2 rad (the tilt's range).
fn parse_max_tilt_rad(s: &str) -> Result<f64, String> {
    let rad: f64 = s.trim().parse().map_err(|e| format!("`{s}` is not a number of radians: {e}"))?;
    if (0.0..=std::f64::consts::FRAC_PI_2).contains(&rad) {
        Ok(rad)
    } else {
        Err(format!("{rad} rad is outside 0 to pi/2 (1.571), the range of a tilt from z"))
    }
}

/// A report's JSON object: its fields in their order, then the upright success test's
/// figures when one was asked.
#[derive(serde::Serialize)]
struct ReportLine<'a> {
    #[serde(flatten)]
    report: &'a vge_run::eval::EvalReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    max_tilt_rad: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    upright_success_rate: Option<f64>,
}

impl<'a> ReportLine<'a> {
    fn new(report: &'a vge_run::eval::EvalReport, max_tilt_rad: Option<f64>) -> Self {
        let upright_success_rate = max_tilt_rad.map(|rad| report.upright_success_rate(rad));
        Self { report, max_tilt_rad, upright_success_rate }
    }
}

/// A report as one JSON object ([`ReportLine`]).
fn report_json(report: &vge_run::eval::EvalReport, max_tilt_rad: Option<f64>) -> anyhow::Result<String> {
    serde_json::to_string(&ReportLine::new(report, max_tilt_rad)).context("writing the report as JSON")
}

/// The upright success line of a text report, if one was asked, its label padded to
/// `label_width` as the report's other labels are.
fn print_upright(report: &vge_run::eval::EvalReport, max_tilt_rad: Option<f64>, label_width: usize) {
    if let Some(rad) = max_tilt_rad {
        println!(
            "  {:<label_width$}{:.2} (a success about an axis within {:.0} deg of z)",
            "upright success",
            report.upright_success_rate(rad),
            rad.to_degrees()
        );
    }
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let EvalArgs {
        policy,
        episodes,
        episode: EpisodeArgs { object, seed, episode_s, grasp_noise_rad },
        objects,
        noise_q_rad,
        noise_normal_frac,
        noise_position_m,
        perturb_force_n,
        perturb_magnitude_n,
        plot,
        record,
        json,
        max_tilt_rad,
        run,
        write,
        hand,
    } = args;
    if let Some(dir) = run {
        return rescore_run(&dir, write, json, max_tilt_rad);
    }
    if let Some(path) = &record {
        vge_sim::recording::check_path(path)?;
    }
    let policy = policy.context("--policy or --run is required")?;
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    anyhow::ensure!(episode_s.is_finite() && episode_s > 0.0, "--episode-s must be positive");
    for (name, v) in [
        ("noise-q-rad", noise_q_rad),
        ("noise-normal-frac", noise_normal_frac),
        ("noise-position-m", noise_position_m),
        ("perturb-force-n", perturb_force_n),
        ("perturb-magnitude-n", perturb_magnitude_n),
        ("grasp-noise-rad", grasp_noise_rad),
    ] {
        anyhow::ensure!(v.is_finite() && v >= 0.0, "--{name} must be >= 0, got {v}");
    }
    // The policy's own task: its hand, orientation and observation, refused before any
    // episode if the policy cannot run on it.
    let task =
        vge_run::eval::policy_task_env(&vge_run::eval::read_policy_file(&policy)?, hand.as_deref(), object)
            .with_context(|| format!("the task of {}", policy.display()))?;
    // The success test's env for an object, with the robustness test's disturbances set the
    // one way it sets them.
    let env_for = |object: ObjectShape| {
        let env =
            EnvConfig { object: vge_sim::ObjectConfig { shape: object, ..task.object }, ..task.clone() };
        let mut env = vge_run::eval::success_test_env(&env, episode_s, grasp_noise_rad);
        use vge_lab::robustness::Axis;
        for (axis, level) in [
            (Axis::JointNoise, noise_q_rad),
            (Axis::NormalError, noise_normal_frac),
            (Axis::PositionError, noise_position_m),
            (Axis::Perturbation, perturb_force_n),
            (Axis::PerturbationMagnitude, perturb_magnitude_n),
        ] {
            axis.apply(&mut env, level);
        }
        env
    };
    if let Some(ObjectList(objects)) = objects {
        let envs: Vec<EnvConfig> = objects.iter().map(|&o| env_for(o)).collect();
        let out = ObjectsOutput { plot: plot.as_deref(), json, max_tilt_rad };
        return eval_objects(&policy, &envs, episodes, seed, episode_s, out);
    }
    let env = env_for(object);
    // Before the evaluation, so that a path that cannot be written fails at once.
    if let Some(path) = &record {
        record_episode(&policy, &env, seed, path)?;
    }
    let report = vge_run::eval::eval_policy_file(&policy, &env, episodes, seed)
        .with_context(|| format!("evaluating {}", policy.display()))?;
    if let Some(png) = &plot {
        draw_gait_diagram(&policy, &env, seed, png)?;
    }
    if json {
        println!("{}", report_json(&report, max_tilt_rad)?);
    } else {
        print_eval_report(&report, &policy, episode_s, object, max_tilt_rad);
    }
    Ok(())
}

/// What `vge eval --objects` writes beside the table: the gait diagrams (`--plot`), JSON in
/// place of text (`--json`), the upright success test (`--max-tilt-rad`).
struct ObjectsOutput<'a> {
    plot: Option<&'a Path>,
    json: bool,
    max_tilt_rad: Option<f64>,
}

/// `vge eval --objects`: the success test on each of `envs` (one per object).
fn eval_objects(
    policy: &Path,
    envs: &[EnvConfig],
    episodes: usize,
    seed: u64,
    episode_s: f32,
    ObjectsOutput { plot, json, max_tilt_rad }: ObjectsOutput<'_>,
) -> anyhow::Result<()> {
    let bytes = vge_run::eval::read_policy_file(policy)?;
    let report = vge_run::eval::eval_policy_bytes_per_object(&bytes, envs, episodes, seed)
        .with_context(|| format!("evaluating {}", policy.display()))?;
    if let Some(png) = plot {
        let outs: Vec<PathBuf> =
            envs.iter().map(|env| vge_lab::gait_diagram::per_object_png(png, env.object.shape)).collect();
        let panels: Vec<(&EnvConfig, &Path)> = envs.iter().zip(outs.iter().map(PathBuf::as_path)).collect();
        vge_lab::gait_diagram::draw_episodes(&bytes, &panels, seed, &policy.display().to_string(), png)
            .with_context(|| {
                format!("drawing the gait diagrams of {} beside {}", policy.display(), png.display())
            })?;
        for out in &outs {
            eprintln!("vge eval: gait diagram of episode seed {seed} in {}", out.display());
        }
        if envs.len() > 1 {
            eprintln!("vge eval: all {} objects' gait diagrams in {}", envs.len(), png.display());
        }
    }
    if json {
        /// The overall report with the per-object figures beside it.
        #[derive(serde::Serialize)]
        struct Line<'a> {
            #[serde(flatten)]
            overall: ReportLine<'a>,
            per_object: vge_run::eval::PerObjectFigures,
            /// Per object, in the order asked for.
            #[serde(skip_serializing_if = "Option::is_none")]
            upright_success_rate_per_object: Option<vge_run::eval::ByObject<f64>>,
        }
        let line = Line {
            overall: ReportLine::new(&report.overall, max_tilt_rad),
            per_object: report.figures(),
            upright_success_rate_per_object: max_tilt_rad.map(|rad| report.upright_success_rates(rad)),
        };
        println!("{}", serde_json::to_string(&line).context("writing the report as JSON")?);
        return Ok(());
    }
    println!("{episodes} episodes of {episode_s} s per object, policy {}", policy.display());
    print_objects_table(&report.per_object, &report.overall);
    if let Some(rad) = max_tilt_rad {
        let per_object: Vec<String> =
            report.upright_success_rates(rad).0.iter().map(|(o, rate)| format!("{o} {rate:.2}")).collect();
        println!(
            "upright success (a success about an axis within {:.0} deg of z): overall {:.2}; {}",
            rad.to_degrees(),
            report.overall.upright_success_rate(rad),
            per_object.join(", ")
        );
    }
    let verdict = match report.worst_object() {
        Some(_) if report.every_object_learned() => "learned on every object".to_owned(),
        Some((object, success)) => format!("not learned on every object (worst: the {object}, {success:.2})"),
        None => "no objects".to_owned(),
    };
    println!(
        "verdict: {verdict} (success >= {:.0}% of an object's episodes)",
        100.0 * vge_run::eval::LEARNED_SUCCESS_RATE
    );
    Ok(())
}

/// One row per object and the overall figures: success, drops, rotation, return, switches.
fn print_objects_table(
    per_object: &[(ObjectShape, vge_run::eval::EvalReport)],
    overall: &vge_run::eval::EvalReport,
) {
    println!(
        "  {:<16} {:>8} {:>7} {:>9} {:>9} {:>9} {:>9}",
        "object", "episodes", "success", "drops", "rot_rad", "return", "switches"
    );
    let row = |name: &str, r: &vge_run::eval::EvalReport| {
        println!(
            "  {name:<16} {:>8} {:>7.2} {:>9.2} {:>9.2} {:>9.2} {:>9.1}",
            r.episodes,
            r.success_rate,
            r.drop_rate,
            r.mean_rotation_rad,
            r.mean_return,
            r.mean_contact_switches
        );
    };
    for (object, r) in per_object {
        row(object.name(), r);
    }
    row("overall", overall);
}

/// `vge eval --run DIR [--write]`.
fn rescore_run(dir: &Path, write: bool, json: bool, max_tilt_rad: Option<f64>) -> anyhow::Result<()> {
    let r = vge_run::run_eval::rescore_final_eval(dir, write)
        .with_context(|| format!("scoring the run in {}", dir.display()))?;
    if json {
        println!("{}", report_json(&r.report, max_tilt_rad)?);
        return Ok(());
    }
    let stored = |v: Option<f64>, unit: &str| v.map_or("-".to_owned(), |v| format!("{v:.3}{unit}"));
    println!("{}", dir.display());
    println!(
        "  success rate     {:.3} (stored: {})",
        r.report.success_rate,
        stored(r.stored_success_rate, "")
    );
    print_upright(&r.report, max_tilt_rad, 17);
    println!(
        "  rotation         {:.2} rad per episode (stored: {}), about an axis tilted {:.0} deg from z",
        r.report.mean_rotation_rad,
        stored(r.stored_rotation_rad, " rad"),
        r.report.mean_rotation_axis_tilt_rad.to_degrees()
    );
    println!(
        "  drops {:.2}, contact switches {:.1} per episode, learned: {}",
        r.report.drop_rate,
        r.report.mean_contact_switches,
        r.report.learned()
    );
    println!(
        "  fingertip slip   {:.3} m per episode, {}",
        r.report.mean_tip_slip_m,
        slip_per_rad(r.report.mean_tip_slip_m, r.report.mean_rotation_rad)
    );
    if !r.per_object.is_empty() {
        print_objects_table(&r.per_object, &r.report);
    }
    if write {
        println!("  final-eval.json rewritten");
    }
    Ok(())
}

/// `vge eval --plot`: the gait diagram of the episode with seed `seed`.
fn draw_gait_diagram(policy: &Path, env: &EnvConfig, seed: u64, png: &Path) -> anyhow::Result<()> {
    let bytes = vge_run::eval::read_policy_file(policy)?;
    vge_lab::gait_diagram::draw_episode(&bytes, env, seed, &policy.display().to_string(), png).with_context(
        || format!("drawing the gait diagram of {} into {}", policy.display(), png.display()),
    )?;
    eprintln!("vge eval: gait diagram of episode seed {seed} in {}", png.display());
    Ok(())
}

/// `vge eval --record`: the episode with seed `seed` recorded into `path`.
fn record_episode(policy: &Path, env: &EnvConfig, seed: u64, path: &Path) -> anyhow::Result<()> {
    let bytes = vge_run::eval::read_policy_file(policy)?;
    let outcome = vge_run::eval::record_policy_bytes(&bytes, env, seed, path)
        .with_context(|| format!("recording {} into {}", policy.display(), path.display()))?;
    eprintln!(
        "vge eval: episode seed {seed} ({} steps) recorded in {}; see it in Rerun with \
         `python -m vge.recording {} --spawn`",
        outcome.length,
        path.display(),
        path.display()
    );
    Ok(())
}

/// Slip per radian turned, or a dash where the object did not turn.
fn slip_per_rad(slip_m: f64, rotation_rad: f64) -> String {
    if rotation_rad > 0.0 {
        format!("{:.4} m per rad turned", slip_m / rotation_rad)
    } else {
        "- m per rad turned".to_owned()
    }
}

fn print_eval_report(
    report: &vge_run::eval::EvalReport,
    policy: &Path,
    episode_s: f32,
    object: ObjectShape,
    max_tilt_rad: Option<f64>,
) {
    println!("{} episodes of {episode_s} s on the {object}, policy {}", report.episodes, policy.display());
    println!("  mean return        {:.3}", report.mean_return);
    println!(
        "  mean rotation      {:.3} rad about z, about an axis tilted {:.0} deg from z",
        report.mean_rotation_rad,
        report.mean_rotation_axis_tilt_rad.to_degrees()
    );
    println!("  success rate       {:.2} (turned >= 2 pi without a drop)", report.success_rate);
    print_upright(report, max_tilt_rad, 19);
    println!("  dropped            {:.2} of episodes", report.drop_rate);
    println!(
        "  contact switches   {:.1} per episode (a fingertip let go and touched again)",
        report.mean_contact_switches
    );
    println!(
        "  fingertip slip     {:.3} m per episode, {} (contact points' travel over the object)",
        report.mean_tip_slip_m,
        slip_per_rad(report.mean_tip_slip_m, report.mean_rotation_rad)
    );
    println!("  mean contacts      {:.2}; mean length {:.0} steps", report.mean_contacts, report.mean_length);
    let verdict = if report.learned() { "learned" } else { "not learned" };
    println!(
        "  verdict            {verdict} (success >= {:.0}% of episodes)",
        100.0 * vge_run::eval::LEARNED_SUCCESS_RATE
    );
}
