//! # Cortex-M4 replay of a recorded input sequence through `fsw_core::executive::FlightCore`
//!
//! The fixture (`fixtures/replay.bin`, `fixtures/replay.expected.bin`, written by
//! `cargo run -p fsw-core --example replay_record`) is compiled in with `include_bytes!`.
//! [`run`] feeds every recorded cycle (raw sensor frame + ground commands) to a
//! `FlightCore` held in a static, encodes each cycle's output with the ICD encoders and
//! compares it with the host's output: the CRC-32 of every cycle record, and the whole record
//! where the fixture stores it. The result is logged with defmt over semihosting and the
//! program exits through semihosting with status 0 only on a bit-identical match.
//!
//! Both binaries (`replay`, `no-panic`) run [`firmware_main`]; they differ only in their panic
//! handler.
#![no_std]

/// The replay fixture format and the per-cycle record (shared with the host recorder
/// `fsw-core/examples/replay_record.rs` through `include!`).
pub mod fixture;
#[cfg(feature = "defmt")]
mod logger;

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut};
use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m_semihosting::debug;
use fixture::{
    check_cycle, file_crc, CycleCheck, CycleRecord, ExpectedReader, FixtureError, InputReader,
};
use fsw_core::executive::FlightCore;

/// Logging that forwards to defmt when the `defmt` feature is on and does nothing otherwise.
macro_rules! log_info {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::info!($($t)*);
    }};
}
/// Error-level counterpart of `log_info!`.
macro_rules! log_error {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::error!($($t)*);
    }};
}

/// The recorded inputs (frames and commands).
pub static INPUTS: &[u8] = include_bytes!("../fixtures/replay.bin");
/// The host's outputs for [`INPUTS`].
pub static EXPECTED: &[u8] = include_bytes!("../fixtures/replay.expected.bin");

/// Progress is logged every this many cycles.
const PROGRESS_EVERY: u32 = 100;
/// Mismatching cycles logged in full (the rest are only counted).
const MISMATCHES_LOGGED: u32 = 3;
/// Fill pattern of the unused stack, for the high-water mark.
const STACK_PAINT: u32 = 0xDEAD_C0DE;

/// A cell handing out one `&'static mut` to a value built in place in `.bss`, once; a second
/// `take` returns `None` (where `static_cell`/`singleton!` would panic or need `Option<T>`
/// in `.data`).
pub struct OnceCell<T> {
    taken: AtomicBool,
    value: UnsafeCell<MaybeUninit<T>>,
}

// SAFETY: the `taken` flag gives the inner value to at most one caller.
unsafe impl<T> Sync for OnceCell<T> {}

impl<T> OnceCell<T> {
    /// An empty cell (`const`, so it is placed in `.bss`).
    #[must_use]
    pub const fn new() -> Self {
        Self {
            taken: AtomicBool::new(false),
            value: UnsafeCell::new(MaybeUninit::uninit()),
        }
    }

    /// Initialise with `init` and return the only mutable reference, or `None` if taken.
    // The `taken` flag makes the returned reference unique, which is what this cell is for.
    #[allow(clippy::mut_from_ref)]
    pub fn take(&'static self, init: impl FnOnce() -> T) -> Option<&'static mut T> {
        if self.taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: first and only taker (flag above); `MaybeUninit::write` initialises it.
        let slot = unsafe { &mut *self.value.get() };
        Some(slot.write(init()))
    }
}

impl<T> Default for OnceCell<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The flight core lives in `.bss`, not on the stack (it is ~163 KiB).
static CORE: OnceCell<FlightCore> = OnceCell::new();

/// Outcome of a replay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Summary {
    /// Cycles replayed.
    pub cycles: u32,
    /// Cycles whose output differed from the host's.
    pub mismatches: u32,
    /// First mismatching cycle.
    pub first_mismatch: Option<u32>,
    /// Full records compared byte for byte.
    pub full_records_compared: u32,
    /// CRC-32 of the last cycle record.
    pub last_digest: u32,
}

/// Replay the compiled-in fixture through `core`.
///
/// # Errors
/// [`FixtureError`] when the fixture cannot be read or the two files do not belong together.
pub fn run(core: &mut FlightCore) -> Result<Summary, FixtureError> {
    // Opaque to the optimiser: the no-panic proof must hold for any fixture bytes, not only
    // for the compiled-in ones.
    let input_bytes: &'static [u8] = core::hint::black_box(INPUTS);
    let expected_bytes: &'static [u8] = core::hint::black_box(EXPECTED);
    let mut inputs = InputReader::new(input_bytes)?;
    let mut expected = ExpectedReader::new(expected_bytes)?;
    let inputs_crc = file_crc(input_bytes);
    log_info!(
        "fixture: {=usize} B inputs (CRC-32 {=u32:08x}), {=usize} B expected, {=u32} cycles, {=usize} table images",
        input_bytes.len(),
        inputs_crc,
        expected_bytes.len(),
        inputs.header.cycles,
        inputs.images().len()
    );
    if expected.header.inputs_crc != inputs_crc || expected.header.cycles != inputs.header.cycles {
        log_error!(
            "expected outputs belong to inputs with CRC-32 {=u32:08x}, {=u32} cycles",
            expected.header.inputs_crc,
            expected.header.cycles
        );
        return Err(FixtureError::BadHeader);
    }
    let mut summary = Summary {
        cycles: 0,
        mismatches: 0,
        first_mismatch: None,
        full_records_compared: 0,
        last_digest: 0,
    };
    loop {
        let (cycle, want) = match (inputs.next_cycle(), expected.next_cycle()) {
            (None, None) => break,
            (Some(c), Some(e)) => (c?, e?),
            _ => return Err(FixtureError::TrailingBytes),
        };
        let n = summary.cycles;
        let commands = inputs.commands(&cycle)?;
        let out = core.step(&cycle.frame, &commands);
        let record = CycleRecord::encode(&out)?;
        summary.last_digest = record.digest();
        if want.record.is_some() {
            summary.full_records_compared = summary.full_records_compared.saturating_add(1);
        }
        match check_cycle(&record, &want) {
            CycleCheck::Match => {}
            mismatch => {
                summary.mismatches = summary.mismatches.saturating_add(1);
                if summary.first_mismatch.is_none() {
                    summary.first_mismatch = Some(n);
                }
                if summary.mismatches <= MISMATCHES_LOGGED {
                    log_error!("cycle {=u32}: MISMATCH {}", n, mismatch);
                    log_error!("cycle {=u32}: target housekeeping {}", n, out.housekeeping);
                    log_error!("cycle {=u32}: target events {}", n, out.events.as_slice());
                }
            }
        }
        summary.cycles = summary.cycles.saturating_add(1);
        if summary.cycles.is_multiple_of(PROGRESS_EVERY) {
            let hk = &out.housekeeping;
            log_info!(
                "cycle {=u32}: digest {=u32:08x}, filter mode {=u8}, control mode {=u8}, accepted {=u32}, mismatches so far {=u32}",
                n,
                summary.last_digest,
                hk.filter_mode,
                hk.control_mode,
                hk.counters.accepted_measurements,
                summary.mismatches
            );
        }
    }
    Ok(summary)
}

