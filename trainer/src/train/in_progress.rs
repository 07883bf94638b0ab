//! The envs' episodes in progress, saved with a checkpoint that does not end them (a stop),
//! as the checkpoint's `episodes.bin`.
//!
//! Neither the physics world nor a controller's state can be saved, but both are functions
//! of what happened since the episode began: the env's reset seed and disturbance levels,
//! the actions it executed, and the calls its controller got with the generator it was
//! reseeded with. That record ([`EpisodeLog`]) is what is saved, and a resume makes the same
//! reset, steps and calls again (`Collector::restore`), which puts every env, its episode's
//! bookkeeping and its controller where the stopped run left them. The behaviour policy's
//! segment of each env and its observation (to check the replay against) are saved beside it.
//!
//! The file is little-endian: the magic `VGEEPI02`, the observation's and the action's
//! lengths (u32 each: the hand's), the number of envs (u32), then per env its seeds and ramp
//! step (3 x u64), its segment (source u8, steps left u64, controller stale u8), its
//! observation (obs x f32), its actions (u32 count, act x f32 each) and its controller calls
//! (u32 count, each the episode step u32 and the kind u8). Every count is checked against the
//! bytes left before anything is allocated.

use crate::behaviour::{ControllerCall, Segment};
use crate::replay::Source;

const MAGIC: &[u8; 8] = b"VGEEPI02";

/// One env's episode since its reset: what replays it.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct EpisodeLog {
    /// The seed the env was reset with.
    pub env_seed: u64,
    /// The seed its controller's generator was reseeded with.
    pub controller_seed: u64,
    /// Env steps of training when the episode began: its disturbance levels (curricula).
    pub ramp_step: u64,
    /// The executed actions, one per step of the episode so far.
    pub actions: Vec<Vec<f32>>,
    /// The controller's calls, each with the episode step it was made before (on the state
    /// that step started from), in order.
    pub calls: Vec<(u32, ControllerCall)>,
}

/// One env at a checkpoint that keeps its episode.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct EnvInProgress {
    pub log: EpisodeLog,
    pub segment: Segment,
    /// Its observation when the checkpoint was written: the replay must arrive at it.
    pub obs: Vec<f32>,
}

/// Every env's episode in progress, env by env.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct InProgress {
    /// The length of every env's observation (the critic's: the env's full observation).
    pub obs_dim: usize,
    /// The length of every action (the hand's joints).
    pub act_dim: usize,
    pub envs: Vec<EnvInProgress>,
}

impl InProgress {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(MAGIC);
        put_u32(&mut b, self.obs_dim);
        put_u32(&mut b, self.act_dim);
        put_u32(&mut b, self.envs.len());
        for e in &self.envs {
            for v in [e.log.env_seed, e.log.controller_seed, e.log.ramp_step] {
                b.extend_from_slice(&v.to_le_bytes());
            }
            b.push(u8::from(e.segment.source == Source::Controller));
            b.extend_from_slice(&(e.segment.remaining as u64).to_le_bytes());
            b.push(u8::from(e.segment.controller_stale));
            e.obs.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
            put_u32(&mut b, e.log.actions.len());
            e.log.actions.iter().flatten().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
            put_u32(&mut b, e.log.calls.len());
            for &(at, call) in &e.log.calls {
                b.extend_from_slice(&at.to_le_bytes());
                b.push(match call {
                    ControllerCall::Reset => 0,
                    ControllerCall::Act => 1,
                });
            }
        }
        b
    }

    /// Parses [`Self::to_bytes`] of a run whose observations and actions have `obs_dim` and
    /// `act_dim` entries; `Err` says what is wrong.
    pub fn from_bytes(bytes: &[u8], obs_dim: usize, act_dim: usize) -> Result<Self, String> {
        let mut r = Reader { bytes, at: 0 };
        if r.take(MAGIC.len())? != MAGIC {
            return Err(
                "not a file of episodes in progress of this vge (resume it with the vge that wrote it)"
                    .to_owned(),
            );
        }
        let (file_obs, file_act) = (r.u32()? as usize, r.u32()? as usize);
        if (file_obs, file_act) != (obs_dim, act_dim) {
            return Err(format!(
                "its episodes have observations of {file_obs} and actions of {file_act}, the run's {obs_dim} and {act_dim}"
            ));
        }
        // Each env takes at least its fixed fields: a count beyond the bytes left is refused
        // before anything is allocated for it.
        let fixed = 3 * 8 + 1 + 8 + 1 + 4 * obs_dim + 4 + 4;
        let n = r.count(fixed)?;
        let mut envs = Vec::with_capacity(n);
        for _ in 0..n {
            let (env_seed, controller_seed, ramp_step) = (r.u64()?, r.u64()?, r.u64()?);
            let source = match r.u8()? {
                0 => Source::Learner,
                1 => Source::Controller,
                other => return Err(format!("segment source {other}")),
            };
            let remaining = usize::try_from(r.u64()?).map_err(|_| "segment length".to_owned())?;
            let controller_stale = match r.u8()? {
                0 => false,
                1 => true,
                other => return Err(format!("controller state flag {other}")),
            };
            let obs = (0..obs_dim).map(|_| r.f32()).collect::<Result<Vec<_>, String>>()?;
            let actions = (0..r.count(4 * act_dim)?)
                .map(|_| (0..act_dim).map(|_| r.f32()).collect::<Result<Vec<_>, String>>())
                .collect::<Result<Vec<_>, String>>()?;
            let calls = (0..r.count(5)?)
                .map(|_| {
                    let at = r.u32()?;
                    let call = match r.u8()? {
                        0 => ControllerCall::Reset,
                        1 => ControllerCall::Act,
                        other => return Err(format!("controller call kind {other}")),
                    };
                    Ok((at, call))
                })
                .collect::<Result<Vec<_>, String>>()?;
            if calls.windows(2).any(|w| w[0].0 > w[1].0)
                || calls.last().is_some_and(|c| c.0 as usize >= actions.len())
            {
                return Err("controller calls out of order or past the episode's steps".to_owned());
            }
            envs.push(EnvInProgress {
                log: EpisodeLog { env_seed, controller_seed, ramp_step, actions, calls },
                segment: Segment { source, remaining, controller_stale },
                obs,
            });
        }
        if r.at != bytes.len() {
            return Err(format!("{} bytes after the last env", bytes.len() - r.at));
        }
        Ok(Self { obs_dim, act_dim, envs })
    }
}

