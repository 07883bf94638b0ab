//! How busy the cores this process may run on are, measured from `/proc/stat` over a short
//! window (`vge bench cores`). Why `vge train` asks: libtorch's parallel regions wait for
//! every worker thread, so a run with more threads than idle cores does not slow down
//! gently, it stalls (8x fewer env steps measured beside one busy core, docs/libtorch.md).
//! The load average would not do: it counts tasks on every CPU of a container's host, and
//! tasks waiting on disk.

use std::time::Duration;

/// The cores this process may run on, and how many of them were busy over the window (0 to
/// `cores`; stolen time, where a hypervisor ran someone else, counts as busy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CpuUse {
    pub cores: usize,
    pub busy_cores: f64,
}

impl CpuUse {
    /// Cores left idle over the window.
    pub fn idle_cores(&self) -> f64 {
        (self.cores as f64 - self.busy_cores).max(0.0)
    }

    /// The most libtorch threads that fit beside the other processes (at least 1): the idle
    /// cores, rounded, so that half a core of someone else's work already costs a thread.
    pub fn threads_that_fit(&self) -> usize {
        (self.idle_cores() + 0.5).floor().max(1.0) as usize
    }
}

/// Busy and total jiffies summed over the `cpuN` lines of `/proc/stat` whose N `allowed`
/// accepts, and how many such lines there were. None if no line could be read.
fn jiffies(stat: &str, allowed: impl Fn(usize) -> bool) -> Option<(u64, u64, usize)> {
    let (mut busy, mut total, mut cores) = (0u64, 0u64, 0usize);
    for line in stat.lines() {
        let mut fields = line.split_ascii_whitespace();
        let Some(cpu) = fields.next().and_then(|name| name.strip_prefix("cpu")) else { continue };
        let Ok(index) = cpu.parse::<usize>() else { continue };
        if !allowed(index) {
            continue;
        }
        // user nice system idle iowait irq softirq steal; guest time is already in user.
        let values: Vec<u64> = fields.take(8).map_while(|f| f.parse().ok()).collect();
        let [user, nice, system, idle, iowait, irq, softirq, steal] = values[..] else { return None };
        let line_total = user + nice + system + idle + iowait + irq + softirq + steal;
        total += line_total;
        busy += line_total - idle - iowait;
        cores += 1;
    }
    (cores > 0).then_some((busy, total, cores))
}

/// Busy cores between two readings of `/proc/stat`.
fn between(before: (u64, u64, usize), after: (u64, u64, usize)) -> Option<CpuUse> {
    let (busy, total) = (after.0.checked_sub(before.0)?, after.1.checked_sub(before.1)?);
    let cores = after.2;
    let busy_cores = if total == 0 { 0.0 } else { busy as f64 / total as f64 * cores as f64 };
    Some(CpuUse { cores, busy_cores })
}

/// Measures over `window` (the caller's own threads count too: measure before starting work).
#[cfg(target_os = "linux")]
pub fn measure(window: Duration) -> std::io::Result<CpuUse> {
    let allowed = allowed_cpus();
    let read = || -> std::io::Result<(u64, u64, usize)> {
        let text = std::fs::read_to_string("/proc/stat")?;
        jiffies(&text, |i| allowed.as_ref().is_none_or(|set| set.contains(&i)))
            .ok_or_else(|| std::io::Error::other("/proc/stat: no cpuN line this process may run on"))
    };
    let before = read()?;
    std::thread::sleep(window);
    let after = read()?;
    between(before, after).ok_or_else(|| std::io::Error::other("/proc/stat: counters went backwards"))
}

/// The CPUs of this process's affinity mask (`Cpus_allowed_list` of `/proc/self/status`, as
/// `0-3,8,10-11`); None when the kernel does not say.
#[cfg(target_os = "linux")]
fn allowed_cpus() -> Option<Vec<usize>> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let list = status.lines().find_map(|l| l.strip_prefix("Cpus_allowed_list:"))?;
    cpu_list(list.trim())
}

