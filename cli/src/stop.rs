//! A stop requested by a signal, and the exit status that says so.
//!
//! SIGINT (Ctrl-C), SIGTERM (Slurm's preemption, `scancel`, a time limit's warning, `kill`)
//! and SIGHUP (a closed terminal) ask `vge train` and `vge sweep` to stop: training writes a
//! checkpoint at the step it is at and returns. The command then exits with 128 + the
//! signal's number (130, 143, 129), as a shell reports a process ended by that signal, so
//! that a script or a scheduler never takes a stopped run for a finished one (0), nor for a
//! failed one (1). `vge_lab::sweep` reads the same statuses back from its child processes.

use std::fmt;
#[cfg(feature = "train")]
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// Raised by the signal handler; what the training loop polls.
#[cfg(feature = "train")]
static STOP: AtomicBool = AtomicBool::new(false);
/// The number of the last stopping signal received (0: none).
#[cfg(feature = "train")]
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// A command that ended because a signal asked it to stop, after saving what resumes it.
/// `main` exits with [`Self::exit_code`] and prints nothing more: the command printed where it
/// stopped and how to continue.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stopped {
    /// The signal's number.
    pub signal: i32,
}

impl Stopped {
    /// 128 + the signal's number ([`vge_lab::sweep::stopped_exit_code`]).
    pub fn exit_code(&self) -> u8 {
        vge_lab::sweep::stopped_exit_code(self.signal)
    }
}

impl fmt::Display for Stopped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "stopped by {}", signal_name(self.signal))
    }
}

impl std::error::Error for Stopped {}

/// `SIGTERM` for 15, and so on; `signal N` for one vge does not handle.
pub fn signal_name(signal: i32) -> String {
    match signal {
        libc::SIGINT => "SIGINT".to_owned(),
        libc::SIGTERM => "SIGTERM".to_owned(),
        libc::SIGHUP => "SIGHUP".to_owned(),
        n => format!("signal {n}"),
    }
}

/// The stopping signal received so far, if any.
#[cfg(feature = "train")]
pub fn received() -> Option<Stopped> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        signal => Some(Stopped { signal }),
    }
}

/// Async-signal-safe: two lock-free atomic stores.
#[cfg(feature = "train")]
extern "C" fn on_signal(signal: libc::c_int) {
    SIGNAL.store(signal, Ordering::SeqCst);
    STOP.store(true, Ordering::SeqCst);
}

/// Installs the handler of SIGINT, SIGTERM and SIGHUP; returns the flag they raise.
#[cfg(feature = "train")]
pub fn on_signal_stop() -> anyhow::Result<&'static AtomicBool> {
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    // SA_RESTART: a read or write that the signal interrupts goes on instead of failing.
    let action = SigAction::new(SigHandler::Handler(on_signal), SaFlags::SA_RESTART, SigSet::empty());
    for signal in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP] {
        // SAFETY: the handler only stores to two atomics, which is async-signal-safe, and it
        // replaces the default action (ending the process) for these signals only.
        #[allow(unsafe_code)]
        unsafe { sigaction(signal, &action) }
            .map_err(|e| anyhow::anyhow!("installing the handler of {signal}: {e}"))?;
    }
    Ok(&STOP)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exit_status_is_128_plus_the_signal_as_a_shell_reports_it() {
        assert_eq!(Stopped { signal: libc::SIGINT }.exit_code(), 130);
        assert_eq!(Stopped { signal: libc::SIGTERM }.exit_code(), 143);
        assert_eq!(Stopped { signal: libc::SIGHUP }.exit_code(), 129);
        assert_eq!(Stopped { signal: libc::SIGTERM }.to_string(), "stopped by SIGTERM");
    }
}
