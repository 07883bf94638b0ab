//! How busy the machine's cores are, from the kernel's counters in `/proc/stat`: measured over
//! a short window on the cores this process may run on ([`measure`]: `vge bench cores`, and
//! `vge train` before it starts), and read as raw counters ([`Jiffies::read`]) by the
//! learner's thread governor, which fits libtorch's threads to the idle cores while a run
//! trains. Why both ask: libtorch's parallel regions wait for every worker thread, so a run
//! with more threads than idle cores does not slow down gently, it stalls (8x fewer env steps
//! measured beside one busy core, docs/libtorch.md). The load average would not do: it counts
//! tasks on every CPU of a container's host, and tasks waiting on disk.

use std::time::Duration;

use thiserror::Error;

/// Why the cores' use could not be measured.
#[derive(Debug, Error)]
pub enum CpuUseError {
    #[error("/proc/stat: {0}")]
    Read(#[source] std::io::Error),
    #[error("/proc/stat: no cpuN line this process may run on")]
    NoCpuLine,
    /// A `cpuN` line without its eight counters, or with counters past `u64`.
    #[error("/proc/stat: a cpuN line without its eight counters")]
    Garbled,
    #[error("/proc/stat: counters went backwards")]
    Backwards,
    #[error("no /proc/stat on this system")]
    Unsupported,
}

/// Busy and total jiffies (the kernel's ticks) summed over some cores' `cpuN` lines of
/// `/proc/stat`, and how many cores that was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Jiffies {
    pub busy: u64,
    pub total: u64,
    pub cores: usize,
}

impl Jiffies {
    /// Sums the `cpuN` lines of `stat` (the text of `/proc/stat`) whose N `counted` accepts.
    /// A line it cannot read is refused, not read as idle.
    pub fn parse(stat: &str, counted: impl Fn(usize) -> bool) -> Result<Self, CpuUseError> {
        let (mut busy, mut total, mut cores) = (0u64, 0u64, 0usize);
        for line in stat.lines() {
            let mut fields = line.split_ascii_whitespace();
            let Some(cpu) = fields.next().and_then(|name| name.strip_prefix("cpu")) else { continue };
            let Ok(index) = cpu.parse::<usize>() else { continue };
            if !counted(index) {
                continue;
            }
            // user nice system idle iowait irq softirq steal; guest time is already in user.
            let values: Vec<u64> = fields.take(8).map_while(|f| f.parse().ok()).collect();
            let [_user, _nice, _system, idle, iowait, _irq, _softirq, _steal] = values[..] else {
                return Err(CpuUseError::Garbled);
            };
            let line_total = values.iter().try_fold(0u64, |sum, v| sum.checked_add(*v));
            let line_total = line_total.ok_or(CpuUseError::Garbled)?;
            total = total.checked_add(line_total).ok_or(CpuUseError::Garbled)?;
            // idle and iowait are two of the summed counters: no underflow.
            busy = busy.checked_add(line_total - idle - iowait).ok_or(CpuUseError::Garbled)?;
            cores += 1;
        }
        if cores == 0 {
            return Err(CpuUseError::NoCpuLine);
        }
        Ok(Self { busy, total, cores })
    }

    /// `/proc/stat` now, summed over the cores `counted` accepts.
    pub fn read(counted: impl Fn(usize) -> bool) -> Result<Self, CpuUseError> {
        let text = std::fs::read_to_string("/proc/stat").map_err(CpuUseError::Read)?;
        Self::parse(&text, counted)
    }

    /// The jiffies between an earlier reading and this one, on this reading's cores; None
    /// where a counter went backwards.
    #[must_use]
    pub fn since(&self, before: &Self) -> Option<Self> {
        Some(Self {
            busy: self.busy.checked_sub(before.busy)?,
            total: self.total.checked_sub(before.total)?,
            cores: self.cores,
        })
    }

    /// The cores these jiffies kept busy (0 to `cores`; stolen time, where a hypervisor ran
    /// someone else, counts as busy); None when no jiffy passed.
    #[must_use]
    pub fn busy_cores(&self) -> Option<f64> {
        (self.total > 0).then(|| self.busy as f64 / self.total as f64 * self.cores as f64)
    }
}

/// The cores this process may run on, and how many of them were busy over the window (0 to
/// `cores`; stolen time, where a hypervisor ran someone else, counts as busy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CpuUse {
    pub cores: usize,
    pub busy_cores: f64,
}

