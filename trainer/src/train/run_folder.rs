//! A run's folder: the effective config, `metrics.csv` and the TensorBoard events written as
//! training goes, and the checkpoint (module docs of [`super`] list every file).
//!
//! One process writes a folder at a time ([`RunLock`], held as long as the [`RunFolder`]).
//! Every file is written whole or not at all ([`vge_run::run_dir::atomic_file`]) but the ones that grow
//! row by row: `metrics.csv` and `eval.csv` get rows appended (a row cut short by a kill is
//! past the checkpoint), and a resume checks each of them whole (a header, complete rows)
//! before it appends, rewriting it atomically to the rows up to its checkpoint. A folder
//! holding any sign of a run ([`RUN_FILES`]) is never taken for a new run.

use std::fs::File;
use std::path::{Path, PathBuf};

use super::in_progress::InProgress;
use super::metrics::{METRICS_HEADER, TrainingObjects, csv_fields};
use super::state::TrainState;
use super::{TrainError, io_err};
use crate::checkpoint;
use crate::learner::Learner;
use crate::replay::ReplayBuffer;
use crate::tensorboard::EventWriter;
use vge_run::config::Config;
use vge_run::read_limits;
use vge_run::run_dir::RunDir;
use vge_run::run_dir::atomic_file;
use vge_run::run_dir::lock::RunLock;

pub use vge_run::run_dir::RUN_FILES;

/// Refuses `dir` for a new run when it holds any of [`RUN_FILES`], naming those found.
pub fn check_no_run(dir: &Path) -> Result<(), TrainError> {
    let found = RunDir::new(dir).run_files_present();
    if found.is_empty() {
        return Ok(());
    }
    let resumable = checkpoint::resume_dir(dir).is_some();
    Err(TrainError::RunExists {
        dir: dir.display().to_string(),
        found: found.join(", "),
        advice: if resumable {
            format!("continue it with `vge train --resume {}`, or choose another --out", dir.display())
        } else {
            "it has no checkpoint to resume from (stopped before its first): delete the folder to \
             start over, or choose another --out"
                .to_owned()
        },
    })
}

/// Removes every one of [`RUN_FILES`] from `dir`: what a new run wrote before it failed
/// without a checkpoint (it holds nothing to resume, and would refuse a new start there).
/// Best effort: the run's error is what the caller reports.
pub(super) fn remove_run_files(dir: &Path) {
    for name in RUN_FILES {
        let path = dir.join(name);
        let _ = if path.is_dir() { std::fs::remove_dir_all(&path) } else { std::fs::remove_file(&path) };
    }
}

pub(super) struct RunFolder {
    dir: PathBuf,
    metrics_path: PathBuf,
    metrics: csv::Writer<File>,
    events: EventWriter,
    /// `metrics.csv` holds the per-object columns: a run on several objects does, unless it
    /// was started by a vge that wrote none and goes on in its layout.
    object_columns: bool,
    _lock: RunLock,
}

impl RunFolder {
    /// Opens `dir` for a session that starts at `step`, holding its `lock`: a fresh run writes
    /// `config.toml` and the metrics header; a resumed one (`resumed`) checks its metrics and
    /// evaluation rows and drops those past its checkpoint, and writes `config.toml` again if
    /// this session's config differs (a run extended with `--steps`), so that the folder says
    /// what the run finished under.
    pub fn open(
        dir: &Path,
        config: &Config,
        step: u64,
        resumed: bool,
        lock: RunLock,
    ) -> Result<Self, TrainError> {
        let metrics_path = dir.join(vge_run::run_dir::METRICS);
        let config_path = dir.join(vge_run::run_dir::CONFIG);
        let effective = config.to_toml_string()?;
        let header = TrainingObjects::new(&config.env.objects, config.num_envs).metrics_header();
        if resumed {
            if !resume_csv(&metrics_path, step)? {
                atomic_file::write(&metrics_path, format!("{header}\n").as_bytes())
                    .map_err(io_err(&metrics_path))?;
            }
            let eval_path = dir.join(vge_run::run_dir::EVAL);
            if !resume_csv(&eval_path, step)? && eval_path.exists() {
                // Rows are appended to it with its header when the file is new.
                std::fs::remove_file(&eval_path).map_err(io_err(&eval_path))?;
            }
            let stored = RunDir::new(dir).read_config_text()?;
            if stored != effective {
                atomic_file::write(&config_path, effective.as_bytes()).map_err(io_err(&config_path))?;
            }
        } else {
            atomic_file::write(&config_path, effective.as_bytes()).map_err(io_err(&config_path))?;
            atomic_file::write(&metrics_path, format!("{header}\n").as_bytes())
                .map_err(io_err(&metrics_path))?;
        }
        // A resumed run keeps its file's layout: one started by a vge without the per-object
        // columns goes on without them.
        let object_columns = header != METRICS_HEADER && first_line(&metrics_path)? == header;
        // A new event file per session (named by its first step and its process: two resumes
        // from one checkpoint may start within a second); a resumed one starts with a
        // session-start marker so that TensorBoard drops the interrupted session's points
        // past the checkpoint.
        let tb_dir = dir.join(vge_run::run_dir::TENSORBOARD);
        let suffix = format!(".s{step}.p{}", std::process::id());
        let mut events = EventWriter::create(&tb_dir, &suffix).map_err(io_err(&tb_dir))?;
        if resumed {
            events.session_start(step).map_err(io_err(events.path()))?;
        }
        let file =
            File::options().append(true).create(true).open(&metrics_path).map_err(io_err(&metrics_path))?;
        let metrics = csv::WriterBuilder::new().has_headers(false).from_writer(file);
        Ok(Self { dir: dir.to_owned(), metrics_path, metrics, events, object_columns, _lock: lock })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether [`Self::log`]'s rows carry the per-object columns.
    pub fn object_columns(&self) -> bool {
        self.object_columns
    }

    /// One metrics row, to `metrics.csv` (flushed) and to TensorBoard as `train/<column>`
    /// (the empty ones left out).
    pub fn log(&mut self, step: u64, values: &[(&str, Option<f64>)]) -> Result<(), TrainError> {
        let path = &self.metrics_path;
        let csv_err = |e: csv::Error| io_err(path)(std::io::Error::other(e));
        self.metrics.write_record(csv_fields(step, values)).map_err(csv_err)?;
        self.metrics.flush().map_err(io_err(path))?;
        let scalars: Vec<(String, f64)> =
            values.iter().filter_map(|(n, v)| v.map(|x| (format!("train/{n}"), x))).collect();
        self.events.scalars(step, &scalars).map_err(io_err(self.events.path()))
    }

    /// Saves a checkpoint ([`crate::checkpoint::save`]) of `learner`, `state`, when
    /// `state.has_replay` `replay`, and the envs' episodes in progress when they go on
    /// through it. The rows logged up to it are synced to disk first: a resume from it keeps
    /// them.
    pub fn checkpoint(
        &self,
        learner: &dyn Learner,
        replay: &ReplayBuffer,
        state: &TrainState,
        episodes: Option<&[u8]>,
    ) -> Result<(), TrainError> {
        let path = &self.metrics_path;
        self.metrics.get_ref().sync_data().map_err(io_err(path))?;
        let eval = self.dir.join(vge_run::run_dir::EVAL);
        match File::options().append(true).open(&eval) {
            Ok(file) => file.sync_data().map_err(io_err(&eval))?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io_err(&eval)(e)),
        }
        let text =
            toml::to_string(state).map_err(|e| TrainError::Resume(format!("serialising state: {e}")))?;
        Ok(checkpoint::save(&self.dir, learner, state.has_replay.then_some(replay), &text, episodes)?)
    }
}

