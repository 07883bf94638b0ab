//! vge-runtime on a Cortex-M4F, emulated by `qemu-system-arm -machine mps2-an386`.
//!
//! Embeds a policy file (`.vgep`, see `build.rs`) in flash with `include_bytes!`, loads it
//! with `vge_runtime::Policy::load` into a static weight storage sized from the file at build
//! time, evaluates it on fixed observations, prints every observation and action over
//! semihosting as IEEE-754 bit patterns (exact; the host test parses them) plus decimals, and
//! exits through semihosting: status 0 on success, 1 on error (e.g. a corrupted file).
//!
//! ```text
//! cd runtime/firmware-m4 && VGE_POLICY=/path/to/actor.vgep cargo run --release
//! ```
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprint, hprintln};
use vge_runtime::{Policy, PolicyError};

// STORAGE_LEN, MAX_LAYERS, MAX_WIDTH: from the embedded file, see build.rs.
include!(concat!(env!("OUT_DIR"), "/policy_sizes.rs"));

/// The policy file, in flash. `Policy::load` needs no alignment: it decodes each `f32` once
/// into the storage below and borrows everything else (names, provenance) from here.
static POLICY: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/policy.vgep"));

/// Number of fixed observations evaluated.
const N_CASES: usize = 8;

#[entry]
fn main() -> ! {
    // cortex-m-rt's `#[entry]` turns a `static mut` declared here into a `&'static mut` that
    // only this never-returning call can reach, so this needs no `unsafe`. Zero-initialised:
    // it lives in .bss, not in flash.
    static mut STORAGE: [f32; STORAGE_LEN] = [0.0; STORAGE_LEN];
    let window = paint_stack();
    let result = run(STORAGE);
    hprintln!("stack_peak_bytes {}", stack_peak(window));
    let status = match result {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(e) => {
            hprintln!("error: {:?}: {}", e, e);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(status);
    #[allow(clippy::empty_loop)]
    loop {}
}

fn run(storage: &'static mut [f32]) -> Result<(), PolicyError> {
    hprintln!("vge-firmware-m4: policy file {} bytes, storage {} f32", POLICY.len(), storage.len());
    let policy = Policy::<MAX_LAYERS, MAX_WIDTH>::load(POLICY, storage)?;
    let info = policy.info();
    hprintln!(
        "loaded: format {}, crc32 {:08x}, {} -> {} in {} layers, {} params, vge {}, seed {}",
        info.format_version,
        info.checksum,
        info.obs_dim,
        info.act_dim,
        info.num_layers,
        info.num_params,
        info.provenance.vge_version,
        info.provenance.seed
    );

    let mut rng = 0x1234_5678_u32;
    let mut obs_buf = [0.0f32; MAX_WIDTH];
    let mut act_buf = [0.0f32; MAX_WIDTH];
    // `load` checked obs_dim, act_dim <= MAX_WIDTH.
    let obs = &mut obs_buf[..policy.obs_dim()];
    let action = &mut act_buf[..policy.act_dim()];
    for case in 0..N_CASES {
        observation(case, &mut rng, obs);
        policy.forward(obs, action)?;
        hprint!("obs {}", case);
        for x in obs.iter() {
            hprint!(" {:08x}", x.to_bits());
        }
        hprint!("\nact {}", case);
        for a in action.iter() {
            hprint!(" {:08x}", a.to_bits());
        }
        hprint!("\nact_dec {}", case);
        for a in action.iter() {
            hprint!(" {:+.6}", a);
        }
        hprintln!();
    }
    hprintln!("done {}", N_CASES);
    Ok(())
}

/// Fixed observations: all zeros, then xorshift32 values in [-3, 3), then one large-magnitude
/// case (±50) that saturates the tanh head.
fn observation(case: usize, rng: &mut u32, obs: &mut [f32]) {
    if case == 0 {
        obs.fill(0.0);
        return;
    }
    let scale = if case == N_CASES - 1 { 50.0 } else { 3.0 };
    for x in obs.iter_mut() {
        *rng ^= *rng << 13;
        *rng ^= *rng >> 17;
        *rng ^= *rng << 5;
        *x = ((*rng >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0) * scale;
    }
}

/// Stack high-water mark: [`paint_stack`] fills `PAINT_BYTES` below the current stack pointer
/// with a pattern, [`stack_peak`] finds the lowest overwritten word. The only `unsafe` in the
/// firmware (besides reading the linker symbol's address); the runtime itself has none.
const PAINT_BYTES: u32 = 32 * 1024;
const PAINT: u32 = 0xDEAD_BEEF;

fn stack_window() -> (u32, u32) {
    let sp = cortex_m::register::msp::read();
    (sp - PAINT_BYTES, sp - 64)
}

fn paint_stack() -> (u32, u32) {
    let (lo, hi) = stack_window();
    for addr in (lo..hi).step_by(4) {
        // SAFETY: unused stack memory below the live frame, inside RAM (4 MiB, stack at its top).
        #[allow(unsafe_code)]
        unsafe {
            core::ptr::write_volatile(addr as *mut u32, PAINT)
        };
    }
    (lo, hi)
}

fn stack_peak((lo, hi): (u32, u32)) -> u32 {
    unsafe extern "C" {
        static _stack_start: u32;
    }
    let top = core::ptr::addr_of!(_stack_start) as u32;
    let lowest = (lo..hi)
        .step_by(4)
        // SAFETY: reads of the painted window, see `paint_stack`.
        .find(|&addr| unsafe { core::ptr::read_volatile(addr as *const u32) } != PAINT)
        .unwrap_or(hi);
    top - lowest
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}
