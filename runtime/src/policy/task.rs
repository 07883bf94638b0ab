//! The task record of a version-3 file: which hand, observation set, object and orientation
//! a policy was trained for, so that a policy is refused on a hand it was not trained on.

use crate::PolicyError;
use crate::policy::fields::Reader;

/// Longest hand, object or orientation name in a task record, in bytes: a name, not a text,
/// so that firmware can hold one in a small fixed buffer.
pub const MAX_TASK_NAME_LEN: usize = 64;
/// Largest `K` of the `proprio:K` observation set (proprioception over the last `K` steps).
pub const MAX_PROPRIO_HISTORY: u32 = 64;
/// The hand a file without a task record drives: vge's own, the only one vge wrote
/// policies for before task records.
pub const UNRECORDED_HAND: &str = "vge15";
/// The observation set of a file without a task record.
pub const UNRECORDED_OBSERVATION_SET: &str = "full";

/// Which hand and task a policy was trained for (the task record of a version-3 file),
/// borrowed from the file bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TaskInfo<'a> {
    /// The hand's name, e.g. `"vge15"`, `"allegro"`: 1 to [`MAX_TASK_NAME_LEN`] bytes.
    pub hand: &'a str,
    /// SHA-256 of the hand's MJCF description (`vge_hand::Hand::description_sha256`), so
    /// that an edited hand file under the same name is told apart.
    pub hand_sha256: &'a [u8; 32],
    /// `"full"`, `"proprio"` or `"proprio:K"` (see [`is_observation_set`]).
    pub observation_set: &'a str,
    /// The object manipulated (e.g. `"cube"`); empty when unspecified.
    pub object: &'a str,
    /// The hand's orientation (e.g. `"palm_down"`); empty when unspecified.
    pub orientation: &'a str,
}

/// Whether `s` names an observation set: `full`, `proprio` or `proprio:K` with `K` from 1 to
/// [`MAX_PROPRIO_HISTORY`] in decimal without a leading zero (one spelling per set, so that
/// sets compare as strings).
pub fn is_observation_set(s: &str) -> bool {
    if s == "full" || s == "proprio" {
        return true;
    }
    let Some(k) = s.strip_prefix("proprio:") else {
        return false;
    };
    let canonical =
        !k.is_empty() && k.len() <= 2 && k.bytes().all(|b| b.is_ascii_digit()) && !k.starts_with('0');
    canonical && k.parse::<u32>().is_ok_and(|k| (1..=MAX_PROPRIO_HISTORY).contains(&k))
}

/// Checks a task-record name's length: at most [`MAX_TASK_NAME_LEN`] bytes, and not empty
/// when `required`.
pub fn check_task_name(field: &'static str, name: &str, required: bool) -> Result<(), PolicyError> {
    let len = name.len();
    if len > MAX_TASK_NAME_LEN || (required && len == 0) {
        return Err(PolicyError::TaskName { field, len });
    }
    Ok(())
}

/// Reads the optional task record at the end of version-3 metadata: `00`, or `01` and the
/// record (docs/policy-format.md).
pub(crate) fn task<'a>(r: &mut Reader<'a>) -> Result<Option<TaskInfo<'a>>, PolicyError> {
    let tag_at = r.pos;
    match r.take::<u8>("task")? {
        0 => return Ok(None),
        1 => {}
        _ => return Err(PolicyError::Malformed { field: "task", offset: tag_at }),
    }
    let hand: &'a str = r.take("task.hand")?;
    check_task_name("task.hand", hand, true)?;
    let sha_at = r.pos;
    let hand_sha256 = <&[u8; 32]>::try_from(r.bytes(32, "task.hand_sha256")?)
        .map_err(|_| PolicyError::Malformed { field: "task.hand_sha256", offset: sha_at })?;
    let set_at = r.pos;
    let observation_set: &'a str = r.take("task.observation_set")?;
    if !is_observation_set(observation_set) {
        return Err(PolicyError::BadObservationSet { offset: set_at });
    }
    let object: &'a str = r.take("task.object")?;
    check_task_name("task.object", object, false)?;
    let orientation: &'a str = r.take("task.orientation")?;
    check_task_name("task.orientation", orientation, false)?;
    Ok(Some(TaskInfo { hand, hand_sha256, observation_set, object, orientation }))
}
