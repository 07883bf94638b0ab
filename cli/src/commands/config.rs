//! `vge config`: a config as training reads it.

use std::path::PathBuf;

use clap::{Args, Subcommand};

/// Show a config as training reads it
#[derive(Debug, Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    command: ConfigCommand,
}

#[derive(Debug, Subcommand)]
enum ConfigCommand {
    /// Print FILE resolved (its base chain merged, the --set overrides applied, every key at
    /// its value) as the TOML a run folder stores, then `# hash HEX`: the hash a run is
    /// resumed and compared by.
    Show {
        file: PathBuf,
        /// Override a key, e.g. `--set sac.batch=128` (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
    },
}

/// `vge config`.
pub fn run(args: ConfigArgs) -> anyhow::Result<()> {
    let ConfigCommand::Show { file, overrides } = args.command;
    let config = vge_run::config::load_config(&file, &overrides)?;
    config.validate()?;
    print!("{}", config.to_toml_string()?);
    println!("# hash {}", config.hash_hex());
    Ok(())
}
