//! `vge queue`: a queue of training runs, each trained one after another by a fixed `vge`
//! built from a named commit, so that a queue trains the same program on the same config
//! whatever the checkout has become since.
//!
//! A queue file holds one run a line, `REL COMMIT CONFIG SEED [--set KEY=VALUE ...]
//! [--score-with COMMIT2]` (blank lines and lines starting with `#` are skipped). The run
//! trains into `runs/REL` (its output appended to `runs/REL.log`) with `runs/bin/vge-COMMIT`,
//! which [`build`] makes once from a git worktree of COMMIT at `runs/src/COMMIT`, and CONFIG is
//! read from that worktree. `--score-with COMMIT2` scores the finished run again with
//! `runs/bin/vge-COMMIT2` (`vge score --force`), for scores the training binary lacks;
//! `runs/REL.scored-with-COMMIT2` marks that done. Every path is relative to the repository's
//! root, where the queue runs ([`Checkout`]).
//!
//! The modules: [`lane`] trains a queue's runs (skipping, resuming, scoring, logging),
//! [`build`] makes the binaries, [`status`] says where each run stands, [`collect`] copies a
//! finished run's record to `docs/results/REL`.

pub mod build;
pub mod collect;
pub mod lane;
pub mod status;

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};
use std::process::Command;
use std::time::{SystemTime, UNIX_EPOCH};

use thiserror::Error;

#[derive(Debug, Error)]
pub enum QueueError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    /// Every problem found in a queue file, one a line.
    #[error("{}", .0.join("\n"))]
    Check(Vec<String>),
    #[error("{0}")]
    Invalid(String),
}

pub(crate) fn io_err(path: &Path) -> impl Fn(std::io::Error) -> QueueError + '_ {
    move |source| QueueError::Io { path: path.display().to_string(), source }
}

/// One run of a queue file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueueLine {
    /// The line's number in its file, from 1.
    pub number: usize,
    /// The run's folder under `runs/` (and under `docs/results/` once collected).
    pub rel: String,
    /// The commit whose `vge` trains it, as the file writes it.
    pub commit: String,
    /// The config, relative to the repository's root at `commit`.
    pub config: String,
    pub seed: u64,
    /// The `--set KEY=VALUE` overrides, in order.
    pub sets: Vec<String>,
    /// `--score-with COMMIT2`.
    pub score_with: Option<String>,
}

const LINE_FORMAT: &str = "expected REL COMMIT CONFIG SEED [--set KEY=VALUE ...] [--score-with COMMIT]";

/// The runs of a queue file's text and the problems of its malformed lines, each as
/// `SOURCE:LINE: what`. Only the form is checked here; [`check`] checks commits and files.
pub fn parse(text: &str, source: &str) -> (Vec<QueueLine>, Vec<String>) {
    let mut lines = Vec::new();
    let mut problems = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let number = index + 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.first().is_none_or(|w| w.starts_with('#')) {
            continue;
        }
        match parse_words(&words, number) {
            Ok(parsed) => lines.push(parsed),
            Err(why) => problems.push(format!("{source}:{number}: {why}")),
        }
    }
    (lines, problems)
}

fn parse_words(words: &[&str], number: usize) -> Result<QueueLine, String> {
    let [rel, commit, config, seed, rest @ ..] = words else {
        return Err(LINE_FORMAT.to_owned());
    };
    if !is_plain_relative(rel) {
        return Err(format!("{rel}: REL must be a relative path without `..` (it is a folder under runs/)"));
    }
    let seed = seed.parse::<u64>().map_err(|_| format!("seed '{seed}' is not a whole number"))?;
    let mut sets = Vec::new();
    let mut score_with = None;
    let mut rest = rest.iter();
    while let Some(word) = rest.next() {
        match (*word, rest.next()) {
            ("--set", Some(set))
                if set.split_once('=').is_some_and(|(k, v)| !k.is_empty() && !v.is_empty()) =>
            {
                sets.push((*set).to_owned());
            }
            ("--score-with", Some(other)) if score_with.is_none() => score_with = Some((*other).to_owned()),
            _ => {
                return Err(format!(
                    "after the seed only --set KEY=VALUE words and one --score-with COMMIT: {}",
                    words[4..].join(" ")
                ));
            }
        }
    }
    Ok(QueueLine {
        number,
        rel: (*rel).to_owned(),
        commit: (*commit).to_owned(),
        config: (*config).to_owned(),
        seed,
        sets,
        score_with,
    })
}

fn is_plain_relative(path: &str) -> bool {
    let path = Path::new(path);
    path.components().all(|c| matches!(c, Component::Normal(_))) && path.components().next().is_some()
}