extern "C" {
    /// End of `.bss`/`.uninit` (start of the unused RAM below the stack), from cortex-m-rt's
    /// link.x.
    static mut __sheap: u32;
    /// Initial stack pointer (top of RAM), from cortex-m-rt's link.x.
    static mut _stack_start: u32;
}

/// Fill the RAM between the end of `.bss` and the current stack pointer (less a margin)
/// with [`STACK_PAINT`].
fn paint_stack() {
    let start = addr_of_mut!(__sheap) as usize;
    let sp = cortex_m::register::msp::read() as usize;
    let end = sp.saturating_sub(512);
    let mut addr = start;
    while addr < end {
        // SAFETY: [start, end) is RAM above .bss and below the live stack, unused by anything
        // (no heap), 4-byte aligned (cortex-m-rt aligns __sheap).
        unsafe { core::ptr::write_volatile(addr as *mut u32, STACK_PAINT) };
        addr = addr.saturating_add(4);
    }
}

/// Deepest stack use since [`paint_stack`], bytes.
fn stack_high_water() -> usize {
    let start = addr_of!(__sheap) as usize;
    let top = addr_of!(_stack_start) as usize;
    let mut addr = start;
    while addr < top {
        // SAFETY: reading RAM inside the memory map (painted region and stack).
        let v = unsafe { core::ptr::read_volatile(addr as *const u32) };
        if v != STACK_PAINT {
            break;
        }
        addr = addr.saturating_add(4);
    }
    top.saturating_sub(addr)
}

/// A reachable, unprovable bounds check: with the `no-panic-canary` feature the `no-panic`
/// binary must fail to link (the self-test of `scripts/no-panic-check.sh`).
#[cfg(feature = "no-panic-canary")]
#[inline(never)]
#[allow(clippy::indexing_slicing)]
fn canary() {
    let i = core::hint::black_box(INPUTS.len());
    let b = INPUTS[i];
    log_info!("canary {=u8}", b);
}

/// Exit QEMU through semihosting with success or failure.
pub fn exit(success: bool) -> ! {
    debug::exit(if success {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Not reached under QEMU; on hardware without a debugger, park.
    loop {
        cortex_m::asm::wfi();
    }
}

/// A fault (bad memory access, stack overflow into the memory map's holes) ends the run
/// with failure instead of QEMU spinning in the default handler.
#[cortex_m_rt::exception]
unsafe fn HardFault(ef: &cortex_m_rt::ExceptionFrame) -> ! {
    log_error!("RESULT: FAIL HardFault at pc {=u32:08x}", ef.pc());
    let _ = ef;
    exit(false)
}

/// The whole program: paint the stack, build the core in `.bss`, replay, report, exit.
pub fn firmware_main() -> ! {
    paint_stack();
    log_info!(
        "fsw-firmware replay on Cortex-M4 (QEMU mps2-an386); size_of::<FlightCore>() = {=usize} B",
        core::mem::size_of::<FlightCore>()
    );
    let Some(core) = CORE.take(FlightCore::new) else {
        log_error!("RESULT: FAIL flight core already taken");
        exit(false)
    };
    #[cfg(feature = "no-panic-canary")]
    canary();
    let result = run(core);
    let stack = stack_high_water();
    let ok = match result {
        Ok(s) => {
            log_info!(
                "replayed {=u32} cycles: {=u32} mismatches, {=u32} full records compared, last digest {=u32:08x}; stack high-water {=usize} B",
                s.cycles,
                s.mismatches,
                s.full_records_compared,
                s.last_digest,
                stack
            );
            if s.mismatches == 0 && s.cycles > 0 {
                log_info!(
                    "RESULT: PASS bit-identical to the host on all {=u32} cycles",
                    s.cycles
                );
                true
            } else {
                log_error!(
                    "RESULT: FAIL {=u32} of {=u32} cycles differ, first {}",
                    s.mismatches,
                    s.cycles,
                    s.first_mismatch
                );
                false
            }
        }
        Err(e) => {
            log_error!("RESULT: FAIL fixture error {}", e);
            false
        }
    };
    exit(ok)
}
