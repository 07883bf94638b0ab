//! A run's folder: the effective config, `metrics.csv` and the TensorBoard events written as
//! training goes, and the checkpoint (module docs of [`super`] list every file).

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use super::metrics::{METRICS_HEADER, csv_fields};
use super::state::TrainState;
use super::{TrainError, io_err};
use crate::checkpoint;
use crate::config::Config;
use crate::replay::ReplayBuffer;
use crate::sac::Sac;
use crate::tensorboard::EventWriter;

pub(super) struct RunFolder {
    dir: PathBuf,
    metrics_path: PathBuf,
    metrics: csv::Writer<File>,
    events: EventWriter,
}

impl RunFolder {
    /// Opens `dir` for a session that starts at `step`: a fresh run writes `config.toml` and
    /// the metrics header; a resumed one (`resumed`) drops the rows past its checkpoint, and
    /// writes `config.toml` again if this session's config differs (a run extended with
    /// `--steps`), so that the folder says what the run finished under.
    pub fn open(dir: &Path, config: &Config, step: u64, resumed: bool) -> Result<Self, TrainError> {
        let metrics_path = dir.join("metrics.csv");
        let config_path = dir.join("config.toml");
        let effective = config.to_toml_string()?;
        if resumed {
            truncate_csv(&metrics_path, step)?;
            truncate_csv(&dir.join("eval.csv"), step)?;
            let stored = std::fs::read_to_string(&config_path).map_err(io_err(&config_path))?;
            if stored != effective {
                std::fs::write(&config_path, &effective).map_err(io_err(&config_path))?;
            }
        } else {
            std::fs::write(&config_path, &effective).map_err(io_err(&config_path))?;
            std::fs::write(&metrics_path, format!("{METRICS_HEADER}\n")).map_err(io_err(&metrics_path))?;
        }
        // A new event file per session; a resumed one starts with a session-start marker so
        // that TensorBoard drops the interrupted session's points past the checkpoint.
        let tb_dir = dir.join("tensorboard");
        let mut events = EventWriter::create(&tb_dir, &format!(".s{step}")).map_err(io_err(&tb_dir))?;
        if resumed {
            events.session_start(step).map_err(io_err(events.path()))?;
        }
        let file =
            File::options().append(true).create(true).open(&metrics_path).map_err(io_err(&metrics_path))?;
        let metrics = csv::WriterBuilder::new().has_headers(false).from_writer(file);
        Ok(Self { dir: dir.to_owned(), metrics_path, metrics, events })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
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

    /// Saves a checkpoint ([`crate::checkpoint::save`]) of `sac`, `state` and, when
    /// `state.has_replay`, `replay`.
    pub fn checkpoint(&self, sac: &Sac, replay: &ReplayBuffer, state: &TrainState) -> Result<(), TrainError> {
        let text =
            toml::to_string(state).map_err(|e| TrainError::Resume(format!("serialising state: {e}")))?;
        Ok(checkpoint::save(&self.dir, sac, state.has_replay.then_some(replay), &text)?)
    }
}

/// The checkpoint of `dir`, verified ([`crate::checkpoint::open`]), loaded into `sac` and
/// `replay`; returns its state.
pub(super) fn load_checkpoint(
    dir: &Path,
    sac: &mut Sac,
    replay: &mut ReplayBuffer,
) -> Result<TrainState, TrainError> {
    let ckpt = checkpoint::open(dir)?;
    let state: TrainState = toml::from_str(ckpt.state_toml()).map_err(|e| {
        TrainError::Resume(format!("{}: {e}", ckpt.dir().join(checkpoint::STATE_FILE).display()))
    })?;
    ckpt.load(sac, state.has_replay.then_some(replay))?;
    Ok(state)
}

/// Keeps the header and the rows whose first field (step) is <= `step`.
fn truncate_csv(path: &Path, step: u64) -> Result<(), TrainError> {
    if !path.exists() {
        return Ok(());
    }
    let file = File::open(path).map_err(io_err(path))?;
    let mut kept = String::new();
    for (k, line) in BufReader::new(file).lines().enumerate() {
        let line = line.map_err(io_err(path))?;
        let keep =
            k == 0 || line.split(',').next().and_then(|s| s.parse::<u64>().ok()).is_some_and(|s| s <= step);
        if keep {
            kept.push_str(&line);
            kept.push('\n');
        }
    }
    std::fs::write(path, kept).map_err(io_err(path))
}
