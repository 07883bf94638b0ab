//! TensorBoard event files for scalar curves, written directly: a TFRecord stream of
//! `tensorflow.Event` protobufs. The Rust crates that write them (tensorboard-rs,
//! syntaxdot-summary) have not been maintained since 2021-22, and scalars need only a few
//! protobuf fields, so this is the format by hand (about a hundred lines).
//!
//! Record framing (TFRecord): `u64 length`, `u32 masked_crc32c(length)`, `data`,
//! `u32 masked_crc32c(data)`, all little-endian. The first event carries
//! `file_version = "brain.Event:2"`; a resumed run writes a `SessionLog START` event at its
//! step, which makes TensorBoard drop the previous session's points past that step (those
//! the metrics CSV also truncates).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// Appends scalar events to one `events.out.tfevents.*` file.
#[derive(Debug)]
pub struct EventWriter {
    path: PathBuf,
    out: BufWriter<File>,
}

impl EventWriter {
    /// Creates `dir/events.out.tfevents.<unix seconds>.vge<suffix>` (the directory too) and
    /// writes the file-version event. `suffix` keeps two sessions of one run apart when
    /// they start within the same second.
    pub fn create(dir: &Path, suffix: &str) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let now = wall_time();
        let path = dir.join(format!("events.out.tfevents.{}.vge{suffix}", now as u64));
        let out = BufWriter::new(File::options().create_new(true).write(true).open(&path)?);
        let mut w = Self { path, out };
        let mut event = event_header(now, 0);
        put_bytes(&mut event, 3, b"brain.Event:2");
        w.write_record(&event)?;
        w.out.flush()?;
        Ok(w)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A session resumed from a checkpoint at `step`: TensorBoard discards the earlier
    /// sessions' events after `step` (it drops those at or after a START event's step, so
    /// the event is placed at `step + 1`).
    pub fn session_start(&mut self, step: u64) -> std::io::Result<()> {
        let mut event = event_header(wall_time(), step + 1);
        let mut session_log = Vec::new();
        put_varint_field(&mut session_log, 1, 1); // status = START
        put_bytes(&mut event, 7, &session_log);
        self.write_record(&event)?;
        self.out.flush()
    }

    /// One event holding `values` (tag, value) at `step`; flushed, so a killed run loses
    /// nothing it logged.
    pub fn scalars<S: AsRef<str>>(&mut self, step: u64, values: &[(S, f64)]) -> std::io::Result<()> {
        let mut summary = Vec::new();
        for (tag, value) in values {
            let mut v = Vec::new();
            put_bytes(&mut v, 1, tag.as_ref().as_bytes());
            v.push((2 << 3) | 5); // simple_value: float, fixed32
            v.extend_from_slice(&(*value as f32).to_le_bytes());
            put_bytes(&mut summary, 1, &v);
        }
        let mut event = event_header(wall_time(), step);
        put_bytes(&mut event, 5, &summary);
        self.write_record(&event)?;
        self.out.flush()
    }

    fn write_record(&mut self, data: &[u8]) -> std::io::Result<()> {
        let len = (data.len() as u64).to_le_bytes();
        self.out.write_all(&len)?;
        self.out.write_all(&masked_crc32c(&len).to_le_bytes())?;
        self.out.write_all(data)?;
        self.out.write_all(&masked_crc32c(data).to_le_bytes())
    }
}

fn wall_time() -> f64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

/// `Event.wall_time` (field 1, double) and `Event.step` (field 2, int64).
fn event_header(wall_time: f64, step: u64) -> Vec<u8> {
    let mut e = vec![(1 << 3) | 1];
    e.extend_from_slice(&wall_time.to_le_bytes());
    put_varint_field(&mut e, 2, step);
    e
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_varint_field(out: &mut Vec<u8>, field: u64, v: u64) {
    put_varint(out, field << 3);
    put_varint(out, v);
}

/// A length-delimited field (strings, bytes, embedded messages).
fn put_bytes(out: &mut Vec<u8>, field: u64, bytes: &[u8]) {
    put_varint(out, (field << 3) | 2);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), bitwise: records are small and
/// written every few thousand steps.
pub fn crc32c(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0x82f6_3b78 } else { crc >> 1 };
        }
    }
    !crc
}

/// TFRecord's mask: rotate right by 15 and add a constant.
pub fn masked_crc32c(data: &[u8]) -> u32 {
    crc32c(data).rotate_right(15).wrapping_add(0xa282_ead8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_matches_the_published_check_value() {
        // RFC 3720 (iSCSI) and every CRC catalogue: CRC-32C("123456789") = 0xE3069283.
        assert_eq!(crc32c(b"123456789"), 0xe306_9283);
        // 32 bytes of zeros, RFC 3720 B.4.
        assert_eq!(crc32c(&[0u8; 32]), 0x8a91_36aa);
    }

    #[test]
    fn varints_encode_as_protobuf_does() {
        let enc = |v| {
            let mut out = Vec::new();
            put_varint(&mut out, v);
            out
        };
        assert_eq!(enc(1), vec![1]);
        assert_eq!(enc(300), vec![0xac, 0x02]);
        assert_eq!(enc(u64::MAX).len(), 10);
    }
}
