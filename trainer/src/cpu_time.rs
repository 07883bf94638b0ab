//! This process's CPU time, all threads, user and system: what a run's clock adds up and what
//! the thread governor subtracts from the cores' busy time.

/// CPU time of this process, all threads, user and system (s); None where the OS does not
/// say.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
#[must_use]
pub fn process_cpu_s() -> Option<f64> {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec through a valid pointer to a local.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    (rc == 0).then_some(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9)
}

/// CPU time of this process (s): not measured outside Linux.
#[cfg(not(target_os = "linux"))]
#[must_use]
pub fn process_cpu_s() -> Option<f64> {
    None
}
