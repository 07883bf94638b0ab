//! The paper's robustness test (its Fig. 4): a policy's return, success and drops against the
//! level of one disturbance at a time, the others off: noise on the measured joint positions
//! (0..0.1 rad), error on the contact normals (0..50%), error on the contact positions
//! (0..3 mm), and a random external force on the object (0..its weight), drawn two ways: the
//! issue's Gaussian of the weight per component, and the paper's words ("perturbation forces
//! equivalent to the full weight of the object") read literally, a force of the weight's
//! magnitude in a random direction. Every level runs the
//! same episodes (same seeds, so the same initial grasps): the differences are the
//! disturbance's. `vge robustness` writes `robustness.csv`, `robustness.json` and
//! `robustness.png`.

use std::path::Path;

use plotters::prelude::*;
use serde::Serialize;
use vge_sim::EnvConfig;

use crate::plot::PlotError;
use vge_run::eval::{EvalError, EvalReport, eval_policy_bytes_per_object, success_test_env};

/// Standard gravity, for the object's weight (N).
const GRAVITY_MPS2: f32 = 9.81;

/// One disturbance of the robustness test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Gaussian noise on each observed joint position, std in rad.
    JointNoise,
    /// Gaussian noise on each contact-normal component, std as a fraction of its length.
    NormalError,
    /// Gaussian noise on each contact-point coordinate, std in m.
    PositionError,
    /// A random force on the object, std per axis in N, redrawn with probability 0.1 per step.
    Perturbation,
    /// A random force on the object of this magnitude in N in a uniformly random direction,
    /// redrawn as [`Axis::Perturbation`]'s.
    PerturbationMagnitude,
}

impl Axis {
    pub const ALL: [Axis; 5] = [
        Axis::JointNoise,
        Axis::NormalError,
        Axis::PositionError,
        Axis::Perturbation,
        Axis::PerturbationMagnitude,
    ];

    /// The axis whose [`Axis::name`] is `name`.
    pub fn from_name(name: &str) -> Option<Axis> {
        Axis::ALL.into_iter().find(|a| a.name() == name)
    }

    /// The column value in `robustness.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Axis::JointNoise => "joint_noise_rad",
            Axis::NormalError => "normal_error_frac",
            Axis::PositionError => "position_error_m",
            Axis::Perturbation => "perturbation_force_n",
            Axis::PerturbationMagnitude => "perturbation_magnitude_n",
        }
    }

    fn title(self) -> &'static str {
        match self {
            Axis::JointNoise => "joint position noise (rad)",
            Axis::NormalError => "contact normal error (fraction)",
            Axis::PositionError => "contact position error (mm)",
            Axis::Perturbation => "force on the object, std per axis (N)",
            Axis::PerturbationMagnitude => "force on the object, magnitude (N)",
        }
    }

    /// The paper's largest level: 0.1 rad, 50%, 3 mm, the object's weight (both forces).
    pub fn max_level(self, env: &EnvConfig) -> f32 {
        match self {
            Axis::JointNoise => 0.1,
            Axis::NormalError => 0.5,
            Axis::PositionError => 0.003,
            Axis::Perturbation | Axis::PerturbationMagnitude => env.object.mass_kg * GRAVITY_MPS2,
        }
    }

    /// Sets this disturbance to `level` in `env`.
    pub fn apply(self, env: &mut EnvConfig, level: f32) {
        match self {
            Axis::JointNoise => env.noise.q_std_rad = level,
            Axis::NormalError => env.noise.normal_std_frac = level,
            Axis::PositionError => env.noise.position_std_m = level,
            Axis::Perturbation => env.perturbation.force_std_n = level,
            Axis::PerturbationMagnitude => env.perturbation.force_magnitude_n = level,
        }
        // A force with no redraw rate is never drawn.
        let is_push = matches!(self, Axis::Perturbation | Axis::PerturbationMagnitude);
        if is_push && level > 0.0 && env.perturbation.change_probability == 0.0 {
            env.perturbation.change_probability = 0.1;
        }
    }
}

/// What episodes each level runs, and on which axes.
#[derive(Debug, Clone, PartialEq)]
pub struct RobustnessOptions {
    pub episodes: usize,
    pub episode_s: f32,
    pub grasp_noise_rad: f32,
    pub seed: u64,
    /// Levels per axis, evenly from 0 to the axis's largest (at least 2).
    pub levels: usize,
    /// The axes to test, in this order (at least one; [`Axis::ALL`] for the paper's figure).
    pub axes: Vec<Axis>,
}

