//! Link-time proof that the replay firmware has no panic path.
//!
//! The same program as `replay`, but the panic handler calls a function that exists nowhere.
//! Built with the release profile (fat LTO, one codegen unit, `panic = "abort"`), it links
//! only if the optimiser removed every call to the panic handler, i.e. no reachable panic
//! (bounds check, unwrap, overflow, division by zero, `core::fmt` panic) remains in fsw-core,
//! postcard, heapless, nalgebra, libm or this crate. `scripts/no-panic-check.sh` builds it and,
//! when the link fails, lists the surviving panic call sites from the `replay` binary.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
extern "C" {
    /// Deliberately undefined: a reference to it that survives optimisation fails the link.
    fn fsw_firmware_panic_path_survives_optimisation() -> !;
}

#[entry]
fn main() -> ! {
    fsw_firmware::firmware_main()
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    // SAFETY: never called in a binary that links; the call is the proof device.
    unsafe { fsw_firmware_panic_path_survives_optimisation() }
}