/// A kernel CPU list (`0-3,8,10-11`) as its CPUs; None where it is malformed.
fn cpu_list(list: &str) -> Option<Vec<usize>> {
    let mut cpus = Vec::new();
    for range in list.split(',') {
        let (first, last) = range.split_once('-').unwrap_or((range, range));
        let (first, last): (usize, usize) = (first.parse().ok()?, last.parse().ok()?);
        if first > last {
            return None;
        }
        cpus.extend(first..=last);
    }
    Some(cpus)
}

#[cfg(not(target_os = "linux"))]
pub fn measure(_window: Duration) -> std::io::Result<CpuUse> {
    Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "no /proc/stat on this system"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const BEFORE: &str = "cpu  300 0 100 1000 50 0 0 0 0 0\n\
                          cpu0 100 0 50 500 25 0 0 0 0 0\n\
                          cpu1 200 0 50 500 25 0 0 0 0 0\n\
                          intr 1 2 3\n";
    // cpu0 then busy 90 of 100 jiffies (10 of them stolen), cpu1 busy 10 of 100.
    const AFTER: &str = "cpu  400 0 100 1100 50 0 0 10 0 0\n\
                         cpu0 180 0 50 510 25 0 0 10 0 0\n\
                         cpu1 210 0 50 590 25 0 0 0 0 0\n";

    fn read(text: &str, allowed: impl Fn(usize) -> bool) -> (u64, u64, usize) {
        jiffies(text, allowed).expect("cpuN lines")
    }

    #[test]
    fn busy_cores_are_the_busy_share_of_the_allowed_cpus_jiffies() {
        let both = between(read(BEFORE, |_| true), read(AFTER, |_| true)).expect("forward");
        assert_eq!(both.cores, 2);
        assert!((both.busy_cores - 1.0).abs() < 1e-12, "{both:?}");
        let cpu0 = between(read(BEFORE, |i| i == 0), read(AFTER, |i| i == 0)).expect("forward");
        assert_eq!(cpu0.cores, 1);
        assert!((cpu0.busy_cores - 0.9).abs() < 1e-12, "stolen time counts as busy: {cpu0:?}");
        assert!((cpu0.idle_cores() - 0.1).abs() < 1e-12);
        assert_eq!(cpu0.threads_that_fit(), 1, "never fewer than one");
        let fit = |busy_cores| CpuUse { cores: 2, busy_cores }.threads_that_fit();
        assert_eq!((fit(0.0), fit(0.49), fit(0.51), fit(1.0), fit(2.0)), (2, 2, 1, 1, 1));
    }

    #[test]
    fn cpu_lists_read_as_the_kernel_writes_them() {
        assert_eq!(cpu_list("0-1"), Some(vec![0, 1]));
        assert_eq!(cpu_list("0-2,5,7-8"), Some(vec![0, 1, 2, 5, 7, 8]));
        assert_eq!(cpu_list("3"), Some(vec![3]));
        assert_eq!(cpu_list("2-1"), None);
        assert_eq!(cpu_list("0-x"), None);
    }

    #[test]
    fn unreadable_stat_text_is_refused_not_read_as_idle() {
        assert_eq!(jiffies("intr 1 2\n", |_| true), None, "no cpuN line");
        assert_eq!(jiffies("cpu0 1 2 x\n", |_| true), None, "a short or garbled line");
        let later = read(AFTER, |_| true);
        assert_eq!(between(later, read(BEFORE, |_| true)), None, "counters went backwards");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_spinning_thread_shows_as_a_busy_core_on_this_machine() {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = stop.clone();
        let spinner = std::thread::spawn(move || {
            let mut n = 0u64;
            while !flag.load(std::sync::atomic::Ordering::Relaxed) {
                n = std::hint::black_box(n.wrapping_add(1));
            }
        });
        let measured = measure(Duration::from_millis(300)).expect("/proc/stat");
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        spinner.join().expect("spinner");
        let allowed = allowed_cpus().expect("Cpus_allowed_list in /proc/self/status");
        assert_eq!(measured.cores, allowed.len(), "the affinity mask's CPUs: {measured:?}");
        // The spinner alone keeps most of a core busy; whatever else runs only adds to it.
        assert!(
            measured.busy_cores >= 0.7 && measured.busy_cores <= measured.cores as f64 + 1e-9,
            "{measured:?}"
        );
    }
}
