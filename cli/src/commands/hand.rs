//! `vge hand`: what vge reads from a hand's description.

use anyhow::Context;
use clap::{Args, Subcommand};
use vge_hand::Hand;
use vge_sim::{ObservationLayout, ObservationSet};

/// Read a hand's description (an MJCF file and the TOML beside it) as the simulator does.
#[derive(Debug, Args)]
pub struct HandArgs {
    #[command(subcommand)]
    command: HandCommand,
}

#[derive(Debug, Subcommand)]
enum HandCommand {
    /// Print a hand's fingers, joints (ranges, position servos), fingertips and start grasp,
    /// or the error that refuses it (the element and its line). Exits non-zero if refused.
    Inspect {
        /// A shipped hand's name (`vge15`, `allegro`) or the path of an MJCF file; the TOML of
        /// the same stem beside it names fingertips, finger order, palm and start grasp.
        hand: String,
    },
}

/// `vge hand`.
pub fn run(args: HandArgs) -> anyhow::Result<()> {
    match args.command {
        HandCommand::Inspect { hand } => {
            let description = vge_sim::hands::load(&hand).with_context(|| format!("reading hand {hand}"))?;
            print!("{}", summary(&description));
            Ok(())
        }
    }
}

fn range_text(r: Option<[f32; 2]>) -> String {
    r.map_or_else(|| "-".to_owned(), |[lo, hi]| format!("{lo:+.3}..{hi:+.3}"))
}

/// The summary `vge hand inspect` prints.
fn summary(hand: &Hand) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let sha: String = hand.description_sha256().iter().take(8).map(|b| format!("{b:02x}")).collect();
    let (n, f) = (hand.num_joints(), hand.num_fingers());
    let _ = writeln!(out, "hand {} (description sha256 {sha}...): {n} joints, {f} fingers", hand.name());
    let size = |set| ObservationLayout::new(set, n, f).dim();
    let _ = writeln!(
        out,
        "observation: full {} floats (with fingertip contacts), proprio {} floats (joints only); action {n} floats",
        size(ObservationSet::Full),
        size(ObservationSet::Proprio { history: 0 })
    );
    let _ = writeln!(out, "fingers:");
    for finger in hand.fingers() {
        let joints = &hand.joints()[finger.joints.clone()];
        let names: Vec<&str> = joints.iter().map(|j| j.name.as_str()).collect();
        let radius = finger
            .tip_radius_m
            .map_or_else(|| "no tip sphere".to_owned(), |r| format!("tip radius {:.1} mm", 1e3 * r));
        let _ = writeln!(
            out,
            "  {:<8} fingertip {:<10} {radius}; joints {}",
            finger.name,
            finger.tip_name,
            names.join(", ")
        );
    }
    let _ = writeln!(out, "joints (kv: the servo's damping; damping: the joint's own):");
    let w = hand.joints().iter().map(|j| j.name.len()).max().unwrap_or(4).max(4);
    let _ = writeln!(
        out,
        "  {:>3}  {:<w$} {:<17} {:>8} {:>8} {:>8} {:>17}",
        "#", "name", "range (rad)", "kp", "kv", "damping", "torque (N m)"
    );
    for (i, joint) in hand.joints().iter().enumerate() {
        let range = range_text(joint.limit.map(|l| [l.lower_rad, l.upper_rad]));
        let (kp, kv, force) = match &joint.servo {
            Some(s) => (
                format!("{:.3}", s.kp_nm_per_rad),
                format!("{:.3}", s.kv_nms_per_rad),
                range_text(s.force_range_nm),
            ),
            None => ("-".to_owned(), "-".to_owned(), "no actuator".to_owned()),
        };
        let damping = format!("{:.3}", joint.damping_nms_per_rad);
        let _ = writeln!(
            out,
            "  {i:>3}  {:<w$} {range:<17} {kp:>8} {kv:>8} {damping:>8} {force:>17}",
            joint.name
        );
    }
    match hand.start_grasp_rad() {
        Some(q) => {
            let values: Vec<String> = q.iter().map(|v| format!("{v:.3}")).collect();
            let _ = writeln!(out, "start grasp: {}", values.join(" "));
        }
        None => {
            let _ = writeln!(out, "start grasp: none (the fingers close on the object)");
        }
    }
    out
}
