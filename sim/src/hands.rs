//! The hands that ship with vge, read from their MJCF descriptions in `hands/` (compiled into
//! the binary, so that an installed `vge` needs no checkout), and hands read from a user's file.
//!
//! A hand is named in a config as `hand = "vge15"` (a shipped hand) or as a path to an MJCF
//! file (the TOML beside it, same stem, is read too).

use std::path::Path;
use std::sync::{Arc, OnceLock};

use vge_hand::Hand;

use crate::error::SimError;

/// The shipped hands: name, MJCF text, TOML text.
const SHIPPED: [(&str, &str, &str); 2] = [
    ("vge15", include_str!("../../hands/vge15.xml"), include_str!("../../hands/vge15.toml")),
    ("allegro", include_str!("../../hands/allegro.xml"), include_str!("../../hands/allegro.toml")),
];

/// The names of the shipped hands.
#[must_use]
pub fn shipped_names() -> Vec<&'static str> {
    SHIPPED.iter().map(|(name, _, _)| *name).collect()
}

fn shipped(name: &str) -> Option<Result<Arc<Hand>, SimError>> {
    static CACHE: [OnceLock<Result<Arc<Hand>, SimError>>; SHIPPED.len()] = [OnceLock::new(), OnceLock::new()];
    let i = SHIPPED.iter().position(|(n, _, _)| *n == name)?;
    let (n, xml, toml) = SHIPPED[i];
    Some(
        CACHE[i]
            .get_or_init(|| {
                Hand::from_strs(xml, Some(toml), n)
                    .map(Arc::new)
                    .map_err(|e| SimError::Hand(format!("shipped hand {n}: {e}")))
            })
            .clone(),
    )
}

/// vge's own 15-DOF hand (`hands/vge15.xml`).
pub fn vge15() -> Result<Arc<Hand>, SimError> {
    shipped("vge15").unwrap_or_else(|| Err(SimError::InvalidConfig("no shipped hand vge15".to_owned())))
}

/// A shipped hand by name, or the MJCF file at `spec` when `spec` names a file (it has a
/// path separator or ends in `.xml`). Anything else is refused, naming the shipped hands.
pub fn load(spec: &str) -> Result<Arc<Hand>, SimError> {
    if let Some(hand) = shipped(spec) {
        return hand;
    }
    // A shipped hand also by the model name its file gives (`<mujoco model>`, what a policy
    // file records): `allegro_right` is `allegro`.
    for (name, _, _) in SHIPPED {
        if let Some(Ok(hand)) = shipped(name)
            && hand.name() == spec
        {
            return Ok(hand);
        }
    }
    if spec.contains(std::path::MAIN_SEPARATOR) || spec.contains('/') || spec.ends_with(".xml") {
        return Hand::load(Path::new(spec)).map(Arc::new).map_err(|e| SimError::Hand(e.to_string()));
    }
    Err(SimError::Hand(format!(
        "hand `{spec}`: not a shipped hand ({}) nor a path to an MJCF file (a path has a `/` or ends in .xml)",
        shipped_names().join(", ")
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shipped_hand_loads_by_its_name_or_its_model_name_and_an_unknown_name_is_refused() {
        let allegro = load("allegro").expect("allegro");
        assert_eq!(allegro.name(), "allegro_right");
        assert!(Arc::ptr_eq(&load("allegro_right").expect("by model name"), &allegro));
        let err = load("shadow").expect_err("not shipped");
        assert!(err.to_string().contains("vge15, allegro"), "{err}");
    }
}
