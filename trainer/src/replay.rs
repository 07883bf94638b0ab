//! A preallocated f32 ring buffer of transitions, sampled uniformly with a seeded generator
//! into a [`Batch`]. Besides SAC's fields each transition records whether its action came
//! from the learner ([`Source::Learner`]) or a controller, and, where the method clones a
//! controller, the controller's action at that state (the BC target: the executed action
//! for VGE+BC, the queried but not executed one for RL+BC).

use std::io::{Read, Write};
use std::path::Path;

use rand::RngExt;
use tch::Tensor;
use thiserror::Error;

use crate::learner::{Batch, BcTerm};

/// Who chose a transition's action.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    Learner,
    Controller,
}

#[derive(Debug, Error)]
pub enum ReplayError {
    #[error("replay buffer: {0}")]
    Shape(String),
    #[error("replay buffer file {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("replay buffer file {path}: {message}")]
    Format { path: String, message: String },
}

/// The ring buffer. Rows are contiguous `obs_dim` / `act_dim` runs of f32.
#[derive(Debug, Clone)]
pub struct ReplayBuffer {
    obs_dim: usize,
    act_dim: usize,
    capacity: usize,
    len: usize,
    next: usize,
    obs: Vec<f32>,
    action: Vec<f32>,
    reward: Vec<f32>,
    next_obs: Vec<f32>,
    done: Vec<f32>,
    /// 1.0 when the learner chose the action.
    learner: Vec<f32>,
    /// The controller's action to clone (zeros where there is none).
    bc_action: Vec<f32>,
    /// 1.0 where `bc_action` holds a controller action.
    bc_mask: Vec<f32>,
}

const MAGIC: &[u8; 8] = b"VGERPLY2";

impl ReplayBuffer {
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Result<Self, ReplayError> {
        if capacity == 0 || obs_dim == 0 || act_dim == 0 {
            return Err(ReplayError::Shape(format!("capacity {capacity}, obs {obs_dim}, act {act_dim}")));
        }
        Ok(Self {
            obs_dim,
            act_dim,
            capacity,
            len: 0,
            next: 0,
            obs: vec![0.0; capacity * obs_dim],
            action: vec![0.0; capacity * act_dim],
            reward: vec![0.0; capacity],
            next_obs: vec![0.0; capacity * obs_dim],
            done: vec![0.0; capacity],
            learner: vec![0.0; capacity],
            bc_action: vec![0.0; capacity * act_dim],
            bc_mask: vec![0.0; capacity],
        })
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Stores one transition, overwriting the oldest when full. `done` is termination only
    /// (a truncated episode bootstraps). `bc_target` is the controller action the BC loss
    /// clones at `obs`, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn push(
        &mut self,
        obs: &[f32],
        action: &[f32],
        reward: f32,
        next_obs: &[f32],
        done: bool,
        source: Source,
        bc_target: Option<&[f32]>,
    ) -> Result<(), ReplayError> {
        if obs.len() != self.obs_dim
            || next_obs.len() != self.obs_dim
            || action.len() != self.act_dim
            || bc_target.is_some_and(|b| b.len() != self.act_dim)
        {
            return Err(ReplayError::Shape(format!(
                "transition of obs {} / next {} / action {}, expected {} / {}",
                obs.len(),
                next_obs.len(),
                action.len(),
                self.obs_dim,
                self.act_dim
            )));
        }
        let i = self.next;
        let (o, a) = (self.obs_dim, self.act_dim);
        self.obs[i * o..(i + 1) * o].copy_from_slice(obs);
        self.next_obs[i * o..(i + 1) * o].copy_from_slice(next_obs);
        self.action[i * a..(i + 1) * a].copy_from_slice(action);
        self.reward[i] = reward;
        self.done[i] = if done { 1.0 } else { 0.0 };
        self.learner[i] = if source == Source::Learner { 1.0 } else { 0.0 };
        let bc_row = &mut self.bc_action[i * a..(i + 1) * a];
        match bc_target {
            Some(b) => bc_row.copy_from_slice(b),
            None => bc_row.fill(0.0),
        }
        self.bc_mask[i] = if bc_target.is_some() { 1.0 } else { 0.0 };
        self.next = (i + 1) % self.capacity;
        self.len = (self.len + 1).min(self.capacity);
        Ok(())
    }

