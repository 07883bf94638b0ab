//! The TOML beside the XML, and the fingers it names: each fingertip is a site or a body, each
//! finger the joints on the path from the root to its fingertip.

use serde::Deserialize;

use nalgebra::Vector3;

use crate::error::HandError;
use crate::mjcf::Parsed;
use crate::model::{Finger, GeomShape};

/// Sites whose name starts with this are the fingertips of a hand without a TOML (or whose
/// TOML names none), in file order.
pub const FINGERTIP_SITE_PREFIX: &str = "fingertip";

/// What the TOML may say; every key is optional, and an unknown key is refused.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Spec {
    /// Site or body names, one per finger, in finger order.
    pub(crate) fingertips: Option<Vec<String>>,
    /// The fingers' names, in the same order.
    pub(crate) finger_names: Option<Vec<String>>,
    /// The palm's body name.
    pub(crate) palm: Option<String>,
    /// The keyframe that is the hand's start grasp.
    pub(crate) start_grasp: Option<String>,
    /// The width of the object the hand is sized for (m): a cube's side.
    pub(crate) object_width_m: Option<f32>,
    /// That object's mass (kg).
    pub(crate) object_mass_kg: Option<f32>,
}

impl Spec {
    pub(crate) fn parse(text: &str, file: &str) -> Result<Self, HandError> {
        toml::from_str(text).map_err(|e| HandError::Spec { file: file.to_owned(), message: e.to_string() })
    }
}

/// What the TOML resolves to in the model.
#[derive(Debug)]
pub(crate) struct Resolved {
    pub(crate) fingers: Vec<Finger>,
    pub(crate) palm: Option<usize>,
    pub(crate) start_grasp: Option<usize>,
    pub(crate) nominal_object: Option<NominalObject>,
}

/// The object a hand is sized for, as its TOML gives it: the task's default object is a cube
/// of this width and mass, and the other shapes share its width.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NominalObject {
    /// Width (m): a cube's side, twice the inradius of the other shapes.
    pub width_m: f32,
    /// Mass (kg).
    pub mass_kg: f32,
}

/// Where a fingertip name points.
enum Tip {
    Site(usize),
    Body(usize),
}

pub(crate) fn resolve(
    parsed: &Parsed,
    spec: &Spec,
    spec_file: &str,
    xml_file: &str,
) -> Result<Resolved, HandError> {
    let spec_error = |message: String| HandError::Spec { file: spec_file.to_owned(), message };
    let tips: Vec<String> = match &spec.fingertips {
        Some(tips) => tips.clone(),
        None => {
            let by_rule: Vec<String> = parsed
                .sites
                .iter()
                .filter_map(|s| s.name.clone())
                .filter(|n| n.starts_with(FINGERTIP_SITE_PREFIX))
                .collect();
            if by_rule.is_empty() {
                return Err(HandError::Spec {
                    file: xml_file.to_owned(),
                    message: format!(
                        "no fingertips: name them in `fingertips = [...]` in a TOML beside the XML (same \
                         stem), or name the fingertip sites `{FINGERTIP_SITE_PREFIX}...`"
                    ),
                });
            }
            by_rule
        }
    };
    if tips.is_empty() {
        return Err(spec_error("`fingertips` is empty".to_owned()));
    }
    let names = match &spec.finger_names {
        Some(names) if names.len() != tips.len() => {
            return Err(spec_error(format!("{} finger_names for {} fingertips", names.len(), tips.len())));
        }
        Some(names) => names.clone(),
        None => tips.clone(),
    };
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            return Err(spec_error(format!("finger `{name}` is named twice")));
        }
    }
    let mut paths = Vec::with_capacity(tips.len());
    for tip in &tips {
        paths.push(path_to(parsed, tip, &spec_error)?);
    }
    check_ownership(parsed, &paths, &names)?;
    let mut fingers = Vec::with_capacity(tips.len());
    for ((tip, name), path) in tips.iter().zip(&names).zip(paths) {
        fingers.push(finger(parsed, tip, name, path)?);
    }
    for pair in fingers.windows(2) {
        if let [a, b] = pair
            && b.joints.start < a.joints.start
        {
            return Err(spec_error(format!(
                "finger `{}` (joints {:?}) is listed after `{}` (joints {:?}): list the fingers in the \
                 order of their joints in the file, so that the joint vector is MuJoCo's qpos",
                b.name, b.joints, a.name, a.joints
            )));
        }
    }
    let palm = spec
        .palm
        .as_ref()
        .map(|p| body_named(parsed, p).ok_or_else(|| spec_error(format!("palm: no body named `{p}`"))))
        .transpose()?;
    let start_grasp = spec
        .start_grasp
        .as_ref()
        .map(|k| {
            let mut found = parsed
                .keyframes
                .iter()
                .enumerate()
                .filter(|(_, key)| key.name.as_deref() == Some(k.as_str()));
            match (found.next(), found.next()) {
                (Some((i, _)), None) => Ok(i),
                (None, _) => Err(spec_error(format!("start_grasp: no keyframe named `{k}`"))),
                (Some(_), Some(_)) => Err(spec_error(format!("start_grasp: two keyframes are named `{k}`"))),
            }
        })
        .transpose()?;
    let nominal_object = match (spec.object_width_m, spec.object_mass_kg) {
        (None, None) => None,
        (Some(width_m), Some(mass_kg)) => {
            let ok = |v: f32, max: f32| v.is_finite() && v > 0.0 && v <= max;
            if !ok(width_m, 0.3) || !ok(mass_kg, 10.0) {
                return Err(spec_error(format!(
                    "object_width_m = {width_m}, object_mass_kg = {mass_kg}: need 0 < width <= 0.3 m and 0 < mass <= 10 kg"
                )));
            }
            Some(NominalObject { width_m, mass_kg })
        }
        _ => {
            return Err(spec_error(
                "object_width_m and object_mass_kg go together: set both or neither".to_owned(),
            ));
        }
    };
    Ok(Resolved { fingers, palm, start_grasp, nominal_object })
}