impl CpuUse {
    /// The use between two readings; None where a counter went backwards. No jiffy passed
    /// reads as no core busy.
    #[must_use]
    pub fn between(before: &Jiffies, after: &Jiffies) -> Option<Self> {
        let counted = after.since(before)?;
        Some(Self { cores: counted.cores, busy_cores: counted.busy_cores().unwrap_or(0.0) })
    }

    /// Cores left idle over the window.
    #[must_use]
    pub fn idle_cores(&self) -> f64 {
        (self.cores as f64 - self.busy_cores).max(0.0)
    }

    /// The most libtorch threads that fit beside the other processes (at least 1): the idle
    /// cores, rounded, so that half a core of someone else's work already costs a thread.
    #[must_use]
    pub fn threads_that_fit(&self) -> usize {
        (self.idle_cores() + 0.5).floor().max(1.0) as usize
    }
}

/// Measures over `window` the cores of this process's affinity mask (the caller's own threads
/// count too: measure before starting work).
#[cfg(target_os = "linux")]
pub fn measure(window: Duration) -> Result<CpuUse, CpuUseError> {
    let allowed = allowed_cpus();
    let read = || Jiffies::read(|i| allowed.as_ref().is_none_or(|set| set.contains(&i)));
    let before = read()?;
    std::thread::sleep(window);
    let after = read()?;
    CpuUse::between(&before, &after).ok_or(CpuUseError::Backwards)
}

#[cfg(not(target_os = "linux"))]
pub fn measure(_window: Duration) -> Result<CpuUse, CpuUseError> {
    Err(CpuUseError::Unsupported)
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
#[cfg_attr(not(target_os = "linux"), allow(dead_code))]
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

    fn read(text: &str, counted: impl Fn(usize) -> bool) -> Jiffies {
        Jiffies::parse(text, counted).expect("cpuN lines")
    }

    #[test]
    fn jiffies_sum_the_counted_cpu_lines_not_the_total_line() {
        assert_eq!(read(BEFORE, |_| true), Jiffies { busy: 400, total: 1450, cores: 2 });
        assert_eq!(read(BEFORE, |i| i == 1), Jiffies { busy: 250, total: 775, cores: 1 });
        let counted = read(AFTER, |_| true).since(&read(BEFORE, |_| true)).expect("forward");
        assert_eq!(counted, Jiffies { busy: 100, total: 200, cores: 2 });
        assert_eq!(counted.busy_cores(), Some(1.0));
        assert_eq!(Jiffies { busy: 0, total: 0, cores: 2 }.busy_cores(), None, "no jiffy passed");
    }

    #[test]
    fn busy_cores_are_the_busy_share_of_the_allowed_cpus_jiffies() {
        let both = CpuUse::between(&read(BEFORE, |_| true), &read(AFTER, |_| true)).expect("forward");
        assert_eq!(both.cores, 2);
        assert!((both.busy_cores - 1.0).abs() < 1e-12, "{both:?}");
        let cpu0 = CpuUse::between(&read(BEFORE, |i| i == 0), &read(AFTER, |i| i == 0)).expect("forward");
        assert_eq!(cpu0.cores, 1);
        assert!((cpu0.busy_cores - 0.9).abs() < 1e-12, "stolen time counts as busy: {cpu0:?}");
        assert!((cpu0.idle_cores() - 0.1).abs() < 1e-12);
        assert_eq!(cpu0.threads_that_fit(), 1, "never fewer than one");
        let fit = |busy_cores| CpuUse { cores: 2, busy_cores }.threads_that_fit();
        assert_eq!((fit(0.0), fit(0.49), fit(0.51), fit(1.0), fit(2.0)), (2, 2, 1, 1, 1));
        let still = read(BEFORE, |_| true);
        assert_eq!(CpuUse::between(&still, &still), Some(CpuUse { cores: 2, busy_cores: 0.0 }));
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
        let parse = |text| Jiffies::parse(text, |_| true);
        assert!(matches!(parse("intr 1 2\n"), Err(CpuUseError::NoCpuLine)), "no cpuN line");
        assert!(matches!(parse("cpu0 1 2 x\n"), Err(CpuUseError::Garbled)), "a short or garbled line");
        let max = u64::MAX;
        let past_u64 = format!("cpu0 {max} 1 0 0 0 0 0 0\n");
        assert!(matches!(parse(&past_u64), Err(CpuUseError::Garbled)), "counters past u64");
        let (before, after) = (read(BEFORE, |_| true), read(AFTER, |_| true));
        assert_eq!(before.since(&after), None, "counters went backwards");
        assert_eq!(CpuUse::between(&after, &before), None);
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
