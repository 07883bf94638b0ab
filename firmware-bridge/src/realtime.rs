//! Optional real-time scheduling for the control loop thread: SCHED_FIFO and pinning to one
//! CPU, where the process is permitted (root, or CAP_SYS_NICE / an rtprio limit).
//!
//! Both are plain Linux system calls with no safe wrapper in std; this module is the only
//! `unsafe` in the bridge, each call's contract stated beside it.
#![allow(unsafe_code)]

use std::io;

/// What could be applied; a refusal (e.g. EPERM without privileges) is reported, not fatal.
#[derive(Debug)]
pub struct RealtimeOutcome {
    pub fifo: Result<i32, io::Error>,
    pub pinned: Option<Result<usize, io::Error>>,
}

/// Sets SCHED_FIFO at `priority` (1..=99, clamped) for the calling thread and, if `cpu` is
/// given, pins it to that CPU.
pub fn make_current_thread_realtime(priority: i32, cpu: Option<usize>) -> RealtimeOutcome {
    let priority = priority.clamp(1, 99);
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: pid 0 means the calling thread; `param` is a valid, initialised sched_param
    // that outlives the call.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    let fifo = if rc == 0 { Ok(priority) } else { Err(io::Error::last_os_error()) };

    let pinned = cpu.map(|cpu| {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("CPU {cpu} out of range")));
        }
        // SAFETY: cpu_set_t is plain data for which all-zero is the empty set.
        let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
        // SAFETY: `cpu` < CPU_SETSIZE was checked above, so CPU_SET stays inside `set`.
        unsafe { libc::CPU_SET(cpu, &mut set) };
        // SAFETY: pid 0 is the calling thread; the size and pointer describe `set` exactly.
        let rc = unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
        if rc == 0 { Ok(cpu) } else { Err(io::Error::last_os_error()) }
    });
    RealtimeOutcome { fifo, pinned }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pinning_to_an_existing_cpu_works_and_fifo_either_applies_or_says_why() {
        // Run on a scratch thread so the test harness's thread keeps its scheduling.
        let outcome =
            std::thread::spawn(|| make_current_thread_realtime(10, Some(0))).join().expect("thread");
        assert_eq!(outcome.pinned.as_ref().map(|r| r.as_ref().ok().copied()), Some(Some(0)));
        match &outcome.fifo {
            Ok(p) => assert_eq!(*p, 10),
            Err(e) => assert_eq!(e.raw_os_error(), Some(libc::EPERM), "{e}"),
        }
        let bad = make_current_thread_realtime(10, Some(1 << 20));
        assert!(matches!(bad.pinned, Some(Err(_))));
    }
}
