//! Fixed-point fields: physical values scaled to little-endian integers, range-checked.

use super::ProtocolError;

/// One count of a joint angle: 1e-4 rad (range -3.2768 to 3.2767 rad).
pub const ANGLE_RAD_PER_COUNT: f32 = 1e-4;
/// One count of a joint velocity: 1e-3 rad/s (range -32.768 to 32.767 rad/s).
pub const VELOCITY_RADPS_PER_COUNT: f32 = 1e-3;
/// One count of a joint torque: 1e-4 N·m (range -3.2768 to 3.2767 N·m; the motors cap at 0.45 N·m).
pub const EFFORT_NM_PER_COUNT: f32 = 1e-4;
/// One count of a contact position: 1e-4 m (range -3.2768 to 3.2767 m in the hand frame).
pub const POSITION_M_PER_COUNT: f32 = 1e-4;
/// One count of a contact force magnitude: 1e-3 N (range 0..65.535 N).
pub const FORCE_N_PER_COUNT: f32 = 1e-3;
/// One count of a unit-normal component: 1/32767.
pub const NORMAL_PER_COUNT: f32 = 1.0 / 32767.0;

/// The whole i16 range, i16::MIN included: every count a decoder reads must encode again
/// (the FD transport splits a received frame into classic messages by re-encoding them).
pub(crate) fn to_i16(what: &'static str, value: f32, scale: f32) -> Result<i16, ProtocolError> {
    let (min, max) = (f32::from(i16::MIN) * scale, f32::from(i16::MAX) * scale);
    if !value.is_finite() || !(min..=max).contains(&value) {
        return Err(ProtocolError::OutOfRange { what, value, min, max });
    }
    Ok(libm_round(value / scale) as i16)
}

pub(crate) fn to_u16(what: &'static str, value: f32, scale: f32) -> Result<u16, ProtocolError> {
    let max = f32::from(u16::MAX) * scale;
    if !value.is_finite() || !(0.0..=max).contains(&value) {
        return Err(ProtocolError::OutOfRange { what, value, min: 0.0, max });
    }
    Ok(libm_round(value / scale) as u16)
}

/// Round half away from zero without std (`f32::round` needs std).
fn libm_round(x: f32) -> f32 {
    let t = x as i32 as f32; // truncation toward zero; |x| <= 65535 here
    let frac = x - t;
    if frac >= 0.5 {
        t + 1.0
    } else if frac <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

pub(crate) fn put_i16x3(data: &mut [u8; 8], values: [i16; 3]) {
    for (chunk, v) in data.chunks_exact_mut(2).zip(values) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
}

pub(crate) fn get_i16(data: &[u8; 8], at: usize) -> i16 {
    i16::from_le_bytes([data[at], data[at + 1]])
}

pub(crate) fn get_i16x3(data: &[u8; 8]) -> [i16; 3] {
    [get_i16(data, 0), get_i16(data, 2), get_i16(data, 4)]
}

pub(crate) fn scaled3(what: &'static str, values: [f32; 3], scale: f32) -> Result<[i16; 3], ProtocolError> {
    Ok([to_i16(what, values[0], scale)?, to_i16(what, values[1], scale)?, to_i16(what, values[2], scale)?])
}

pub(crate) fn unscaled3(counts: [i16; 3], scale: f32) -> [f32; 3] {
    counts.map(|c| f32::from(c) * scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounds_to_nearest_count() {
        assert_eq!(to_i16("x", 0.00015, 1e-4), Ok(2));
        assert_eq!(to_i16("x", -0.00015, 1e-4), Ok(-2));
        assert_eq!(to_i16("x", 0.00014, 1e-4), Ok(1));
        assert_eq!(to_u16("f", 65.535, 1e-3), Ok(65535));
        assert!(to_u16("f", -0.1, 1e-3).is_err());
        assert!(to_i16("x", f32::INFINITY, 1e-4).is_err());
        // Every count decodes to a value that encodes to the same count, the extremes too.
        for count in [i16::MIN, -1, 0, 1, i16::MAX] {
            for scale in [ANGLE_RAD_PER_COUNT, VELOCITY_RADPS_PER_COUNT, NORMAL_PER_COUNT] {
                assert_eq!(to_i16("x", f32::from(count) * scale, scale), Ok(count), "{count} x {scale}");
            }
        }
        assert!(to_i16("x", (f32::from(i16::MIN) - 1.0) * 1e-4, 1e-4).is_err());
    }
}
