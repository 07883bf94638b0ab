//! The Cortex-M4F firmware (`runtime/firmware-m4`) built around a policy file and run under
//! `qemu-system-arm -machine mps2-an386`, and what it reports: its outputs (exact bit
//! patterns), flash and static RAM from the linker's symbols, the stack peak, and the
//! instructions per forward.
//!
//! Instructions are counted with `qemu -icount shift=6`: virtual time advances 2^6 ns per
//! executed instruction, so the SysTick ticks a forward takes are proportional to its
//! instructions. The firmware also times a loop of known length (`asm::delay`), which gives
//! the ticks per instruction without trusting the board's clock frequency. Cycles on a real
//! Cortex-M4F differ (loads, FPU and branches take 1-3 cycles, flash adds wait states):
//! `instructions_per_forward` is the measured quantity, a cycle figure is an estimate.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

/// Why the firmware could not be built, run or read.
#[derive(Debug, thiserror::Error)]
pub enum FirmwareError {
    #[error("building runtime/firmware-m4 failed ({0}); it needs `rustup target add thumbv7em-none-eabihf`")]
    Build(String),
    #[error(
        "cannot run qemu-system-arm ({0}); install it: apt-get install -y --no-install-recommends qemu-system-arm"
    )]
    QemuMissing(String),
    #[error("qemu-system-arm did not exit within {0:?}")]
    Timeout(Duration),
    #[error("qemu-system-arm was killed by a signal; stderr: {0}")]
    Killed(String),
    #[error("the firmware's output lacks `{what}`:\n{output}")]
    Output { what: String, output: String },
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// The firmware's source folder in this checkout.
pub fn source_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime/firmware-m4")
}

/// Builds the firmware embedding `policy` into `target_dir` (a cargo target folder of its
/// own: it builds for `thumbv7em-none-eabihf`); returns the ELF. `opt_level` overrides the
/// firmware's release `opt-level` (3): `"s"` or `"z"` trade speed for flash.
pub fn build(policy: &Path, target_dir: &Path, opt_level: Option<&str>) -> Result<PathBuf, FirmwareError> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    // Run from the firmware folder so that its .cargo/config.toml (target, linker script)
    // applies. Not --locked: its own Cargo.lock follows vge-runtime's dependencies. Flags
    // meant for the host build (e.g. -C target-cpu=native) are dropped.
    let mut command = Command::new(cargo);
    if let Some(level) = opt_level {
        command.env("CARGO_PROFILE_RELEASE_OPT_LEVEL", level);
    } else {
        command.env_remove("CARGO_PROFILE_RELEASE_OPT_LEVEL");
    }
    let status = command
        .current_dir(source_dir())
        .args(["build", "--release", "--quiet"])
        .env("CARGO_TARGET_DIR", target_dir)
        .env("VGE_POLICY", policy)
        .env_remove("VGE_MEMORY_MAP")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env_remove("CARGO_BUILD_RUSTFLAGS")
        .env_remove("CARGO_BUILD_TARGET")
        .status()
        .map_err(|e| FirmwareError::Build(e.to_string()))?;
    if !status.success() {
        return Err(FirmwareError::Build(status.to_string()));
    }
    Ok(target_dir.join("thumbv7em-none-eabihf/release/vge-firmware-m4"))
}

/// What one run of the firmware printed.
#[derive(Debug, Clone, PartialEq)]
pub struct FirmwareRun {
    /// Semihosting exit status: 0 success, 1 error (e.g. a corrupted policy file).
    pub exit_code: i32,
    pub output: String,
}

/// Runs `elf` under qemu with instruction counting, `timeout` at most.
pub fn run(elf: &Path, timeout: Duration) -> Result<FirmwareRun, FirmwareError> {
    const QEMU: &str = "qemu-system-arm";
    let mut child = Command::new(QEMU)
        .args(["-cpu", "cortex-m4", "-machine", "mps2-an386", "-nographic", "-monitor", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=6,align=off,sleep=off", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| FirmwareError::QemuMissing(e.to_string()))?;
    let mut stdout = child.stdout.take().ok_or_else(|| FirmwareError::QemuMissing("no stdout".into()))?;
    let reader = thread::spawn(move || {
        let mut s = String::new();
        stdout.read_to_string(&mut s).map(|_| s)
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if start.elapsed() > timeout {
            child.kill()?;
            child.wait()?;
            return Err(FirmwareError::Timeout(timeout));
        }
        thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        e.read_to_string(&mut stderr)?;
    }
    let output = reader.join().map_err(|_| FirmwareError::Killed("reader thread panicked".into()))??;
    let exit_code = status.code().ok_or(FirmwareError::Killed(stderr))?;
    Ok(FirmwareRun { exit_code, output })
}

impl FirmwareRun {
    fn missing(&self, what: &str) -> FirmwareError {
        FirmwareError::Output { what: what.to_owned(), output: self.output.clone() }
    }

    /// The integer after `key ` on its line.
    pub fn value(&self, key: &str) -> Result<u64, FirmwareError> {
        self.output
            .lines()
            .find_map(|l| l.strip_prefix(key)?.strip_prefix(' ')?.trim().parse().ok())
            .ok_or_else(|| self.missing(key))
    }

    /// Flash the image occupies: vector table, code, read-only data (the policy file among
    /// them) and the initial values of `.data`.
    pub fn flash_bytes(&self) -> Result<u64, FirmwareError> {
        self.value("flash_bytes")
    }

    /// RAM: static data (`.data`, `.bss`) plus the measured stack peak.
    pub fn ram_bytes(&self) -> Result<u64, FirmwareError> {
        Ok(self.value("static_ram_bytes")? + self.value("stack_peak_bytes")?)
    }

    /// Instructions per policy forward (mean over the firmware's observations).
    pub fn instructions_per_forward(&self) -> Result<f64, FirmwareError> {
        let ticks = self.value("systick_ticks_per_forward")? as f64;
        let key = "systick_ticks_per_100000_instructions";
        let calibration = self.value(key)? as f64;
        if calibration <= 0.0 {
            return Err(self.missing(key));
        }
        Ok(ticks * 100_000.0 / calibration)
    }

    /// `<tag> <case> <hex f32 bits>...` lines (`obs`, `act`), in order.
    pub fn vectors(&self, tag: &str) -> Result<Vec<Vec<f32>>, FirmwareError> {
        self.output
            .lines()
            .filter_map(|l| l.strip_prefix(tag).and_then(|r| r.strip_prefix(' ')))
            .enumerate()
            .map(|(i, rest)| {
                let mut words = rest.split_whitespace();
                if words.next().and_then(|w| w.parse::<usize>().ok()) != Some(i) {
                    return Err(self.missing(&format!("{tag} line {i}")));
                }
                words
                    .map(|w| u32::from_str_radix(w, 16).map(f32::from_bits))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|_| self.missing(&format!("hex values on {tag} line {i}")))
            })
            .collect()
    }
}
