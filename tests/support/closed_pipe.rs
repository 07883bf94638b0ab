//! A command run with one output stream a pipe whose reader was closed before it started, so
//! that its first write there meets EPIPE every time: the closed-pipe tests of `vge` and
//! `vge-bridge` (each includes this file).

use std::io::Read;
use std::process::{Command, Stdio};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    Stdout,
    Stderr,
}

/// Runs `cmd` with `closed` a pipe without a reader and the other stream captured; returns
/// the exit status and what the other stream got.
pub fn run_closed(mut cmd: Command, closed: Stream) -> (Option<i32>, String) {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    cmd.stdin(Stdio::null());
    match closed {
        Stream::Stdout => cmd.stdout(writer).stderr(Stdio::piped()),
        Stream::Stderr => cmd.stderr(writer).stdout(Stdio::piped()),
    };
    let mut child = cmd.spawn().unwrap_or_else(|e| panic!("{:?} starts: {e}", cmd.get_program()));
    drop(cmd); // and with it this process's copy of the writer
    let mut other = String::new();
    let pipe: Option<&mut dyn Read> = match closed {
        Stream::Stdout => child.stderr.as_mut().map(|p| p as &mut dyn Read),
        Stream::Stderr => child.stdout.as_mut().map(|p| p as &mut dyn Read),
    };
    pipe.expect("captured").read_to_string(&mut other).expect("read the other stream");
    let status = child.wait().expect("the command exits");
    (status.code(), other)
}
