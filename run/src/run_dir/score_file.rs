//! `score.json`: a run's policies scored on held-out episodes (`vge score`, and training at
//! its end; the scoring module makes it).

use serde::{Deserialize, Serialize};

use crate::eval::PerObjectFigures;

/// One policy's figures on the held-out episodes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyScore {
    /// The policy file, relative to the run folder.
    pub file: String,
    /// The env step it was exported at.
    pub step: u64,
    /// The file's CRC-32 (its format's checksum; a rescore is skipped only for the same files).
    pub crc32: u32,
    /// Share of episodes turned >= 2 pi about z without a drop.
    pub success_rate: f64,
    pub mean_return: f64,
    pub drop_rate: f64,
    pub mean_rotation_rad: f64,
    pub mean_contact_switches: f64,
    /// Fingertip slip per episode (m, [`vge_sim::slip`]); absent in scores of older vge
    /// versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_tip_slip_m: Option<f64>,
    /// Mean tilt of the axis the object turned about overall, from world z (rad,
    /// `EvalReport::mean_rotation_axis_tilt_rad`); absent in scores of older vge versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_rotation_axis_tilt_rad: Option<f64>,
    /// For a run on several objects: each object's figures (the ones above pool them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_object: Option<PerObjectFigures>,
}

/// The last periodic snapshots: the mean of their figures, and each one's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SnapshotsScore {
    pub success_rate: f64,
    pub mean_return: f64,
    pub drop_rate: f64,
    pub mean_rotation_rad: f64,
    pub mean_contact_switches: f64,
    /// The mean over the snapshots that have one (absent in scores of older vge versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_tip_slip_m: Option<f64>,
    /// The mean over the snapshots that have one (absent in scores of older vge versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_rotation_axis_tilt_rad: Option<f64>,
    pub snapshots: Vec<PolicyScore>,
}

/// `score.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// What the score means (the score module's `DEFINITION`): a score of another definition is
    /// scored again, never compared.
    pub definition: String,
    /// Episodes per policy.
    pub episodes: usize,
    /// Env seed of the first episode (episode k: seed + k).
    pub seed: u64,
    pub episode_s: f32,
    pub grasp_noise_rad: f32,
    /// The run's model selection; None for a run without one.
    pub selected: Option<PolicyScore>,
    #[serde(rename = "final")]
    pub final_policy: PolicyScore,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_snapshots: Option<SnapshotsScore>,
}
