//! What sizes a machine holds: the bounds `vge train` and the Python package's vector env
//! check before they allocate, so that both refuse the same sizes with the same words.

/// The most memory a run (or a vector of envs) may hold by its estimate, whatever the
/// machine: 1 TiB. Beyond it a size is a typo (`sac.buffer_size = 1000000000000` asks for
/// 656 TB).
pub const MAX_RUN_BYTES: u64 = 1 << 40;

/// One training env with its controller, generator and bookkeeping, besides its episode's
/// records: a generous bound on the measured growth of `vge train`'s resident memory per env.
pub const ENV_BYTES: u64 = 4 << 20;

/// One simulated env alone (its physics world, generator and observation), as the Python
/// package's vector env holds it: a generous bound on the 0.16 MB measured per env of
/// `VecHandEnv(200)` after 20 steps.
pub const SIM_ENV_BYTES: u64 = 1 << 20;

/// `bytes` in decimal units, 3 significant digits (`656 MB`, `1.10 TB`).
pub fn bytes_text(bytes: u64) -> String {
    let units = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut x = bytes as f64;
    let mut unit = 0;
    while x >= 1000.0 && unit + 1 < units.len() {
        x /= 1000.0;
        unit += 1;
    }
    match x {
        _ if unit == 0 => format!("{bytes} B"),
        x if x >= 100.0 => format!("{x:.0} {}", units[unit]),
        x if x >= 10.0 => format!("{x:.1} {}", units[unit]),
        x => format!("{x:.2} {}", units[unit]),
    }
}

/// `MemTotal` of `/proc/meminfo`, in bytes (None where it cannot be read: not Linux).
pub fn machine_memory_bytes() -> Option<u64> {
    let text = crate::read_to_string_bounded(std::path::Path::new("/proc/meminfo"), 1 << 20).ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.trim_start_matches("MemTotal:").trim().trim_end_matches("kB").trim().parse().ok()?;
    kib.checked_mul(1024)
}

/// Why `total` bytes (of which `parts` says what) cannot be held: more than
/// [`MAX_RUN_BYTES`], or than this machine's memory; `None` when it fits. `what` names the
/// holder (`this run`, `this vector of envs`).
pub fn refusal(what: &str, total: u64, parts: &str) -> Option<String> {
    let text = format!("about {}{parts}", bytes_text(total));
    if total > MAX_RUN_BYTES {
        return Some(format!(
            "{what} would hold {text}, more than the {} vge allows: a size is wrong",
            bytes_text(MAX_RUN_BYTES)
        ));
    }
    let machine = machine_memory_bytes()?;
    (total > machine).then(|| {
        format!(
            "{what} would hold {text}, more than this machine's {} of memory (MemTotal in \
             /proc/meminfo): lower the sizes",
            bytes_text(machine)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_read_in_decimal_units_and_typos_are_refused_anywhere() {
        assert_eq!(bytes_text(656), "656 B");
        assert_eq!(bytes_text(656_000_000), "656 MB");
        assert_eq!(bytes_text(1 << 40), "1.10 TB");
        let why = refusal("this vector of envs", 400 << 40, "").expect("refused");
        assert!(why.contains("more than the 1.10 TB vge allows"), "{why}");
        assert_eq!(refusal("a byte", 1, ""), None);
    }
}
