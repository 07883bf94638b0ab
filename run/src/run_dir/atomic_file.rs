//! Files of a run folder written whole or not at all: the bytes go to `NAME.tmp` beside the
//! file, are synced to disk, and are renamed over `NAME`; then the folder is synced, so that
//! the rename itself survives a power cut. A kill or a full disk at any moment leaves the
//! previous `NAME` as it was (and at worst a stale `NAME.tmp`, replaced by the next write).
//!
//! Hand-written rather than `tempfile::NamedTempFile::persist` for the fixed temporary name:
//! a run folder has one writer at a time ([`super::lock`]), so a fixed name is safe, and a
//! write killed midway leaves one recognisable `NAME.tmp` that the next write replaces, not a
//! random name per kill.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// `NAME.tmp` beside `path`.
pub fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".tmp");
    path.with_file_name(name)
}

/// Writes `bytes` to `path` through [`tmp_path`], synced and renamed into place (module
/// docs). On an error (`ENOSPC`, say) the temporary file is removed and `path` is untouched;
/// the error is the OS's.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = tmp_path(path);
    let written = (|| {
        let mut file = File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()
    })();
    if let Err(e) = written {
        // The temporary file is all there is to undo; its removal failing changes nothing.
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path)?;
    sync_dir(path.parent().unwrap_or(Path::new(".")))
}

/// Syncs a folder's entries (the renames and creations in it) to disk.
pub fn sync_dir(dir: &Path) -> std::io::Result<()> {
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    File::open(dir)?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_replaces_the_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("vge-atomic-file-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join(crate::run_dir::METRICS);
        write(&path, b"a\n").expect("first");
        // A stale temporary of a killed write is replaced.
        std::fs::write(tmp_path(&path), b"partial").expect("stale");
        write(&path, b"b\n").expect("second");
        assert_eq!(std::fs::read(&path).expect("read"), b"b\n");
        assert!(!tmp_path(&path).exists());
        assert_eq!(tmp_path(&path), dir.join("metrics.csv.tmp"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