/// One (axis, level) of the test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobustnessRow {
    pub axis: &'static str,
    pub level: f32,
    /// `level` as a fraction of the axis's largest level.
    pub fraction_of_max: f32,
    pub mean_return: f64,
    /// Mean return relative to the undisturbed one (the paper's y axis).
    pub return_fraction: f64,
    pub success_rate: f64,
    pub drop_rate: f64,
    pub mean_rotation_rad: f64,
    pub mean_contact_switches: f64,
}

/// The whole test: what ran, and one row per axis and level (level 0 of every axis is the
/// same undisturbed run).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobustnessReport {
    pub episodes: usize,
    pub episode_s: f32,
    pub grasp_noise_rad: f32,
    pub seed: u64,
    pub clean_return: f64,
    pub rows: Vec<RobustnessRow>,
}

fn row(axis: Axis, level: f32, max: f32, r: &EvalReport, clean_return: f64) -> RobustnessRow {
    RobustnessRow {
        axis: axis.name(),
        level,
        fraction_of_max: if max > 0.0 { level / max } else { 0.0 },
        mean_return: r.mean_return,
        // A clean return at or below zero has no meaningful fraction.
        return_fraction: if clean_return > 0.0 { r.mean_return / clean_return } else { f64::NAN },
        success_rate: r.success_rate,
        drop_rate: r.drop_rate,
        mean_rotation_rad: r.mean_rotation_rad,
        mean_contact_switches: r.mean_contact_switches,
    }
}

/// The most levels per axis: each costs a success test, so more would run for days.
pub const MAX_LEVELS: usize = 1_000;

fn check(options: &RobustnessOptions) -> Result<(), EvalError> {
    if !(2..=MAX_LEVELS).contains(&options.levels) {
        return Err(EvalError::InvalidOption(format!(
            "the robustness test needs 2 to {MAX_LEVELS} levels per axis, got {}",
            options.levels
        )));
    }
    if options.axes.is_empty() {
        return Err(EvalError::InvalidOption("the robustness test needs at least one axis".to_owned()));
    }
    Ok(())
}

/// Runs the test of the policy in `policy_bytes` on `base` (the object and hand; its noise
/// and perturbation settings are replaced); `on_row` sees each row as it is measured.
pub fn run(
    policy_bytes: &[u8],
    base: &EnvConfig,
    options: &RobustnessOptions,
    on_row: impl FnMut(&RobustnessRow),
) -> Result<RobustnessReport, EvalError> {
    run_objects(policy_bytes, std::slice::from_ref(base), options, on_row)
}

/// [`run`] on several objects at once (a policy trained on several): each level's episodes
/// run on every env of `bases`, on the same seeds, and are pooled; a push's level is the same
/// fraction of each object's own weight. The rows' `level` is the first object's.
pub fn run_objects(
    policy_bytes: &[u8],
    bases: &[EnvConfig],
    options: &RobustnessOptions,
    mut on_row: impl FnMut(&RobustnessRow),
) -> Result<RobustnessReport, EvalError> {
    let [first, ..] = bases else {
        return Err(EvalError::NoEpisodes);
    };
    check(options)?;
    let clean_envs: Vec<EnvConfig> = bases
        .iter()
        .map(|b| {
            let mut env = success_test_env(b, options.episode_s, options.grasp_noise_rad);
            for axis in Axis::ALL {
                axis.apply(&mut env, 0.0);
            }
            env
        })
        .collect();
    let eval = |envs: &[EnvConfig]| {
        eval_policy_bytes_per_object(policy_bytes, envs, options.episodes, options.seed).map(|r| r.overall)
    };
    let clean = eval(&clean_envs)?;
    let mut rows = Vec::with_capacity(options.axes.len() * options.levels);
    for &axis in &options.axes {
        for i in 0..options.levels {
            let fraction = i as f32 / (options.levels - 1) as f32;
            let report = if i == 0 {
                clean.clone()
            } else {
                let envs: Vec<EnvConfig> = clean_envs
                    .iter()
                    .zip(bases)
                    .map(|(clean_env, base)| {
                        let mut env = clean_env.clone();
                        axis.apply(&mut env, axis.max_level(base) * fraction);
                        env
                    })
                    .collect();
                eval(&envs)?
            };
            let max = axis.max_level(first);
            let r = row(axis, max * fraction, max, &report, clean.mean_return);
            on_row(&r);
            rows.push(r);
        }
    }
    Ok(RobustnessReport {
        episodes: options.episodes * bases.len(),
        episode_s: options.episode_s,
        grasp_noise_rad: options.grasp_noise_rad,
        seed: options.seed,
        clean_return: clean.mean_return,
        rows,
    })
}