    /// Per-dimension mean and standard deviation of the stored observations (accumulated in
    /// f64), each std raised to at least `min_std` so that a constant input (say, the normal
    /// of a fingertip that never touched) is not divided by zero.
    pub fn obs_stats(&self, min_std: f32) -> (Vec<f32>, Vec<f32>) {
        let o = self.obs_dim;
        let mut sum = vec![0.0f64; o];
        let mut sum_sq = vec![0.0f64; o];
        for row in self.obs[..self.len * o].chunks_exact(o) {
            for (j, &x) in row.iter().enumerate() {
                sum[j] += f64::from(x);
                sum_sq[j] += f64::from(x) * f64::from(x);
            }
        }
        let n = self.len.max(1) as f64;
        let mean: Vec<f64> = sum.iter().map(|s| s / n).collect();
        let std = sum_sq
            .iter()
            .zip(&mean)
            .map(|(sq, m)| ((sq / n - m * m).max(0.0).sqrt() as f32).max(min_std))
            .collect();
        (mean.into_iter().map(|m| m as f32).collect(), std)
    }

    /// Whether the action of stored row `i` came from the learner.
    pub fn source(&self, i: usize) -> Option<Source> {
        (i < self.len).then(|| if self.learner[i] > 0.5 { Source::Learner } else { Source::Controller })
    }

    /// Indices of a uniform sample with replacement (one draw per row from `rng`).
    pub fn sample_indices<R: rand::Rng + ?Sized>(&self, batch: usize, rng: &mut R) -> Vec<usize> {
        (0..batch).map(|_| rng.random_range(0..self.len.max(1))).collect()
    }

    /// The BC target of stored row `i`, if it has one.
    pub fn bc_target(&self, i: usize) -> Option<&[f32]> {
        let a = self.act_dim;
        (i < self.len && self.bc_mask[i] > 0.5).then(|| &self.bc_action[i * a..(i + 1) * a])
    }

    /// A minibatch of `batch` rows drawn uniformly with replacement. With `bc = Some(beta)`,
    /// the batch carries a BC term: the stored controller actions, masked to the rows that
    /// have one.
    pub fn sample<R: rand::Rng + ?Sized>(
        &self,
        batch: usize,
        rng: &mut R,
        bc: Option<f64>,
    ) -> Result<Batch, ReplayError> {
        if self.len == 0 {
            return Err(ReplayError::Shape("sampling an empty buffer".to_owned()));
        }
        let idx = self.sample_indices(batch, rng);
        Ok(self.gather(&idx, bc))
    }

    /// The rows `idx` as a batch (see [`Self::sample`]).
    pub fn gather(&self, idx: &[usize], bc: Option<f64>) -> Batch {
        let (o, a, n) = (self.obs_dim, self.act_dim, idx.len());
        let mut obs = Vec::with_capacity(n * o);
        let mut next_obs = Vec::with_capacity(n * o);
        let mut action = Vec::with_capacity(n * a);
        let mut reward = Vec::with_capacity(n);
        let mut done = Vec::with_capacity(n);
        let mut mask = Vec::with_capacity(n);
        let mut bc_action = Vec::with_capacity(if bc.is_some() { n * a } else { 0 });
        for &i in idx {
            obs.extend_from_slice(&self.obs[i * o..(i + 1) * o]);
            next_obs.extend_from_slice(&self.next_obs[i * o..(i + 1) * o]);
            action.extend_from_slice(&self.action[i * a..(i + 1) * a]);
            reward.push(self.reward[i]);
            done.push(self.done[i]);
            mask.push(self.bc_mask[i]);
            if bc.is_some() {
                bc_action.extend_from_slice(&self.bc_action[i * a..(i + 1) * a]);
            }
        }
        let n = n as i64;
        let t = |v: &[f32], cols: usize| Tensor::from_slice(v).view([n, cols as i64]);
        let bc = bc.map(|beta| BcTerm { beta, mask: t(&mask, 1), action: t(&bc_action, a) });
        Batch { bc, ..Batch::new(t(&obs, o), t(&action, a), t(&reward, 1), t(&next_obs, o), t(&done, 1)) }
    }

