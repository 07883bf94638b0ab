//! The episodes a run is judged on, each a range of env seeds fixed by the run's seed alone
//! (so that training is not perturbed by its evaluations): the validation episodes of its
//! periodic tests, which model selection picks a snapshot on; the test episodes the selected
//! snapshot is reported on, which nothing was selected on; and the held-out episodes its
//! policies are scored on (`vge score`), the same for every run. Config validation and
//! the score keep them apart.

/// Which grasps an evaluation draws: the periodic (and final) evaluations share one set, the
/// validation episodes a snapshot is selected on; the selected snapshot is then reported on
/// the test set, which nothing was selected on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EpisodeSet {
    Validation,
    Test,
}

impl EpisodeSet {
    /// Both sets, with their names, for checks that other episodes stay apart from them.
    pub const ALL: [(Self, &'static str); 2] = [(Self::Validation, "validation"), (Self::Test, "test")];

    /// The env seed of the set's first episode (episode k: this + k), from the run's seed
    /// alone.
    pub fn first_seed(self, run_seed: u64) -> u64 {
        match self {
            Self::Validation => run_seed.wrapping_mul(1_000_003).wrapping_add(0xe7a1),
            Self::Test => run_seed.wrapping_mul(1_000_033).wrapping_add(0x7e57),
        }
    }
}

/// Held-out episodes per policy by default (and at the end of training).
pub const HELD_OUT_EPISODES: usize = 100;
/// Env seed of the first held-out episode (episode k: this + k), 2^52: far from the seeds
/// training's validation and test episodes start at for any seed below about 4.5e9.
pub const HELD_OUT_SEED: u64 = 1 << 52;
