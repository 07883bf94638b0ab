//! vge-runtime on a Cortex-M4F, emulated by `qemu-system-arm -machine mps2-an386`.
//!
//! Embeds a policy (see `build.rs`) in flash with `include_bytes!`, evaluates it with
//! `vge_runtime::Mlp` on fixed observations without copying the weights, prints every
//! observation and action over semihosting as IEEE-754 bit patterns (exact; the host test
//! parses them) plus decimals, and exits through semihosting: status 0 on success, 1 on error.
//!
//! ```text
//! cd runtime/firmware-m4 && cargo run --release
//! ```
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprint, hprintln};
use vge_runtime::{Activation, Layer, PolicyMlp};

/// Layer sizes of the embedded policy: obs 65 -> 256 -> 256 -> 15 actions.
const DIMS: [usize; 4] = [65, 256, 256, 15];
const N_LAYERS: usize = DIMS.len() - 1;
const OBS_DIM: usize = DIMS[0];
const ACT_DIM: usize = DIMS[N_LAYERS];
/// Number of fixed observations evaluated.
const N_CASES: usize = 8;

/// Forces 4-byte alignment on the embedded bytes so they can be viewed as `f32`s in place.
#[repr(C, align(4))]
struct Aligned<T: ?Sized>(T);

static POLICY: &Aligned<[u8]> = &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/policy.bin")));

#[entry]
fn main() -> ! {
    let window = paint_stack();
    let result = run();
    hprintln!("stack_peak_bytes {}", stack_peak(window));
    let status = match result {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(msg) => {
            hprintln!("error: {}", msg);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(status);
    #[allow(clippy::empty_loop)]
    loop {}
}

fn run() -> Result<(), &'static str> {
    let floats: &[f32] =
        bytemuck::try_cast_slice(&POLICY.0).map_err(|_| "policy blob is not a whole number of f32s")?;
    hprintln!("vge-firmware-m4: policy {} bytes, {:?}", POLICY.0.len(), DIMS);

    // Borrow each layer's weights and biases straight from flash.
    let mut rest = floats;
    let mut layers =
        [Layer { in_dim: 1, out_dim: 1, weights: &[], bias: &[], activation: Activation::Identity };
            N_LAYERS];
    for (i, layer) in layers.iter_mut().enumerate() {
        let (n_in, n_out) = (DIMS[i], DIMS[i + 1]);
        let (w, r) = rest.split_at_checked(n_in * n_out).ok_or("policy blob too short")?;
        let (b, r) = r.split_at_checked(n_out).ok_or("policy blob too short")?;
        rest = r;
        let activation = if i + 1 == N_LAYERS { Activation::Tanh } else { Activation::Relu };
        *layer = Layer { in_dim: n_in, out_dim: n_out, weights: w, bias: b, activation };
    }
    if !rest.is_empty() {
        return Err("policy blob too long");
    }
    let mlp = PolicyMlp::new(&layers).map_err(|_| "invalid policy")?;

    let mut rng = 0x1234_5678_u32;
    for case in 0..N_CASES {
        let obs = observation(case, &mut rng);
        let mut action = [0.0f32; ACT_DIM];
        mlp.forward(&obs, &mut action).map_err(|_| "forward failed")?;
        hprint!("obs {}", case);
        for x in obs {
            hprint!(" {:08x}", x.to_bits());
        }
        hprint!("\nact {}", case);
        for a in action {
            hprint!(" {:08x}", a.to_bits());
        }
        hprint!("\nact_dec {}", case);
        for a in action {
            hprint!(" {:+.6}", a);
        }
        hprintln!();
    }
    hprintln!("done {}", N_CASES);
    Ok(())
}

/// Fixed observations: all zeros, then xorshift32 values in [-3, 3), then one large-magnitude
/// case (±50) that saturates the tanh head.
fn observation(case: usize, rng: &mut u32) -> [f32; OBS_DIM] {
    let mut obs = [0.0f32; OBS_DIM];
    if case == 0 {
        return obs;
    }
    let scale = if case == N_CASES - 1 { 50.0 } else { 3.0 };
    for x in obs.iter_mut() {
        *rng ^= *rng << 13;
        *rng ^= *rng >> 17;
        *rng ^= *rng << 5;
        *x = ((*rng >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0) * scale;
    }
    obs
}

/// Stack high-water mark: [`paint_stack`] fills `PAINT_BYTES` below the current stack pointer
/// with a pattern, [`stack_peak`] finds the lowest overwritten word. The only `unsafe` in the
/// firmware; the runtime itself has none.
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
