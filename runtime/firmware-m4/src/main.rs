//! vge-runtime on a Cortex-M4F, emulated by `qemu-system-arm -machine mps2-an386`.
//!
//! Embeds a policy file (`.vgep`, see `build.rs`) in flash with `include_bytes!` at a
//! 16-byte aligned address and loads it with `vge_runtime::Policy::load`: a version-2 file's
//! arrays are read in place from flash (no RAM for weights), a version-1 file's are copied
//! into a static storage sized from the file at build time. It evaluates the policy on fixed
//! observations, prints every observation and action over semihosting as IEEE-754 bit
//! patterns (exact; the host test parses them) plus decimals, the flash and static RAM the
//! image uses (from the linker's symbols), the stack peak, and the SysTick ticks each forward
//! took (under `qemu -icount`, virtual time advances per instruction, so ticks count
//! instructions; see `vge_export::firmware`). Exits through semihosting: status 0 on success,
//! 1 on error (e.g. a corrupted file).
//!
//! ```text
//! cd runtime/firmware-m4 && VGE_POLICY=/path/to/actor.vgep cargo run --release
//! ```
#![no_std]
#![no_main]

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprint, hprintln};
use vge_runtime::{Policy, PolicyError};

// STORAGE_LEN, MAX_LAYERS, MAX_WIDTH: from the embedded file, see build.rs.
include!(concat!(env!("OUT_DIR"), "/policy_sizes.rs"));

/// Bytes at a 16-byte aligned address: a version-2 file's arrays sit at 16-byte aligned
/// offsets, so they can be read in place as `&[f32]` / `&[u16]` / `&[i8]`.
#[repr(C, align(16))]
struct Aligned<T: ?Sized>(T);

/// The policy file, in flash.
static POLICY: &Aligned<[u8]> = &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/policy.vgep")));

/// Number of fixed observations evaluated.
const N_CASES: usize = 8;
/// Instructions of the SysTick calibration loop.
const CALIBRATION_INSTRUCTIONS: u32 = 100_000;

#[entry]
fn main() -> ! {
    // cortex-m-rt's `#[entry]` turns a `static mut` declared here into a `&'static mut` that
    // only this never-returning call can reach, so this needs no `unsafe`. Zero-initialised:
    // it lives in .bss, not in flash.
    static mut STORAGE: [f32; STORAGE_LEN] = [0.0; STORAGE_LEN];
    let Some(peripherals) = cortex_m::Peripherals::take() else {
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    };
    print_memory_use();
    let window = paint_stack();
    let result = run(STORAGE, peripherals.SYST);
    hprintln!("stack_peak_bytes {}", stack_peak(window));
    let status = match result {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(e) => {
            // Display only: `Debug` would link core's string escaping and its Unicode tables
            // (~10 KB of flash).
            hprintln!("error: {}", e);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(status);
    #[allow(clippy::empty_loop)]
    loop {}
}

fn run(storage: &'static mut [f32], mut syst: SYST) -> Result<(), PolicyError> {
    hprintln!("vge-firmware-m4: policy file {} bytes, storage {} f32", POLICY.0.len(), storage.len());
    let policy = Policy::<MAX_LAYERS, MAX_WIDTH>::load(&POLICY.0, storage)?;
    let info = policy.info();
    hprintln!(
        "loaded: format {}, weights {}, crc32 {:08x}, {} -> {} in {} layers, {} params, vge {}, seed {}",
        info.format_version,
        info.weight_type,
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
    // SysTick counts down from 2^24 - 1 at the core clock; one forward takes far fewer ticks.
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();
    let mut ticks_total = 0u32;
    for case in 0..N_CASES {
        observation(case, &mut rng, obs);
        let before = SYST::get_current();
        policy.forward(obs, action)?;
        let after = SYST::get_current();
        ticks_total += before.wrapping_sub(after) & 0x00FF_FFFF;
        hprint!("obs {}", case);
        for x in obs.iter() {
            hprint!(" {:08x}", x.to_bits());
        }
        hprint!("\nact {}", case);
        for a in action.iter() {
            hprint!(" {:08x}", a.to_bits());
        }
        // Bit patterns only: decimal float formatting would add ~14 KB of flash.
        hprintln!();
    }
    hprintln!("systick_ticks_per_forward {}", ticks_total / N_CASES as u32);
    // Calibration: `asm::delay(n)` (cortex-m 0.7.10) is a `subs; bne` loop of n + 1
    // iterations, 2(n + 1) instructions. Under `-icount` this gives ticks per instruction
    // whatever the SysTick clock and the icount shift.
    let before = SYST::get_current();
    cortex_m::asm::delay(CALIBRATION_INSTRUCTIONS / 2 - 1);
    let after = SYST::get_current();
    hprintln!(
        "systick_ticks_per_{}_instructions {}",
        CALIBRATION_INSTRUCTIONS,
        before.wrapping_sub(after) & 0x00FF_FFFF
    );
    hprintln!("done {}", N_CASES);
    Ok(())
}

/// Flash and static RAM of this image, from cortex-m-rt's linker symbols: flash holds the
/// vector table, code and read-only data (the policy file among them) up to `__erodata`, then
/// the initial values of `.data` (`__sidata`, as long as `.data` is); RAM holds `.data`,
/// `.bss` and `.uninit` up to `__sheap` (RAM starts at `__sdata`: `.data` comes first).
/// Only the symbols' addresses are taken, never their values.
fn print_memory_use() {
    unsafe extern "C" {
        static __sidata: u32;
        static __sdata: u32;
        static __edata: u32;
        static __sheap: u32;
        static __vector_table: u32;
    }
    let addr = |p: *const u32| p as u32;
    let data_len = addr(core::ptr::addr_of!(__edata)) - addr(core::ptr::addr_of!(__sdata));
    let flash_origin = addr(core::ptr::addr_of!(__vector_table));
    let flash_end = addr(core::ptr::addr_of!(__sidata)) + data_len;
    let ram_origin = addr(core::ptr::addr_of!(__sdata));
    hprintln!("flash_bytes {}", flash_end - flash_origin);
    hprintln!("static_ram_bytes {}", addr(core::ptr::addr_of!(__sheap)) - ram_origin);
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
