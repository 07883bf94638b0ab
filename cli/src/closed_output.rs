//! A closed stdout or stderr ends `vge` quietly with status 0, as it does command-line tools:
//! `vge inspect policies/cube.vgep | head -1` succeeds, also under `set -o pipefail`. Except
//! where the work outlives its output: `vge train`, `vge sweep` and `vge score` print with
//! [`outln!`] and [`errln!`], which drop a line that cannot be written, and go on to the end
//! of their runs (their folders hold what they report); they call [`keep_going`].
//!
//! Rust ignores SIGPIPE, so writing to a pipe whose reader has gone fails with EPIPE, and the
//! print macros panic on that ("failed printing to stdout: Broken pipe (os error 32)").
//! Restoring SIGPIPE's default would end the process by the signal instead, status 141, which
//! `pipefail` takes for a failure. The printing is spread over the library (eval, plot,
//! table1, ...), so the panic hook is the one place that sees it all: on exactly that panic,
//! from whichever thread, the process exits 0; every other panic goes to the usual hook.

use std::any::Any;
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};

/// `println!` for work that must outlive its output: a line that cannot be written (a pipe
/// whose reader has gone) is dropped, and the work goes on.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

/// `eprintln!` as [`outln!`]: a line that cannot be written is dropped.
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// Set by commands whose work outlives their output ([`keep_going`]).
static KEEP_GOING: AtomicBool = AtomicBool::new(false);

/// From now on a print macro meeting a closed pipe is a bug (these commands print with
/// [`outln!`] and [`errln!`]), reported as the panic it is, never as a quiet success: a run
/// that exited 0 halfway would look finished.
pub fn keep_going() {
    KEEP_GOING.store(true, Ordering::SeqCst);
}

/// Installs the hook; call first thing in `main`.
pub fn end_quietly_when_closed() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if is_closed_output(info.payload()) && !KEEP_GOING.load(Ordering::SeqCst) {
            std::process::exit(0);
        }
        previous(info);
    }));
}

/// Whether a panic's payload is std's print macros meeting a pipe without a reader.
fn is_closed_output(payload: &dyn Any) -> bool {
    let message = match (payload.downcast_ref::<String>(), payload.downcast_ref::<&str>()) {
        (Some(s), _) => s.as_str(),
        (None, Some(s)) => s,
        (None, None) => return false,
    };
    let epipe = io::Error::from_raw_os_error(libc::EPIPE);
    ["stdout", "stderr"].iter().any(|stream| message == format!("failed printing to {stream}: {epipe}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_print_into_a_pipe_without_reader_counts() {
        assert!(is_closed_output(&"failed printing to stdout: Broken pipe (os error 32)".to_owned()));
        assert!(is_closed_output(&"failed printing to stderr: Broken pipe (os error 32)".to_owned()));
        assert!(!is_closed_output(
            &"failed printing to stdout: No space left on device (os error 28)".to_owned()
        ));
        assert!(!is_closed_output(&"index out of bounds"));
        assert!(!is_closed_output(&42));
    }
}