fn body_named(parsed: &Parsed, name: &str) -> Option<usize> {
    parsed.bodies.iter().position(|b| b.name.as_deref() == Some(name))
}

/// A fingertip's body, its point in that body, and the joints on its path from the root.
struct Path {
    tip_body: usize,
    offset: Vector3<f32>,
    joints: Vec<usize>,
}

fn path_to(parsed: &Parsed, tip: &str, spec_error: &dyn Fn(String) -> HandError) -> Result<Path, HandError> {
    let site = parsed.sites.iter().position(|s| s.name.as_deref() == Some(tip));
    let body = body_named(parsed, tip);
    let found = match (site, body) {
        (Some(s), None) => Tip::Site(s),
        (None, Some(b)) => Tip::Body(b),
        (Some(_), Some(_)) => {
            return Err(spec_error(format!("fingertip `{tip}` names both a site and a body; rename one")));
        }
        (None, None) => return Err(spec_error(format!("fingertip `{tip}` is neither a site nor a body"))),
    };
    let (tip_body, offset) = match found {
        Tip::Site(s) => {
            let site = &parsed.sites[s];
            (site.body, site.pose_in_body.translation.vector)
        }
        Tip::Body(b) => (b, Vector3::zeros()),
    };
    // The joints on the path, root first: each body's joints are contiguous, ancestors' first.
    let mut ranges = Vec::new();
    let mut body = Some(tip_body);
    while let Some(b) = body {
        ranges.push(parsed.bodies[b].joints.clone());
        body = parsed.bodies[b].parent;
    }
    ranges.reverse();
    let joints: Vec<usize> = ranges.into_iter().flatten().collect();
    if joints.is_empty() {
        return Err(spec_error(format!("fingertip `{tip}` has no joint on its path from the root")));
    }
    Ok(Path { tip_body, offset, joints })
}

fn finger(parsed: &Parsed, tip: &str, name: &str, path: Path) -> Result<Finger, HandError> {
    let (first, last) = match (path.joints.first(), path.joints.last()) {
        (Some(&first), Some(&last)) => (first, last),
        _ => (0, 0),
    };
    if last + 1 - first != path.joints.len() {
        // A joint of another finger lies between two of this finger's. With bodies numbered depth
        // first and every joint owned once (checked before), this cannot happen; kept so that a
        // change to either cannot make the joint vector silently differ from MuJoCo's qpos.
        let gap = (first..=last).find(|j| !path.joints.contains(j)).unwrap_or(first);
        return Err(HandError::Invalid {
            at: parsed.joint_at[gap].clone(),
            message: format!(
                "joint `{}` lies between joints of finger `{name}` in the file, so that finger's joints are \
                 not contiguous in the joint vector: write each finger's bodies together",
                parsed.joints[gap].name
            ),
        });
    }
    Ok(Finger {
        name: name.to_owned(),
        tip_name: tip.to_owned(),
        joints: first..last + 1,
        tip_body: path.tip_body,
        tip_offset_in_body_m: path.offset,
        tip_geom: tip_geom(parsed, path.tip_body, &path.offset),
        tip_radius_m: tip_geom(parsed, path.tip_body, &path.offset).and_then(|g| {
            match parsed.bodies[path.tip_body].geoms[g].shape {
                GeomShape::Sphere { radius_m } | GeomShape::Capsule { radius_m, .. } => Some(radius_m),
                _ => None,
            }
        }),
    })
}

/// Every hinge joint moves exactly one finger.
fn check_ownership(parsed: &Parsed, paths: &[Path], names: &[String]) -> Result<(), HandError> {
    for (j, joint) in parsed.joints.iter().enumerate() {
        let owners: Vec<&str> =
            paths.iter().zip(names).filter(|(p, _)| p.joints.contains(&j)).map(|(_, n)| n.as_str()).collect();
        let message = match owners.as_slice() {
            [_] => continue,
            [] => format!(
                "joint `{}` is on no finger's path: every hinge joint must move one finger (a wrist or arm \
                 joint is outside a hand)",
                joint.name
            ),
            [a, b, ..] => format!(
                "joint `{}` is on the paths of fingers `{a}` and `{b}`: a joint must move one finger only",
                joint.name
            ),
        };
        return Err(HandError::Invalid { at: parsed.joint_at[j].clone(), message });
    }
    Ok(())
}

/// The tip body's colliding sphere or capsule nearest the fingertip point (its index in the
/// body's geoms); of two as near (a link capsule ending where the tip sphere is centred), the
/// larger, which is what touches first.
fn tip_geom(parsed: &Parsed, body: usize, tip: &Vector3<f32>) -> Option<usize> {
    parsed.bodies[body]
        .geoms
        .iter()
        .enumerate()
        .filter(|(_, g)| g.collides())
        .filter_map(|(i, g)| {
            let centre = g.pose_in_body.translation.vector;
            match g.shape {
                GeomShape::Sphere { radius_m } => Some(((tip - centre).norm(), radius_m, i)),
                GeomShape::Capsule { radius_m, half_length_m } => {
                    let axis = g.pose_in_body.rotation * Vector3::z();
                    let along = (tip - centre).dot(&axis).clamp(-half_length_m, half_length_m);
                    Some(((tip - (centre + axis * along)).norm(), radius_m, i))
                }
                _ => None,
            }
        })
        .min_by(|a, b| a.0.total_cmp(&b.0).then(b.1.total_cmp(&a.1)))
        .map(|(_, _, i)| i)
}
