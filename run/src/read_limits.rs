//! How long each kind of file vge reads whole may be: every such read goes through
//! [`read_bounded`] (regular files only, refused unread beyond their bound), so that a path
//! naming `/dev/zero`, a FIFO or a huge file is an error naming it, not a hang or an
//! exhausted memory.

pub use vge_config_file::{MAX_CONFIG_FILE_LEN, read_bounded, read_to_string_bounded};

/// A JSON or TOML record a run or a command writes (an evaluation, a score, a checkpoint's
/// state and manifest, a controller's figures): kB, a few MB with every episode of a
/// multi-object score.
pub const MAX_RECORD_FILE_LEN: u64 = 64 << 20;

/// A CSV table a run appends to (`metrics.csv`, `eval.csv`): a row of a few hundred bytes per
/// logged step, far below this for any run.
pub const MAX_TABLE_FILE_LEN: u64 = 1 << 30;

/// A text file of numbers (`vge import --obs-mean`): one observation's worth.
pub const MAX_NUMBERS_FILE_LEN: u64 = 1 << 20;