/// Reads and parses a queue file; Err with every malformed line.
pub fn read(queue: &Path) -> Result<Vec<QueueLine>, QueueError> {
    let text = std::fs::read_to_string(queue).map_err(io_err(queue))?;
    let (lines, problems) = parse(&text, &queue.display().to_string());
    if problems.is_empty() { Ok(lines) } else { Err(QueueError::Check(problems)) }
}

/// The repository a queue runs in: its root holds `.git`, `runs/` and `docs/results/`.
#[derive(Debug, Clone)]
pub struct Checkout {
    root: PathBuf,
}

impl Checkout {
    /// `root` must be a git checkout's top folder (the queue's paths are relative to it).
    pub fn open(root: &Path) -> Result<Self, QueueError> {
        if !root.join(".git").exists() {
            return Err(QueueError::Invalid(format!(
                "{} is not a repository's root (no .git): run vge queue from the root of the checkout that \
                 holds runs/ and docs/results/",
                root.display()
            )));
        }
        Ok(Self { root: root.to_owned() })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `runs/REL`: where the run trains.
    pub fn run_dir(&self, rel: &str) -> PathBuf {
        self.root.join("runs").join(rel)
    }

    /// `runs/REL.log`: the run's training output, every segment appended.
    pub fn run_log(&self, rel: &str) -> PathBuf {
        self.root.join("runs").join(format!("{rel}.log"))
    }

    /// `runs/REL.scored-with-COMMIT`: the run was scored again with that commit's vge.
    pub fn scored_with_marker(&self, rel: &str, commit: &str) -> PathBuf {
        self.root.join("runs").join(format!("{rel}.scored-with-{commit}"))
    }

    /// `docs/results/REL`: the run's committed record.
    pub fn results_dir(&self, rel: &str) -> PathBuf {
        self.root.join("docs/results").join(rel)
    }

    /// `runs/bin/vge-COMMIT`: the vge built from COMMIT.
    pub fn binary(&self, commit: &str) -> PathBuf {
        self.root.join("runs/bin").join(format!("vge-{commit}"))
    }

    /// `runs/src/COMMIT`: the git worktree the binary was built from and configs are read from.
    pub fn source(&self, commit: &str) -> PathBuf {
        self.root.join("runs/src").join(commit)
    }

    /// `runs/lanes/NAME.log` for the queue file `NAME.txt`: one line per start, end and skip.
    pub fn lane_log(&self, queue: &Path) -> PathBuf {
        self.lanes_dir().join(format!("{}.log", queue_name(queue)))
    }

    /// `runs/lanes/NAME.lock`: held by the `vge queue run` of the queue file `NAME.txt`.
    pub fn lane_lock(&self, queue: &Path) -> PathBuf {
        self.lanes_dir().join(format!("{}.lock", queue_name(queue)))
    }

    pub fn lanes_dir(&self) -> PathBuf {
        self.root.join("runs/lanes")
    }

    /// The full hash of `commit`, if this repository has it.
    pub fn resolve_commit(&self, commit: &str) -> Option<String> {
        let out = self.git(&["rev-parse", "--verify", "--quiet", &format!("{commit}^{{commit}}")]).ok()?;
        out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
    }

    /// Whether `path` exists at `commit`.
    pub fn has_file_at(&self, commit: &str, path: &str) -> bool {
        self.git(&["cat-file", "-e", &format!("{commit}:{path}")]).is_ok_and(|o| o.status.success())
    }

    pub(crate) fn git(&self, args: &[&str]) -> std::io::Result<std::process::Output> {
        Command::new("git").arg("-C").arg(&self.root).args(args).output()
    }
}

fn queue_name(queue: &Path) -> String {
    queue.file_stem().map_or_else(|| "queue".to_owned(), |s| s.to_string_lossy().into_owned())
}

/// Every commit the queue's runs not yet done ([`lane::is_done`]) train or score with, each
/// once, in order of first use: the binaries a lane still needs.
pub fn commits_to_do(checkout: &Checkout, lines: &[QueueLine]) -> Vec<String> {
    let to_do: Vec<QueueLine> = lines.iter().filter(|l| !lane::is_done(checkout, l)).cloned().collect();
    commits(&to_do)
}

/// Every commit a queue's lines train or score with, each once, in order of first use.
pub fn commits(lines: &[QueueLine]) -> Vec<String> {
    let mut seen = Vec::new();
    for c in lines.iter().flat_map(|l| std::iter::once(&l.commit).chain(l.score_with.as_ref())) {
        if !seen.contains(c) {
            seen.push(c.clone());
        }
    }
    seen
}

/// Every line of `queue` well formed, its commits in the repository, its config at its
/// commit, no run twice, and (with `binaries`) the vge built of every commit a run still to
/// do names: a typo found when a lane reaches its line would cost the hours before it. A
/// finished run's commit needs no binary, so a new checkout builds only what is left. Ok:
/// the lines.
pub fn check(checkout: &Checkout, queue: &Path, binaries: bool) -> Result<Vec<QueueLine>, QueueError> {
    let text = std::fs::read_to_string(queue).map_err(io_err(queue))?;
    let source = queue.display().to_string();
    let (lines, mut problems) = parse(&text, &source);
    let mut line_of: HashMap<&str, usize> = HashMap::new();
    let mut known: HashMap<&str, bool> = HashMap::new();
    for line in &lines {
        let at = format!("{source}:{}", line.number);
        for commit in std::iter::once(&line.commit).chain(line.score_with.as_ref()) {
            let present = *known.entry(commit).or_insert_with(|| checkout.resolve_commit(commit).is_some());
            if !present {
                problems.push(format!("{at}: no commit {commit} in this repository"));
            }
        }
        if known.get(line.commit.as_str()) == Some(&true) && !checkout.has_file_at(&line.commit, &line.config)
        {
            problems.push(format!("{at}: {} does not exist at commit {}", line.config, line.commit));
        }
        if let Some(first) = line_of.insert(&line.rel, line.number) {
            problems.push(format!("{at}: {} is also on line {first}", line.rel));
        }
    }
    if binaries {
        for commit in commits_to_do(checkout, &lines).iter().filter(|c| known.get(c.as_str()) == Some(&true))
        {
            if !checkout.binary(commit).is_file() {
                problems.push(format!(
                    "{source}: no {} (the vge of commit {commit}): build it with `vge queue build {source}`",
                    checkout.binary(commit).display()
                ));
            }
        }
    }
    problems.sort_by_key(|p| p.split(':').nth(1).and_then(|n| n.parse::<usize>().ok()).unwrap_or(usize::MAX));
    if problems.is_empty() { Ok(lines) } else { Err(QueueError::Check(problems)) }
}

/// `2026-11-29T12:09:43Z`: the lane log's time stamps (UTC, to the second).
pub fn utc_timestamp(time: SystemTime) -> String {
    let (date, [h, m, s]) = utc_parts(time);
    format!("{}T{h:02}:{m:02}:{s:02}Z", date.join("-"))
}

/// `20261129T120943Z`: the suffix of a run folder moved aside.
pub fn utc_compact(time: SystemTime) -> String {
    let (date, [h, m, s]) = utc_parts(time);
    format!("{}T{h:02}{m:02}{s:02}Z", date.concat())
}

fn utc_parts(time: SystemTime) -> ([String; 3], [u64; 3]) {
    let secs = time.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (y, m, d) = civil_from_days(i64::try_from(secs / 86_400).unwrap_or(0));
    let rem = secs % 86_400;
    ([format!("{y:04}"), format!("{m:02}"), format!("{d:02}")], [rem / 3600, rem % 3600 / 60, rem % 60])
}

/// The proleptic Gregorian (year, month, day) of a count of days since 1970-01-01
/// (H. Hinnant's `civil_from_days`).
fn civil_from_days(days: i64) -> (i64, i64, i64) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(month <= 2), month, day)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn time_stamps_are_utc_calendar_dates() {
        let t = UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        assert_eq!(utc_timestamp(t), "2023-11-14T22:13:20Z");
        assert_eq!(utc_compact(t), "20231114T221320Z");
        // A leap day and the turn of a century.
        assert_eq!(utc_timestamp(UNIX_EPOCH + Duration::from_secs(951_782_400)), "2000-02-29T00:00:00Z");
        assert_eq!(utc_timestamp(UNIX_EPOCH), "1970-01-01T00:00:00Z");
    }

    #[test]
    fn lines_parse_with_their_overrides_and_malformed_ones_are_named() {
        let text = "# a comment\n\nr/seed-0 abc1234 configs/x.toml 0 --set sac.threads=1 --score-with def5678\n\
                    r/seed-1 abc1234 configs/x.toml one\nr/seed-2 abc1234 configs/x.toml 2 --set\n\
                    ../out abc1234 configs/x.toml 3\nr/seed-4 abc1234\n";
        let (lines, problems) = parse(text, "q.txt");
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].sets, ["sac.threads=1"]);
        assert_eq!(lines[0].score_with.as_deref(), Some("def5678"));
        assert_eq!(lines[0].number, 3);
        assert_eq!(problems.len(), 4, "{problems:?}");
        assert!(problems[0].starts_with("q.txt:4: seed 'one'"), "{problems:?}");
        assert!(problems[1].starts_with("q.txt:5: after the seed"), "{problems:?}");
        assert!(problems[2].contains("without `..`"), "{problems:?}");
        assert!(problems[3].starts_with("q.txt:7: expected REL COMMIT"), "{problems:?}");
    }
}
