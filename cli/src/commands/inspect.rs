//! `vge inspect`: what a policy file holds, and whether it is valid.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;

/// Check a policy file and print what it holds: format version, dimensions, layers,
/// parameter count, provenance, checksum status. Exits non-zero if it is not valid.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// The policy file.
    file: PathBuf,
}

/// `vge inspect`.
pub fn run(args: InspectArgs) -> anyhow::Result<()> {
    let InspectArgs { file } = args;
    let report = vge_export::inspect::report_file(&file)
        .with_context(|| format!("reading policy file {}", file.display()))?;
    print!("{report}");
    if !report.is_valid() {
        bail!("{} is not a valid policy file", file.display());
    }
    Ok(())
}
