//! The joint limits of the hand the bridge drives: what the safety filter clamps every target
//! to and what the plausibility check holds measured positions against.
//!
//! By default they are those of the hand's description ([`ProtocolHand::limits`]: vge15's
//! `hands/vge15.xml`, the hand the policies are trained on; physics-free, so the CAN-only
//! build has them too). A real hand's come from a hand file (`vge-bridge run --hand FILE`),
//! TOML, one pair per joint of the hand, in its joint order; for vge15:
//!
//! ```toml
//! # Joint limits (rad): 15 [lower, upper] pairs, finger-major (thumb, index, middle, ring,
//! # little), each finger's roll, proximal flexion, distal flexion.
//! joint_limits_rad = [
//!     [-0.5, 0.5], [-0.3, 1.6], [-0.3, 1.6], # thumb
//!     [-0.5, 0.5], [-0.3, 1.6], [-0.3, 1.6], # index
//!     [-0.5, 0.5], [-0.3, 1.6], [-0.3, 1.6], # middle
//!     [-0.5, 0.5], [-0.3, 1.6], [-0.3, 1.6], # ring
//!     [-0.5, 0.5], [-0.3, 1.6], [-0.3, 1.6], # little
//! ]
//! ```
//!
//! Every limit must be finite with lower < upper; an error names the joint
//! (`index.flex_prox`, as the policy's action names do). docs/can-protocol.md, Joint limits.

use std::path::Path;

use serde::Deserialize;
use thiserror::Error;
use vge_hand::JointLimit;

use crate::protocol_hand::ProtocolHand;

/// The limits of all joints of a hand, in its joint order.
pub type JointLimits = Vec<JointLimit>;

