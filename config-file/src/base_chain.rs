//! A config file built on another: `base = "FILE"`, relative to the file's own folder. The
//! config is then its base with the keys it sets replaced (tables merge key by key, any other
//! value replaces the base's whole), so a grid or variant config states only what sets it
//! apart. The lab's configs and the Python package's `[env]` reader both read files here, so
//! a file means the same to both.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// The top-level key that names the file a config builds on.
pub const BASE_KEY: &str = "base";

/// Bases of bases, at most this many: a longer chain is a mistake.
pub const MAX_BASE_CHAIN: usize = 8;

/// Why a config file and its bases cannot be read into one table.
#[derive(Debug, Error)]
pub enum BaseChainError {
    /// A file of the chain that cannot be read.
    #[error("reading config {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Not TOML, a `base` that is not a file name, a loop, or too long a chain.
    #[error("parsing config {path}: {message}")]
    Parse {
        /// The file whose text or `base` is wrong.
        path: String,
        /// What is wrong.
        message: String,
    },
}

/// The TOML table of the config file at `path` with its `base` (and the base's base, ...)
/// merged under it. `each_file` sees every file's own table, named by its path, before the
/// merge: the lab moves a file's `[learner]` to its canonical place there, so that a file's
/// spelling is checked within the file.
pub fn read_with_bases<E: From<BaseChainError>>(
    path: &Path,
    each_file: &mut impl FnMut(&mut toml::Table, &str) -> Result<(), E>,
) -> Result<toml::Table, E> {
    read_chain(path, &mut Vec::new(), each_file)
}

fn read_chain<E: From<BaseChainError>>(
    path: &Path,
    chain: &mut Vec<PathBuf>,
    each_file: &mut impl FnMut(&mut toml::Table, &str) -> Result<(), E>,
) -> Result<toml::Table, E> {
    let shown = path.display().to_string();
    // Bounded: a base of /dev/zero, a FIFO or a 1 GB file is refused before it is read.
    let text = crate::read_to_string_bounded(path, crate::MAX_CONFIG_FILE_LEN)
        .map_err(|source| BaseChainError::Io { path: shown.clone(), source })?;
    let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| BaseChainError::Parse {
        path: shown.clone(),
        message: e.to_string(),
    })?;
    each_file(&mut table, &shown)?;
    let Some(base) = table.remove(BASE_KEY) else {
        return Ok(table);
    };
    let refuse = |message: String| BaseChainError::Parse { path: shown.clone(), message };
    let base = base.as_str().ok_or_else(|| {
        refuse(format!("`{BASE_KEY}` names a file, as a string; got a {}", base.type_str()))
    })?;
    let base_path = path.parent().unwrap_or(Path::new(".")).join(base);
    // The file was just read, so it exists; a base that does not is reported by its read.
    chain.push(path.canonicalize().unwrap_or_else(|_| path.to_owned()));
    let canonical = base_path.canonicalize().unwrap_or_else(|_| base_path.clone());
    if chain.contains(&canonical) {
        return Err(refuse(format!(
            "`{BASE_KEY}` {} is a config this one is already built on",
            base_path.display()
        ))
        .into());
    }
    if chain.len() > MAX_BASE_CHAIN {
        return Err(refuse(format!("more than {MAX_BASE_CHAIN} bases in a chain")).into());
    }
    let mut merged = read_chain(&base_path, chain, each_file)?;
    merge_table(&mut merged, table);
    Ok(merged)
}

