//! Reading a file whole, bounded: only a regular file, and only one no longer than its kind
//! of file can be, checked before a byte is read.
//!
//! A config's `base = "/dev/zero"` would otherwise be read until memory runs out, a FIFO
//! would block the reader forever, and a 1 GB file would be read whole before TOML refused
//! it. Every file vge reads whole goes through here (the lab re-exports it), with the bound
//! of its kind.

use std::fs::{File, Metadata};
use std::io::{self, Read};
use std::path::Path;

/// The longest config file (or base) vge reads: the largest of `configs/` is a few kB.
pub const MAX_CONFIG_FILE_LEN: u64 = 4 << 20;

/// The contents of the regular file at `path`, at most `max` bytes. Refused unread, as an
/// `io::Error` of kind `InvalidInput` whose message says why (the caller names the file): a
/// path that is not a regular file (a directory, a FIFO, a device such as `/dev/zero`, a
/// socket), or a file longer than `max`. A file that grows past `max` while it is read is
/// refused as well.
pub fn read_bounded(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    // stat first: opening a FIFO to read would block until a writer comes.
    check_regular(&std::fs::metadata(path)?, max)?;
    let file = open_nonblocking(path)?;
    // The file opened may not be the one stat saw (replaced in between): check it again.
    let meta = file.metadata()?;
    check_regular(&meta, max)?;
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(max.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(too_long(bytes.len() as u64, max, "grew while read; "));
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text (invalid UTF-8 is an `InvalidData` error).
pub fn read_to_string_bounded(path: &Path, max: u64) -> io::Result<String> {
    String::from_utf8(read_bounded(path, max)?)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "stream did not contain valid UTF-8"))
}

fn check_regular(meta: &Metadata, max: u64) -> io::Result<()> {
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("not a regular file ({}): vge reads regular files only (not read)", kind(meta)),
        ));
    }
    if meta.len() > max {
        return Err(too_long(meta.len(), max, ""));
    }
    Ok(())
}

fn too_long(len: u64, max: u64, how: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{len} bytes, more than the {max} bytes a file of its kind may hold ({how}not read)"),
    )
}

/// What a path that is not a regular file is.
fn kind(meta: &Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "a special file"
}

/// Opened for reading without blocking on a FIFO that replaced the file after its stat (on a
/// regular file O_NONBLOCK changes nothing).
fn open_nonblocking(path: &Path) -> io::Result<File> {
    let mut options = File::options();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    options.open(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("vge-bounded-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    #[test]
    fn a_regular_file_within_its_bound_is_read_whole() {
        let dir = temp_dir("ok");
        let path = dir.join("a.toml");
        std::fs::write(&path, "x = 1\n").expect("write");
        assert_eq!(read_to_string_bounded(&path, 6).expect("read"), "x = 1\n");
        let e = read_bounded(&path, 5).expect_err("one byte over");
        assert!(e.to_string().contains("6 bytes, more than the 5"), "{e}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn devices_directories_and_sparse_giants_are_refused_unread() {
        let dir = temp_dir("refused");
        let devices = [(Path::new("/dev/zero"), "a character device"), (dir.as_path(), "a directory")];
        for (path, why) in devices {
            let e = read_bounded(path, MAX_CONFIG_FILE_LEN).expect_err("refused");
            assert!(e.to_string().contains(why) && e.kind() == io::ErrorKind::InvalidInput, "{e}");
        }
        // 1 GB, sparse: refused by its length, so without the time or memory of reading it.
        let big = dir.join("big.toml");
        File::create(&big).expect("create").set_len(1 << 30).expect("set_len");
        let e = read_bounded(&big, MAX_CONFIG_FILE_LEN).expect_err("too long");
        assert!(e.to_string().contains("1073741824 bytes"), "{e}");
        let _ = std::fs::remove_dir_all(dir);
    }
}
