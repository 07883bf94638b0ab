//! `vge plot`: training curves of runs, or the paper's Table I from all runs below folders.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

/// Plot training curves of runs, or with --table1 the paper's Table I and Fig. 3
///
/// Curves of run directories (mean and min-max over runs of the same experiment) go into a
/// PNG, with a markdown table of final success rates printed; --table1 builds Table I and
/// Fig. 3 from all runs below the given folders.
///
/// Panels: episode return, rotation, controller share, the critic's mean Q beside the
/// discounted Monte-Carlo returns of its data (a sound critic stays within them), and their
/// difference, the critic's gap (what `vge facts`, `vge compare` and Table I report at a
/// run's end). A run
/// learned when its final-eval.json success rate is >= 50% (`vge eval`'s success test).
/// Runs trained on several objects also get OUT-per-object.png beside OUT: each object's
/// success in the periodic evaluations, one panel per object.
///
/// --table1 DIR places every run by its config's controller and method and writes
/// DIR/table1.csv (controller,method,seeds,learned,success_rate_mean,return_mean,
/// return_std,env_steps; once runs are scored also scored and the IQM and mean of their
/// held-out success with 95% intervals, selected and final: iqm, iqm_ci_low, ...,
/// final_iqm_ci_high), DIR/table1.md (beside the paper's numbers, and each cell's critic at
/// the end of its runs: mean Q minus the collected return), DIR/curves-fg.png,
/// DIR/curves-cs.png (periodic success rate and return against env steps, one band per
/// method) and, once runs are scored, DIR/improvement.csv (every guided method against RL,
/// VGE against FGE, VGE + BC against VGE, by the selected policies), DIR/improvement-final.csv
/// (the same by the final policies) and DIR/profiles-fg.png, DIR/profiles-cs.png.
/// Runs without final-eval.json are counted as running.
/// The controllers alone come from DIR/controllers/{fg,cs,igm}.json when present
/// (`vge controller --kind fg --episodes 20 --episode-s 30 --json`).
///
/// Examples:
///   vge plot runs/fg/seed-* --out fg.png --success-csv fg.csv
///   vge plot --table1 docs/results/table1 docs/results/table1 docs/results/cube-fg-vge-seeds
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct PlotArgs {
    /// Run directories (each with config.toml and metrics.csv); with --table1, folders
    /// searched for runs (three levels down).
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The PNG of the curves.
    #[arg(long, required_unless_present = "table1", conflicts_with = "table1")]
    out: Option<PathBuf>,
    /// Also write one row per run (learned, success rate, env steps, wall time) here.
    #[arg(long, conflicts_with = "table1")]
    success_csv: Option<PathBuf>,
    /// Write Table I and its curves into this folder instead (see above).
    #[arg(long, value_name = "DIR")]
    table1: Option<PathBuf>,
}

/// `vge plot`.
pub fn run(args: PlotArgs) -> anyhow::Result<()> {
    let PlotArgs { runs, out, success_csv, table1 } = args;
    if let Some(dir) = table1 {
        let written = vge_lab::table1::write(&runs, &dir)?;
        print!(
            "{}",
            vge_lab::table1::to_markdown_with(
                &written.rows,
                &written.improvements,
                &written.improvements_final
            )
        );
        for d in &written.skipped {
            eprintln!("not in Table I (not the cube alone, or no controller): {}", d.display());
        }
        for f in &written.files {
            eprintln!("wrote {}", f.display());
        }
        return Ok(());
    }
    let out = out.context("--out is required without --table1")?;
    let curves = runs.iter().map(|d| vge_run::run_dir::read_run(d)).collect::<Result<Vec<_>, _>>()?;
    let table = vge_lab::plot::plot(&curves, &out)?;
    print!("{table}");
    eprintln!("wrote {}", out.display());
    if let Some(path) = vge_lab::plot::plot_per_object(&curves, &out)? {
        eprintln!("wrote {} (success per object)", path.display());
    }
    if let Some(path) = success_csv {
        std::fs::write(&path, vge_lab::plot::success_csv(&curves))
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