/// The checkpoint of `dir`, verified ([`crate::checkpoint::open`]), loaded into `learner` and
/// `replay`; returns its state and, when it kept them, the envs' episodes in progress.
pub(super) fn load_checkpoint(
    dir: &Path,
    learner: &mut dyn Learner,
    replay: &mut ReplayBuffer,
) -> Result<(TrainState, Option<InProgress>), TrainError> {
    let ckpt = checkpoint::open(dir)?;
    let state: TrainState = toml::from_str(ckpt.state_toml()).map_err(|e| {
        TrainError::Resume(format!("{}: {e}", ckpt.dir().join(checkpoint::STATE_FILE).display()))
    })?;
    let episodes = match ckpt.episodes()? {
        Some(bytes) => Some(
            InProgress::from_bytes(
                &bytes,
                learner.config().net.obs_dim as usize,
                learner.config().net.act_dim as usize,
            )
            .map_err(|e| {
                TrainError::Resume(format!("{}: {e}", ckpt.dir().join(checkpoint::EPISODES_FILE).display()))
            })?,
        ),
        None => None,
    };
    ckpt.load(learner, state.has_replay.then_some(replay))?;
    Ok((state, episodes))
}

/// The first line of the file at `path`, without its line end.
fn first_line(path: &Path) -> Result<String, TrainError> {
    let text =
        read_limits::read_to_string_bounded(path, read_limits::MAX_TABLE_FILE_LEN).map_err(io_err(path))?;
    Ok(text.lines().next().unwrap_or("").to_owned())
}

/// Checks the CSV file `path` (`metrics.csv`, `eval.csv`) of a run resumed at `step` before
/// rows are appended to it, and keeps its header and the rows up to `step`, rewritten
/// atomically when that drops any. A row cut short by a kill (no newline) is past the
/// checkpoint (rows up to it were synced before it was saved) and is dropped. A first line
/// that is not a header, or a row whose step is not a number, is refused with the file's name:
/// appended to, it would not read as a table. Returns false when the file holds no complete
/// line (missing, or a header cut short): it holds no row, and a new one must be started.
fn resume_csv(path: &Path, step: u64) -> Result<bool, TrainError> {
    let text = match read_limits::read_to_string_bounded(path, read_limits::MAX_TABLE_FILE_LEN) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(io_err(path)(e)),
    };
    if !text.contains('\n') {
        if step > 0 && text.is_empty() {
            // Emptied by a vge before this one, killed while rewriting it: the rows are gone.
            super::note_line(&format!(
                "vge: note: {} was empty; it starts again at step {step}",
                path.display()
            ));
        }
        return Ok(false);
    }
    let bad = |what: String| {
        TrainError::Resume(format!(
            "{}: {what}; restore the file, or delete it to resume with a new one (the rows it held \
             are then lost)",
            path.display()
        ))
    };
    let mut lines = text.split_inclusive('\n');
    let header = lines.next().unwrap_or("");
    if !header.starts_with("step,") {
        return Err(bad(format!("its first line is not a header starting `step,`: `{}`", header.trim_end())));
    }
    let mut kept = String::from(header);
    for (k, line) in lines.enumerate() {
        let Some(row) = line.strip_suffix('\n') else { break };
        let row_step = row.split(',').next().and_then(|s| s.trim().parse::<u64>().ok());
        match row_step {
            Some(s) if s <= step => kept.push_str(line),
            Some(_) => {}
            None => return Err(bad(format!("row {} does not start with a step: `{row}`", k + 2))),
        }
    }
    if kept != text {
        atomic_file::write(path, kept.as_bytes()).map_err(io_err(path))?;
    }
    Ok(true)
}
