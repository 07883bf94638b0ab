//! `vge table1`: the paper's Table I on this machine, from the controllers alone through every
//! cell's sweep to the table and its figures.

use std::path::PathBuf;
use std::process::{Command, Stdio};

use anyhow::{Context, bail};
use clap::Args;

/// The Table I cells trained by default: the paper's FG row, CS's guided methods and IGM's
/// VGE (a side note in the paper, so fewer seeds).
const CELLS: [&str; 9] = [
    "cube-fg-rl",
    "cube-fg-rl-bc",
    "cube-fg-fge",
    "cube-fg-vge",
    "cube-fg-vge-bc",
    "cube-cs-fge",
    "cube-cs-vge",
    "cube-cs-vge-bc",
    "cube-igm-vge",
];

/// Run the paper's Table I on this machine: controllers, every cell's seeds, the table
///
/// Writes OUT/controllers/{fg,cs,igm}.json first (vge controller, a minute each; kept when
/// present), then each cell's seeds with vge sweep into OUT/CELL/seed-N (configs/CELL.toml,
/// --jobs at once on one thread each, a checkpoint every 50k env steps), then
/// OUT/table1.csv, table1.md and the curves (vge plot --table1 OUT OUT). Each run is 1M env
/// steps (25-50 minutes for a one-thread job beside another on a 2-core machine), so the
/// whole table (43 runs) is most of a day: run it in the background, and run it again after
/// an interruption: finished seeds are skipped and unfinished ones resume from their last
/// checkpoint.
///
/// Examples:
///   vge table1 runs/table1
///   vge table1 --jobs 4 --seeds 0..10 runs/table1
///   vge table1 --cells cube-fg-rl,cube-cs-vge runs/table1
///   vge table1 --set total_steps=20000 --set sac.warmup=2000 /tmp/t1   # a smoke test
#[derive(Debug, Args)]
#[command(verbatim_doc_comment)]
pub struct Table1Args {
    /// The folder of the table's runs and files.
    out: PathBuf,
    /// Seeds of every cell as `A..B` (B excluded) [default: 0..5, IGM's cell 0..3].
    #[arg(long)]
    seeds: Option<String>,
    /// The cells, comma-separated config names under --configs.
    #[arg(long, value_delimiter = ',', default_values_t = CELLS.map(str::to_owned))]
    cells: Vec<String>,
    /// The folder of the cells' configs.
    #[arg(long, default_value = "configs")]
    configs: PathBuf,
    /// Seeds trained at once, one libtorch thread each.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..))]
    jobs: u32,
    /// Override a config key of every run, e.g. `--set total_steps=20000` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Episodes of each controller alone.
    #[arg(long, default_value_t = 20)]
    controller_episodes: usize,
    /// Seconds of each controller episode.
    #[arg(long, default_value_t = 30.0)]
    controller_episode_s: f32,
}

/// `vge table1`.
pub fn run(args: Table1Args) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("the path of this vge")?;
    let controllers = args.out.join("controllers");
    std::fs::create_dir_all(&controllers).with_context(|| controllers.display().to_string())?;
    for kind in ["fg", "cs", "igm"] {
        let file = controllers.join(format!("{kind}.json"));
        if std::fs::metadata(&file).is_ok_and(|m| m.len() > 0) {
            continue;
        }
        let json = std::fs::File::create(&file).with_context(|| file.display().to_string())?;
        let (episodes, episode_s) =
            (args.controller_episodes.to_string(), args.controller_episode_s.to_string());
        let mut controller = Command::new(&exe);
        controller.args([
            "controller",
            "--kind",
            kind,
            "--episodes",
            &episodes,
            "--episode-s",
            &episode_s,
            "--json",
        ]);
        if let Err(e) = step(controller.stdout(Stdio::from(json)), &format!("the {kind} controller alone")) {
            let _ = std::fs::remove_file(&file);
            return Err(e);
        }
    }
    for cell in &args.cells {
        let seeds = match &args.seeds {
            Some(seeds) => seeds.clone(),
            // The paper's IGM cell is a side note.
            None if cell == "cube-igm-vge" => "0..3".to_owned(),
            None => "0..5".to_owned(),
        };
        println!("==> {cell}, seeds {seeds}");
        let config = args.configs.join(format!("{cell}.toml"));
        if !config.is_file() {
            bail!("{}: no such config (the cell {cell})", config.display());
        }
        let mut sweep = Command::new(&exe);
        sweep.arg("sweep").arg("--config").arg(&config).args(["--seeds", &seeds]);
        sweep.arg("--out").arg(args.out.join(cell));
        sweep.args(["--jobs", &args.jobs.to_string(), "--threads-per-job", "1"]);
        sweep.args(["--set", "run.checkpoint_interval=50000"]);
        sweep.args(args.overrides.iter().flat_map(|o| ["--set", o.as_str()]));
        step(&mut sweep, &format!("the sweep of {cell}"))?;
    }
    step(Command::new(&exe).arg("plot").arg("--table1").arg(&args.out).arg(&args.out), "the table")
}

/// Runs one step to its end; a step that a signal stopped passes its status on.
fn step(command: &mut Command, what: &str) -> anyhow::Result<()> {
    let status = command.status().with_context(|| format!("starting {what}"))?;
    if status.success() {
        return Ok(());
    }
    if let Some(code) = status.code()
        && let Some(signal) = vge_lab::sweep::stopped_by(code)
    {
        eprintln!("vge table1: {what} stopped; the same command again continues");
        return Err(crate::stop::Stopped { signal }.into());
    }
    bail!("{what} failed ({status})")
}