fn put_u32(b: &mut Vec<u8>, n: usize) {
    // Counts are of envs, episode steps and calls: far below u32::MAX (configs bound them).
    b.extend_from_slice(&u32::try_from(n).unwrap_or(u32::MAX).to_le_bytes());
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len()).ok_or("cut short")?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, String> {
        let mut b = [0u8; 4];
        b.copy_from_slice(self.take(4)?);
        Ok(u32::from_le_bytes(b))
    }

    fn u64(&mut self) -> Result<u64, String> {
        let mut b = [0u8; 8];
        b.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(b))
    }

    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_bits(self.u32()?))
    }

    /// A count of items of at least `item_bytes` each, at most what the bytes left hold.
    fn count(&mut self, item_bytes: usize) -> Result<usize, String> {
        let n = self.u32()? as usize;
        if n.saturating_mul(item_bytes) > self.bytes.len() - self.at {
            return Err(format!("a count of {n} that the file cannot hold"));
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> InProgress {
        let log = EpisodeLog {
            env_seed: 7,
            controller_seed: u64::MAX,
            ramp_step: 1234,
            actions: vec![vec![0.5; 4], vec![-0.0; 4], vec![f32::MIN_POSITIVE; 4]],
            calls: vec![(0, ControllerCall::Reset), (0, ControllerCall::Act), (2, ControllerCall::Act)],
        };
        let segment = Segment { source: Source::Controller, remaining: 3, controller_stale: false };
        let fresh = Segment { source: Source::Learner, remaining: 0, controller_stale: true };
        InProgress {
            obs_dim: 6,
            act_dim: 4,
            envs: vec![
                EnvInProgress { log, segment, obs: vec![0.25; 6] },
                EnvInProgress { log: EpisodeLog::default(), segment: fresh, obs: vec![1.0; 6] },
            ],
        }
    }

    #[test]
    fn episodes_in_progress_come_back_bit_for_bit() {
        let saved = sample();
        let bytes = saved.to_bytes();
        let back = InProgress::from_bytes(&bytes, 6, 4).expect("parses");
        let err = InProgress::from_bytes(&bytes, 65, 15).expect_err("another hand's sizes");
        assert!(err.contains("observations of 6"), "{err}");
        assert_eq!(back, saved);
        // -0.0 == 0.0 for PartialEq: the bits must survive too.
        assert_eq!(back.envs[0].log.actions[1][0].to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn cut_padded_or_inconsistent_files_are_refused_without_allocating_their_counts() {
        let bytes = sample().to_bytes();
        for cut in [0, 7, 8, 11, 12, 19, 20, bytes.len() - 1] {
            assert!(InProgress::from_bytes(&bytes[..cut], 6, 4).is_err(), "cut at {cut}");
        }
        let mut padded = bytes.clone();
        padded.push(0);
        assert!(InProgress::from_bytes(&padded, 6, 4).expect_err("padded").contains("after the last env"));
        // A count of u32::MAX envs is refused by the bytes left, not allocated.
        let mut huge = bytes.clone();
        huge[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(InProgress::from_bytes(&huge, 6, 4).expect_err("count").contains("cannot hold"));
        let mut wrong = sample();
        wrong.envs[0].log.calls.push((9, ControllerCall::Act));
        assert!(InProgress::from_bytes(&wrong.to_bytes(), 6, 4).is_err(), "a call past the episode's steps");
    }
}
