//! A run's training sessions as its folder records them: `train.log`'s segments (a lane or a
//! sweep writes `vge train`'s output there) and `tensorboard/`'s event files (one per session,
//! named by the step it started at). A run stopped and resumed trains in several sessions;
//! `metrics.csv`'s `steps_per_s` counts from each session's start, so a wall time read from it
//! is one session's.

use std::path::Path;

use super::{RunDir, RunFileError};

/// How a training segment of `train.log` ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentEnd {
    /// Its process ended without an end line (a SIGKILL, a crash, or still running).
    NoEndLine,
    /// Stopped by a signal with its checkpoint saved at this step.
    Stopped { step: u64 },
    /// Trained to the end.
    Done,
}

/// One training segment of `train.log`: one `vge train` process.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainSegment {
    /// 0, or the step it resumed from.
    pub from_step: u64,
    /// Its wall time, from its `time this session:` line.
    pub wall_s: Option<f64>,
    pub end: SegmentEnd,
}

/// Each training segment in `dir/train.log`, in order; None when the folder has no
/// `train.log` (a run trained by hand, or copied without it).
pub fn read_train_log(dir: &Path) -> Result<Option<Vec<TrainSegment>>, RunFileError> {
    let path = RunDir::new(dir).train_log();
    if !path.is_file() {
        return Ok(None);
    }
    let text = crate::read_limits::read_to_string_bounded(&path, crate::read_limits::MAX_TABLE_FILE_LEN)
        .map_err(|source| RunFileError::Io { path: path.clone(), source })?;
    let mut segments: Vec<TrainSegment> = Vec::new();
    for line in text.lines() {
        let word = |i: usize| line.split_whitespace().nth(i);
        if line.starts_with("training ") {
            let from_step = line
                .split_once("resuming from step ")
                .and_then(|(_, rest)| rest.split(|c: char| !c.is_ascii_digit()).next()?.parse().ok())
                .unwrap_or(0);
            segments.push(TrainSegment { from_step, wall_s: None, end: SegmentEnd::NoEndLine });
        } else if let Some(last) = segments.last_mut() {
            if line.starts_with("time this session: ") {
                last.wall_s = word(3).and_then(|w| w.parse().ok());
            } else if line.starts_with("stopped at step ") {
                if let Some(step) = word(3).and_then(|w| w.trim_end_matches(':').parse::<u64>().ok()) {
                    last.end = SegmentEnd::Stopped { step };
                }
            } else if line.starts_with("done: ") {
                last.end = SegmentEnd::Done;
            }
        }
    }
    Ok(Some(segments))
}

/// One entry per event file in `dir/tensorboard/`, in name order: the step its session
/// started at (the `.s<step>.` of its name), None for a file whose name does not say (an
/// older vge's); None for a folder without `tensorboard/` (stored copies leave it out).
pub fn tensorboard_sessions(dir: &Path) -> Result<Option<Vec<Option<u64>>>, RunFileError> {
    let folder = RunDir::new(dir).tensorboard();
    if !folder.is_dir() {
        return Ok(None);
    }
    let io = |source| RunFileError::Io { path: folder.clone(), source };
    let mut names: Vec<String> = std::fs::read_dir(&folder)
        .map_err(io)?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(io)?
        .into_iter()
        .filter(|n| n.starts_with("events.out.tfevents."))
        .collect();
    names.sort();
    Ok(Some(
        names
            .iter()
            .map(|n| n.split('.').find_map(|part| part.strip_prefix('s')?.parse::<u64>().ok()))
            .collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_and_event_files_name_each_session_and_where_it_started() {
        let tmp = std::env::temp_dir().join(format!("vge-run-sessions-{}", std::process::id()));
        let run = RunDir::new(&tmp);
        std::fs::create_dir_all(run.tensorboard()).expect("mkdir");
        assert_eq!(read_train_log(&tmp).expect("no log"), None);
        std::fs::write(
            run.train_log(),
            "training x (vge, td3, seed 0) into runs/x\n\
             time this session: 3130.3 s: updates 2450.0 s (78%)\n\
             stopped at step 820288: checkpoint saved; continue with `vge train --resume runs/x`\n\
             training x (vge, td3, seed 0) into runs/x, resuming from step 820288\n\
             time this session: 914.3 s: updates 679.2 s (74%)\n\
             done: 1000000 steps, 247502 updates\n\
             training x (vge, td3, seed 0) into runs/x, resuming from step 1000000\n",
        )
        .expect("write");
        let segments = read_train_log(&tmp).expect("reads").expect("a log");
        assert_eq!(
            segments,
            [
                TrainSegment {
                    from_step: 0,
                    wall_s: Some(3130.3),
                    end: SegmentEnd::Stopped { step: 820_288 }
                },
                TrainSegment { from_step: 820_288, wall_s: Some(914.3), end: SegmentEnd::Done },
                TrainSegment { from_step: 1_000_000, wall_s: None, end: SegmentEnd::NoEndLine },
            ]
        );
        for name in
            ["events.out.tfevents.1764000000.vge.s0.p41", "events.out.tfevents.1764003000.vge.s820288.p7"]
        {
            std::fs::write(run.tensorboard().join(name), b"").expect("write");
        }
        std::fs::write(run.tensorboard().join("events.out.tfevents.1763000000.host"), b"").expect("write");
        assert_eq!(tensorboard_sessions(&tmp).expect("reads"), Some(vec![None, Some(0), Some(820_288)]));
        std::fs::remove_dir_all(&tmp).expect("clean up");
        assert_eq!(tensorboard_sessions(&tmp).expect("no folder"), None);
    }
}