    /// Writes the filled part (raw little-endian f32 after a small header) to `path`.
    pub fn save(&self, path: &Path) -> Result<(), ReplayError> {
        let shown = path.display().to_string();
        let io = |source| ReplayError::Io { path: shown.clone(), source };
        let file = std::fs::File::create(path).map_err(io)?;
        let mut w = std::io::BufWriter::new(file);
        self.write_to(&mut w).map_err(io)?;
        w.flush().map_err(io)
    }

    /// Writes what [`Self::save`] writes to `w` (which it does not flush).
    pub fn write_to<W: Write>(&self, w: &mut W) -> std::io::Result<()> {
        let mut header = Vec::with_capacity(48);
        header.extend_from_slice(MAGIC);
        for v in [self.obs_dim, self.act_dim, self.capacity, self.len, self.next] {
            header.extend_from_slice(&(v as u64).to_le_bytes());
        }
        w.write_all(&header)?;
        let n = self.len;
        let (o, a) = (self.obs_dim, self.act_dim);
        // Converted in chunks of 64 KiB, not a whole column (hundreds of MB at 1M transitions).
        let mut bytes = Vec::with_capacity(1 << 16);
        for (v, cols) in [
            (&self.obs, o),
            (&self.action, a),
            (&self.reward, 1),
            (&self.next_obs, o),
            (&self.done, 1),
            (&self.learner, 1),
            (&self.bc_action, a),
            (&self.bc_mask, 1),
        ] {
            for chunk in v[..n * cols].chunks(1 << 14) {
                bytes.clear();
                for x in chunk {
                    bytes.extend_from_slice(&x.to_le_bytes());
                }
                w.write_all(&bytes)?;
            }
        }
        Ok(())
    }

    /// Reads a buffer written by [`Self::save`]; its shape must match this one's. The file's
    /// length is checked against its header before its data is read, and the data is read
    /// in chunks straight into the buffer (a second copy of a 1M-transition buffer would be
    /// another 650 MB).
    pub fn load(&mut self, path: &Path) -> Result<(), ReplayError> {
        let shown = path.display().to_string();
        let io = |source| ReplayError::Io { path: shown.clone(), source };
        let fmt = |message: String| ReplayError::Format { path: shown.clone(), message };
        let file = std::fs::File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut r = std::io::BufReader::with_capacity(1 << 20, file);
        let mut header = [0u8; 48];
        if file_len < 48 {
            return Err(fmt("not a replay buffer file".to_owned()));
        }
        r.read_exact(&mut header).map_err(io)?;
        if &header[..8] != MAGIC {
            return Err(fmt("not a replay buffer file".to_owned()));
        }
        let word = |k: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&header[8 + 8 * k..16 + 8 * k]);
            u64::from_le_bytes(b) as usize
        };
        let (o, a, cap, len, next) = (word(0), word(1), word(2), word(3), word(4));
        if (o, a, cap) != (self.obs_dim, self.act_dim, self.capacity) || len > cap || next >= cap {
            return Err(fmt(format!(
                "shape obs {o} act {a} capacity {cap} (len {len}) does not match obs {} act {} capacity {}",
                self.obs_dim, self.act_dim, self.capacity
            )));
        }
        let expected = 48 + (len as u64) * ((2 * o + 2 * a + 4) * 4) as u64;
        if file_len != expected {
            return Err(fmt(format!("{file_len} bytes, expected {expected}")));
        }
        let mut bytes = vec![0u8; 1 << 16];
        for (v, cols) in [
            (&mut self.obs, o),
            (&mut self.action, a),
            (&mut self.reward, 1),
            (&mut self.next_obs, o),
            (&mut self.done, 1),
            (&mut self.learner, 1),
            (&mut self.bc_action, a),
            (&mut self.bc_mask, 1),
        ] {
            for chunk in v[..len * cols].chunks_mut(1 << 14) {
                let raw = &mut bytes[..4 * chunk.len()];
                r.read_exact(raw).map_err(io)?;
                for (x, b) in chunk.iter_mut().zip(raw.chunks_exact(4)) {
                    *x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                }
            }
        }
        self.len = len;
        self.next = next;
        Ok(())
    }
}