/// Why a hand file was refused.
#[derive(Debug, Error)]
pub enum HandFileError {
    #[error("reading the hand file: {0}")]
    Read(#[from] std::io::Error),
    /// Not TOML, a missing or unknown key, or a limit that is not a number.
    #[error("{0}")]
    Syntax(#[from] toml::de::Error),
    #[error("joint_limits_rad lists {got} joints; the hand {hand} has {want}: {names}")]
    JointCount { got: usize, hand: String, want: usize, names: String },
    #[error("joint {index} ({name}): {got} numbers where [lower, upper] (rad) belongs")]
    NotAPair { index: usize, name: String, got: usize },
    #[error("joint {index} ({name}): limits [{lower_rad}, {upper_rad}] rad are not finite")]
    NotFinite { index: usize, name: String, lower_rad: f32, upper_rad: f32 },
    #[error("joint {index} ({name}): lower limit {lower_rad} rad is not below upper limit {upper_rad} rad")]
    Empty { index: usize, name: String, lower_rad: f32, upper_rad: f32 },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct HandFile {
    /// Not `[f32; 2]`: toml would take the first two numbers of a longer list silently.
    joint_limits_rad: Vec<Vec<f32>>,
}

/// The joint limits of the hand file at `path` for `hand`'s joints, validated.
pub fn load_joint_limits(path: &Path, hand: &ProtocolHand) -> Result<JointLimits, HandFileError> {
    parse_joint_limits(&std::fs::read_to_string(path)?, hand)
}

/// The joint limits a hand file's text describes for `hand`'s joints, validated.
pub fn parse_joint_limits(text: &str, hand: &ProtocolHand) -> Result<JointLimits, HandFileError> {
    let file: HandFile = toml::from_str(text)?;
    let got = file.joint_limits_rad.len();
    if got != hand.num_joints() {
        return Err(HandFileError::JointCount {
            got,
            hand: hand.name.clone(),
            want: hand.num_joints(),
            names: hand.joint_names.join(", "),
        });
    }
    let mut limits = Vec::with_capacity(got);
    for (index, pair) in file.joint_limits_rad.into_iter().enumerate() {
        let name = || hand.joint_name(index);
        let &[lower_rad, upper_rad] = pair.as_slice() else {
            return Err(HandFileError::NotAPair { index, name: name(), got: pair.len() });
        };
        if !(lower_rad.is_finite() && upper_rad.is_finite()) {
            return Err(HandFileError::NotFinite { index, name: name(), lower_rad, upper_rad });
        }
        if lower_rad >= upper_rad {
            return Err(HandFileError::Empty { index, name: name(), lower_rad, upper_rad });
        }
        limits.push(JointLimit { lower_rad, upper_rad });
    }
    Ok(limits)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vge15() -> ProtocolHand {
        ProtocolHand::vge15().expect("vge15")
    }

    fn default_joint_limits() -> JointLimits {
        vge15().limits
    }

    fn parse(text: &str) -> Result<JointLimits, HandFileError> {
        parse_joint_limits(text, &vge15())
    }

    /// A hand file with `pairs` as its limits.
    fn file(pairs: &[[&str; 2]]) -> String {
        let rows: Vec<String> = pairs.iter().map(|[l, u]| format!("    [{l}, {u}],\n")).collect();
        format!("# a test hand\njoint_limits_rad = [\n{}]\n", rows.concat())
    }

    fn default_pairs() -> Vec<[&'static str; 2]> {
        (0..15).map(|j| if j % 3 == 0 { ["-0.5", "0.5"] } else { ["-0.3", "1.6"] }).collect()
    }

    #[test]
    fn a_file_with_the_default_hands_limits_gives_them() {
        let limits = parse(&file(&default_pairs())).expect("valid");
        assert_eq!(limits, default_joint_limits());
    }

    #[test]
    fn the_example_in_the_protocol_doc_is_the_default_hand() {
        let doc = include_str!("../../docs/can-protocol.md");
        let start = doc.find("```toml\n").expect("a TOML example") + "```toml\n".len();
        let end = start + doc[start..].find("```").expect("its end");
        assert_eq!(parse(&doc[start..end]).expect("valid"), default_joint_limits());
    }

    #[test]
    fn limits_land_on_their_joints_and_integers_are_numbers() {
        let mut pairs = default_pairs();
        pairs[4] = ["0", "1"];
        pairs[14] = ["-0.25", "0.75"];
        let limits = parse(&file(&pairs)).expect("valid");
        assert_eq!(limits[4], JointLimit { lower_rad: 0.0, upper_rad: 1.0 });
        assert_eq!(limits[14], JointLimit { lower_rad: -0.25, upper_rad: 0.75 });
        assert_eq!(limits[3], JointLimit { lower_rad: -0.5, upper_rad: 0.5 });
    }

    #[test]
    fn a_wrong_joint_count_is_refused() {
        for n in [0, 14, 16] {
            let pairs: Vec<_> = default_pairs().into_iter().cycle().take(n).collect();
            let err = parse(&file(&pairs)).expect_err("wrong count");
            assert!(matches!(err, HandFileError::JointCount { got, .. } if got == n), "{err}");
            assert!(
                err.to_string().contains(&format!("lists {n} joints; the hand vge15 has 15: thumb.roll,")),
                "{err}"
            );
        }
    }

    #[test]
    fn an_empty_or_inverted_range_is_refused_naming_the_joint() {
        for (lower, upper) in [("1.6", "-0.3"), ("0.2", "0.2")] {
            let mut pairs = default_pairs();
            pairs[4] = [lower, upper];
            let err = parse(&file(&pairs)).expect_err("lower >= upper");
            assert!(matches!(err, HandFileError::Empty { index: 4, .. }), "{err}");
            assert!(err.to_string().starts_with("joint 4 (index.flex_prox): lower limit"), "{err}");
        }
    }

    #[test]
    fn nan_and_infinite_limits_are_refused_naming_the_joint() {
        for (lower, upper) in [("nan", "0.5"), ("-0.5", "inf"), ("-inf", "0.5"), ("-0.5", "1e39")] {
            let mut pairs = default_pairs();
            pairs[12] = [lower, upper];
            let err = parse(&file(&pairs)).expect_err("not finite");
            assert!(matches!(err, HandFileError::NotFinite { index: 12, .. }), "{lower} {upper}: {err}");
            assert!(err.to_string().contains("(little.roll)"), "{err}");
        }
    }

    #[test]
    fn a_limit_that_is_not_a_pair_is_refused_naming_the_joint() {
        let text = file(&default_pairs());
        for (pair, got) in [("[-0.5, 0.0, 0.5]", 3), ("[0.5]", 1), ("[]", 0)] {
            let text = text.replacen("[-0.5, 0.5]", pair, 1);
            let err = parse(&text).expect_err("not a pair");
            assert!(matches!(err, HandFileError::NotAPair { index: 0, got: g, .. } if g == got), "{err}");
            assert!(err.to_string().starts_with("joint 0 (thumb.roll):"), "{err}");
        }
    }

    #[test]
    fn malformed_files_are_refused() {
        for text in [
            "not toml at all [".to_owned(),
            String::new(),
            "joint_limit_rad = []".to_owned(),
            file(&default_pairs()) + "extra = 1\n",
            file(&default_pairs()).replacen("[-0.5, 0.5]", "[-0.5, \"0.5\"]", 1),
            file(&default_pairs()).replacen("[-0.5, 0.5]", "-0.5", 1),
        ] {
            let err = parse(&text).expect_err("malformed");
            assert!(matches!(err, HandFileError::Syntax(_)), "{text}: {err}");
        }
    }

    #[test]
    fn a_missing_file_is_a_read_error() {
        let err = load_joint_limits(Path::new("/nonexistent/hand.toml"), &vge15()).expect_err("no such file");
        assert!(matches!(err, HandFileError::Read(_)), "{err}");
    }
}
