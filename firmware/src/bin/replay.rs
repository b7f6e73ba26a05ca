//! The replay firmware: `fsw_firmware::firmware_main` with an ordinary panic handler
//! (log through defmt, exit QEMU with failure).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
#[entry]
fn main() -> ! {
    fsw_firmware::firmware_main()
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    // No core::fmt: the location is enough to find it with addr2line on the caller.
    #[cfg(feature = "defmt")]
    defmt::error!("RESULT: FAIL panic on target");
    fsw_firmware::exit(false)
}
