//! Each run's figures object by object, for runs trained on several objects (`vge compare`'s
//! `per-object.csv` and its table in `compare.md`): when each object first passed a periodic
//! success test, and the selected and final policies' held-out figures on it.
//!
//! The group aggregates of `vge compare` say how a group does; these rows say which seed
//! and which object carry it, which is what a reader checks a multi-object claim against.

use std::path::Path;

use crate::plot::PlotError;
use vge_run::eval::{LEARNED_SUCCESS_RATE, ObjectFigures};
use vge_run::run_dir::RunCurves;
use vge_sim::ObjectShape;

/// One run on one object.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectRow {
    pub group: String,
    /// The run folder, as given.
    pub run: String,
    pub seed: u64,
    pub object: ObjectShape,
    /// Env step of the first periodic success test (`eval.csv`) at which this object's success
    /// reached [`LEARNED_SUCCESS_RATE`]; None if none did.
    pub first_pass_step: Option<u64>,
    /// The selected policy's step and held-out figures on this object (`score.json`).
    pub selected_step: Option<u64>,
    pub selected: Option<ObjectFigures>,
    /// The final policy's held-out figures on this object.
    pub final_policy: Option<ObjectFigures>,
    /// The run's wall time (`final-eval.json`), the same on each of its rows.
    pub wall_s: Option<f64>,
}

/// The rows of every run of `groups` on each of `objects`, in group, run and object order.
pub fn rows(
    groups: &[(&str, Vec<&RunCurves>)],
    objects: &[ObjectShape],
) -> Result<Vec<ObjectRow>, PlotError> {
    let mut rows = Vec::new();
    for (group, runs) in groups {
        for run in runs {
            let eval_csv = vge_run::run_dir::RunDir::new(&run.dir).eval_csv();
            for &object in objects {
                let figures = |per_object: Option<&vge_run::eval::PerObjectFigures>| {
                    per_object.and_then(|p| p.of(object).copied())
                };
                let score = run.score.as_ref();
                rows.push(ObjectRow {
                    group: (*group).to_owned(),
                    run: run.dir.display().to_string(),
                    seed: run.seed,
                    object,
                    first_pass_step: first_pass_step(&eval_csv, object)?,
                    selected_step: score.and_then(|s| s.selected.as_ref()).map(|s| s.step),
                    selected: figures(
                        score.and_then(|s| s.selected.as_ref()).and_then(|s| s.per_object.as_ref()),
                    ),
                    final_policy: figures(score.and_then(|s| s.final_policy.per_object.as_ref())),
                    wall_s: run.wall_s,
                });
            }
        }
    }
    Ok(rows)
}

/// The step of the first row of `eval_csv` whose `<object>_success` reaches
/// [`LEARNED_SUCCESS_RATE`]; None when none does, or the run has no such column.
fn first_pass_step(eval_csv: &Path, object: ObjectShape) -> Result<Option<u64>, PlotError> {
    let column = format!("{}_success", object.name());
    let Some((steps, success)) = vge_run::run_dir::object_success(eval_csv, &column)? else {
        return Ok(None);
    };
    let steps = vge_run::run_dir::whole_steps(eval_csv, &steps)?;
    Ok(steps.iter().zip(&success).find(|(_, s)| **s >= LEARNED_SUCCESS_RATE).map(|(step, _)| *step))
}

/// `per-object.csv`: one line per row; empty cells where a figure is missing.
pub fn to_csv(rows: &[ObjectRow]) -> String {
    let mut text = String::from(
        "group,run,seed,object,first_pass_step,selected_step,selected_success,selected_drops,\
         selected_rotation_rad,selected_switches,final_success,final_drops,final_rotation_rad,\
         final_switches,wall_s\n",
    );
    let opt = |v: Option<String>| v.unwrap_or_default();
    let figures = |f: &Option<ObjectFigures>| match f {
        Some(f) => format!(
            "{:.4},{:.4},{:.3},{:.2}",
            f.success_rate, f.drop_rate, f.mean_rotation_rad, f.mean_contact_switches
        ),
        None => ",,,".to_owned(),
    };
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.group,
            r.run,
            r.seed,
            r.object.name(),
            opt(r.first_pass_step.map(|s| s.to_string())),
            opt(r.selected_step.map(|s| s.to_string())),
            figures(&r.selected),
            figures(&r.final_policy),
            opt(r.wall_s.map(|s| format!("{s:.0}"))),
        ));
    }
    text
}

/// The rows as a markdown table: success with drops in brackets, rotation and switches per
/// episode of the selected policy, and "never" where no periodic test passed.
pub fn to_markdown(rows: &[ObjectRow]) -> String {
    let mut text = String::from(
        "| group | run | object | first pass | selected: success (drops), at | rotation rad, switches | final: success (drops) | wall s |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let success = |f: &Option<ObjectFigures>| {
        f.as_ref().map_or("-".to_owned(), |f| format!("{:.2} ({:.2})", f.success_rate, f.drop_rate))
    };
    for r in rows {
        let at = r.selected_step.map_or(String::new(), |s| format!(", {}", steps_label(s)));
        let motion = r.selected.as_ref().map_or("-".to_owned(), |f| {
            format!("{:.1}, {:.1}", f.mean_rotation_rad, f.mean_contact_switches)
        });
        text.push_str(&format!(
            "| {} | {} | {} | {} | {}{} | {} | {} | {} |\n",
            r.group,
            r.run,
            r.object.name(),
            r.first_pass_step.map_or("never".to_owned(), steps_label),
            success(&r.selected),
            at,
            motion,
            success(&r.final_policy),
            r.wall_s.map_or("-".to_owned(), |s| format!("{s:.0}")),
        ));
    }
    text
}

/// 250000 -> "250k", 2000000 -> "2M", 1250000 -> "1.25M", other steps as they are.
fn steps_label(step: u64) -> String {
    match step {
        s if s >= 1_000_000 && s % 10_000 == 0 => {
            let m = format!("{:.2}", s as f64 / 1e6);
            format!("{}M", m.trim_end_matches('0').trim_end_matches('.'))
        }
        s if s >= 1_000 && s % 1_000 == 0 => format!("{}k", s / 1_000),
        s => s.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_read_as_people_write_them() {
        assert_eq!(steps_label(250_000), "250k");
        assert_eq!(steps_label(2_000_000), "2M");
        assert_eq!(steps_label(2_500_000), "2.5M");
        assert_eq!(steps_label(1_250_000), "1.25M");
        assert_eq!(steps_label(1_001_000), "1001k");
        assert_eq!(steps_label(4_720), "4720");
    }

    #[test]
    fn the_first_pass_is_the_first_test_at_half_success() {
        let dir = std::env::temp_dir().join(format!("vge-object-rows-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let csv = dir.join("eval.csv");
        std::fs::write(
            &csv,
            "step,cube_success,sphere_success\n250000,0.45,0.0\n500000,0.5,0.1\n750000,0.9,0.2\n",
        )
        .expect("eval.csv");
        assert_eq!(first_pass_step(&csv, ObjectShape::Cube).expect("read"), Some(500_000));
        assert_eq!(first_pass_step(&csv, ObjectShape::Sphere).expect("read"), None);
        assert_eq!(first_pass_step(&csv, ObjectShape::Cylinder).expect("no column is no pass"), None);
        std::fs::remove_dir_all(&dir).ok();
    }
}
