//! Which kernels the MKL inside libtorch runs, and why `vge` overrides its vendor check.
//!
//! The PyPI libtorch links oneMKL statically. MKL asks `mkl_serv_intel_cpu_true()` whether
//! the CPU is an Intel one, and on any other vendor it runs its generic AVX2 ("zen") SGEMM
//! kernels even where the CPU has AVX-512: on the AMD EPYC machines here its code-branch
//! query reads `auto` (no branch of its own) instead of `avx512_e1` (AVX-512 with VNNI).
//! `vge`'s `main.rs` defines that function (exported from the executable, so it takes
//! precedence over libtorch's copy) and answers yes, after which MKL picks its kernels by
//! the CPU's features alone, as it does on Intel. Measured in one run of five alternating
//! pairs with training paused: TD3 one thread +11 to +16% updates/s in every pair (e.g.
//! 132.9 -> 149.4), SAC two threads +9 to +15% in four of five. The sums are those MKL
//! computes on an Intel CPU with AVX-512, so results differ from the AVX2 path only by
//! float rounding, as they already did between the Intel and AMD machines.
//!
//! `VGE_MKL_VENDOR_CHECK=1` leaves MKL's own answer in place (for comparisons); only the
//! `vge` binary carries the override, so tests and examples that call tch in-process keep
//! MKL's default.

use std::ffi::{CStr, c_int};

/// The environment variable that keeps MKL's own vendor check.
pub const KEEP_VENDOR_CHECK_ENV: &str = "VGE_MKL_VENDOR_CHECK";

/// MKL's `MKL_CBWR_*` code-branch numbers (mkl_cbwr.h). On a CPU that MKL does not take
/// for an Intel one the auto branch reads `auto`: no code branch of its own applies.
fn branch_name(branch: c_int) -> &'static str {
    match branch {
        1 => "branch_off",
        2 => "auto",
        3 => "compatible",
        4 => "sse2",
        5 => "sse3",
        6 => "ssse3",
        7 => "sse4_1",
        8 => "sse4_2",
        9 => "avx",
        10 => "avx2",
        11 => "avx512_mic",
        12 => "avx512",
        13 => "avx512_mic_e1",
        14 => "avx512_e1",
        _ => "unknown",
    }
}

/// Looks a C function up among the symbols the process has loaded (`handle`:
/// `RTLD_DEFAULT` or `RTLD_NEXT`); None where libtorch was built without MKL.
#[allow(unsafe_code)]
fn lookup(handle: *mut libc::c_void, name: &CStr) -> Option<unsafe extern "C" fn() -> c_int> {
    // SAFETY: dlsym only reads the loaded objects' symbol tables. A non-null result for
    // these names is MKL's `int f(void)` (mkl_service.h / mkl_cbwr.h).
    let ptr = unsafe { libc::dlsym(handle, name.as_ptr()) };
    if ptr.is_null() {
        return None;
    }
    // SAFETY: see above: the symbol is a function of this signature.
    Some(unsafe { std::mem::transmute::<*mut libc::c_void, unsafe extern "C" fn() -> c_int>(ptr) })
}

/// MKL's auto-selected code branch (e.g. `"avx512_e1"`, or `"auto"` on a CPU it does not
/// take for Intel), or None when
/// libtorch has no MKL. Asking makes MKL run its CPU detection if it has not yet.
#[allow(unsafe_code)]
pub fn code_branch() -> Option<&'static str> {
    let f = lookup(libc::RTLD_DEFAULT, c"mkl_serv_cbwr_get_auto_branch")?;
    // SAFETY: MKL's thread-safe query, no arguments.
    Some(branch_name(unsafe { f() }))
}

/// The answer `vge`'s override of `mkl_serv_intel_cpu_true` gives: 1, or MKL's own answer
/// (the next definition, libtorch's) when [`KEEP_VENDOR_CHECK_ENV`] is set.
#[allow(unsafe_code)]
pub fn intel_cpu_answer() -> c_int {
    if std::env::var_os(KEEP_VENDOR_CHECK_ENV).is_some_and(|v| v != "0") {
        return lookup(libc::RTLD_NEXT, c"mkl_serv_intel_cpu_true")
            // SAFETY: MKL's own `int mkl_serv_intel_cpu_true(void)`.
            .map_or(0, |own| unsafe { own() });
    }
    1
}