/// `robustness.csv`: a header and one line per row.
pub fn to_csv(report: &RobustnessReport) -> String {
    let mut text = String::from(
        "axis,level,fraction_of_max,mean_return,return_fraction,success_rate,drop_rate,mean_rotation_rad,mean_contact_switches\n",
    );
    for r in &report.rows {
        text.push_str(&format!(
            "{},{},{:.4},{:.6},{:.6},{:.4},{:.4},{:.6},{:.4}\n",
            r.axis,
            r.level,
            r.fraction_of_max,
            r.mean_return,
            r.return_fraction,
            r.success_rate,
            r.drop_rate,
            r.mean_rotation_rad,
            r.mean_contact_switches
        ));
    }
    text
}

/// `robustness.png`: one panel per axis tested, return fraction (solid) and success rate
/// (dashed) against the level.
pub fn plot(report: &RobustnessReport, out: &Path) -> Result<(), PlotError> {
    crate::plot::prepare_png(out)?;
    let draw_err = |e: &dyn std::fmt::Display| PlotError::Draw(e.to_string());
    let axes: Vec<Axis> =
        Axis::ALL.into_iter().filter(|a| report.rows.iter().any(|r| r.axis == a.name())).collect();
    let panels = axes.len().max(1);
    let root = BitMapBackend::new(out, (450 * panels as u32, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(&e))?;
    for (panel, &axis) in root.split_evenly((1, panels)).iter().zip(&axes) {
        let rows: Vec<&RobustnessRow> = report.rows.iter().filter(|r| r.axis == axis.name()).collect();
        // Millimetres read better than metres on the position axis.
        let scale = if axis == Axis::PositionError { 1e3 } else { 1.0 };
        let x_max = rows.iter().map(|r| f64::from(r.level) * scale).fold(1e-9, f64::max);
        let y_max = rows
            .iter()
            .flat_map(|r| [r.return_fraction, r.success_rate])
            .filter(|v| v.is_finite())
            .fold(1.05, f64::max);
        let mut chart = ChartBuilder::on(panel)
            .caption(axis.title(), ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..x_max, 0.0..y_max)
            .map_err(|e| draw_err(&e))?;
        chart.configure_mesh().x_labels(5).draw().map_err(|e| draw_err(&e))?;
        let points = |f: fn(&RobustnessRow) -> f64| -> Vec<(f64, f64)> {
            rows.iter().map(|r| (f64::from(r.level) * scale, f(r))).filter(|p| p.1.is_finite()).collect()
        };
        chart
            .draw_series(LineSeries::new(points(|r| r.return_fraction), BLUE.stroke_width(2)))
            .map_err(|e| draw_err(&e))?
            .label("return / clean return")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        chart
            .draw_series(DashedLineSeries::new(points(|r| r.success_rate), 8, 5, RED.stroke_width(2)))
            .map_err(|e| draw_err(&e))?
            .label("success rate")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| draw_err(&e))?;
    }
    root.present().map_err(|e| draw_err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_axis_sets_only_its_own_disturbance_up_to_the_papers_level() {
        let base = EnvConfig::default();
        assert!((Axis::Perturbation.max_level(&base) - 0.15 * 9.81).abs() < 1e-5, "the cube's weight");
        for axis in Axis::ALL {
            let mut env = base.clone();
            axis.apply(&mut env, axis.max_level(&base));
            let set = [
                env.noise.q_std_rad > 0.0,
                env.noise.normal_std_frac > 0.0,
                env.noise.position_std_m > 0.0,
                env.perturbation.force_std_n > 0.0,
                env.perturbation.force_magnitude_n > 0.0,
            ];
            assert_eq!(set.iter().filter(|&&s| s).count(), 1, "{axis:?}");
        }
        for axis in [Axis::Perturbation, Axis::PerturbationMagnitude] {
            let mut env = base.clone();
            axis.apply(&mut env, 1.0);
            assert!(env.perturbation.change_probability > 0.0, "a force that is never drawn is no test");
        }
    }
}