/// `over`'s keys into `base`: tables merge key by key, other values replace.
fn merge_table(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_table(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("vge-base-chain-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    fn read(path: &Path) -> Result<toml::Table, BaseChainError> {
        read_with_bases(path, &mut |_, _| Ok::<(), BaseChainError>(()))
    }

    #[test]
    fn a_file_is_its_base_with_its_own_keys_tables_merged_key_by_key() {
        let dir = temp_dir("merge");
        std::fs::create_dir_all(dir.join("sub")).expect("sub");
        std::fs::write(dir.join("a.toml"), "x = 1\nlist = [1, 2]\n[env]\nk = 1\nm = 2\n").expect("a");
        std::fs::write(dir.join("sub/b.toml"), "base = \"../a.toml\"\nlist = [3]\n[env]\nm = 5\n")
            .expect("b");
        let merged = read(&dir.join("sub/b.toml")).expect("chain");
        let expected: toml::Table = "x = 1\nlist = [3]\n[env]\nk = 1\nm = 5\n".parse().expect("toml");
        assert_eq!(merged, expected);
    }

    #[test]
    fn every_file_of_the_chain_passes_the_hook_before_the_merge() {
        let dir = temp_dir("hook");
        std::fs::write(dir.join("a.toml"), "x = 1\n").expect("a");
        std::fs::write(dir.join("b.toml"), "base = \"a.toml\"\ny = 2\n").expect("b");
        let mut seen = Vec::new();
        read_with_bases(&dir.join("b.toml"), &mut |table: &mut toml::Table, path: &str| {
            seen.push((path.rsplit('/').next().unwrap_or_default().to_owned(), table.len()));
            Ok::<(), BaseChainError>(())
        })
        .expect("chain");
        assert_eq!(seen, [("b.toml".to_owned(), 2), ("a.toml".to_owned(), 1)]);
    }

    #[test]
    fn loops_long_chains_missing_bases_and_non_string_bases_are_refused_naming_the_file() {
        let dir = temp_dir("refuse");
        std::fs::write(dir.join("a.toml"), "base = \"b.toml\"\n").expect("a");
        std::fs::write(dir.join("b.toml"), "base = \"a.toml\"\n").expect("b");
        let e = read(&dir.join("a.toml")).expect_err("loop").to_string();
        assert!(e.contains("already built on") && e.contains("b.toml"), "{e}");

        for i in 0..=MAX_BASE_CHAIN + 1 {
            let text =
                if i == MAX_BASE_CHAIN + 1 { String::new() } else { format!("base = \"c{}.toml\"\n", i + 1) };
            std::fs::write(dir.join(format!("c{i}.toml")), text).expect("chain file");
        }
        let e = read(&dir.join("c0.toml")).expect_err("long").to_string();
        assert!(e.contains("more than 8 bases"), "{e}");
        read(&dir.join("c1.toml")).expect("a chain of exactly the bound is read");

        std::fs::write(dir.join("m.toml"), "base = \"missing.toml\"\n").expect("m");
        let e = read(&dir.join("m.toml")).expect_err("missing").to_string();
        assert!(e.contains("missing.toml"), "{e}");

        std::fs::write(dir.join("n.toml"), "base = 3\n").expect("n");
        let e = read(&dir.join("n.toml")).expect_err("number").to_string();
        assert!(e.contains("n.toml") && e.contains("as a string"), "{e}");
    }

    /// A base that is a device, a FIFO or a file longer than any config is refused before a
    /// byte of it is read, naming it: nothing blocks, nothing is read whole.
    #[test]
    fn a_base_of_dev_zero_a_fifo_or_a_giant_is_refused_unread_naming_it() {
        let dir = temp_dir("bounded");
        let fifo = dir.join("fifo.toml");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
        assert!(made.success());
        let big = dir.join("big.toml");
        std::fs::File::create(&big).expect("create").set_len(1 << 30).expect("sparse 1 GB");
        for (base, why) in [
            ("/dev/zero".to_owned(), "a character device"),
            (fifo.display().to_string(), "a FIFO"),
            (big.display().to_string(), "1073741824 bytes"),
        ] {
            std::fs::write(dir.join("c.toml"), format!("base = \"{base}\"\n")).expect("c");
            let e = read(&dir.join("c.toml")).expect_err(&base).to_string();
            assert!(e.contains(&base) && e.contains(why) && e.contains("not read"), "{e}");
        }
        // The file named on the command line is bounded the same way.
        let e = read(Path::new("/dev/zero")).expect_err("device").to_string();
        assert!(e.contains("/dev/zero") && e.contains("a character device"), "{e}");
    }
}
