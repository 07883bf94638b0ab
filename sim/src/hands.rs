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
    if spec.contains(std::path::MAIN_SEPARATOR) || spec.contains('/') || spec.ends_with(".xml") {
        return Hand::load(Path::new(spec)).map(Arc::new).map_err(|e| SimError::Hand(e.to_string()));
    }
    Err(SimError::Hand(format!(
        "hand `{spec}`: not a shipped hand ({}) nor a path to an MJCF file (a path has a `/` or ends in .xml)",
        shipped_names().join(", ")
    )))
}
