//! A panic-free defmt global logger over Arm semihosting (`SYS_WRITE` to the host's stdout).
//!
//! Same wire behaviour as `defmt-semihosting` 0.4 (rzCOBS frames written with `SYS_WRITE`),
//! written here because that crate keeps three `panic!`s (re-entrant acquire, release/write
//! out of context) and `semihosting`'s `BorrowedFd` assertion in the binary, which the
//! link-time no-panic check (`scripts/no-panic-check.sh`) refuses. Here a nested `acquire`
//! (impossible in this single-threaded, interrupt-free program) is counted and its frame
//! dropped instead of panicking, and host-I/O errors are ignored.
//!
//! Do not mix with other semihosting writes to stdout: they would corrupt the defmt frames.

use core::cell::UnsafeCell;
use cortex_m_semihosting::hio::{self, HostStream};

#[defmt::global_logger]
struct SemihostingLogger;

struct State {
    /// Acquire nesting depth; only depth 1 writes.
    depth: u8,
    /// Critical-section state to restore on the outermost release.
    restore: critical_section::RestoreState,
    encoder: defmt::Encoder,
    /// Host stdout, opened on first use.
    out: Option<HostStream>,
}

struct Shared(UnsafeCell<State>);

// SAFETY: every access happens inside the critical section taken by `acquire` and held until
// the matching `release` (single core).
unsafe impl Sync for Shared {}

static STATE: Shared = Shared(UnsafeCell::new(State {
    depth: 0,
    restore: critical_section::RestoreState::invalid(),
    encoder: defmt::Encoder::new(),
    out: None,
}));

fn emit(out: &mut Option<HostStream>, bytes: &[u8]) {
    if let Some(h) = out {
        let _ = h.write_all(bytes);
    }
}

// SAFETY (for the trait): defmt guarantees acquire/write/flush/release pairing per frame.
unsafe impl defmt::Logger for SemihostingLogger {
    fn acquire() {
        // SAFETY: paired with `critical_section::release` in `release` (outermost) or right
        // below (nested).
        let restore = unsafe { critical_section::acquire() };
        // SAFETY: inside the critical section.
        let s = unsafe { &mut *STATE.0.get() };
        if s.depth != 0 {
            s.depth = s.depth.saturating_add(1);
            // SAFETY: nested section; the outer one still holds.
            unsafe { critical_section::release(restore) };
            return;
        }
        s.depth = 1;
        s.restore = restore;
        if s.out.is_none() {
            s.out = hio::hstdout().ok();
        }
        let State { encoder, out, .. } = s;
        encoder.start_frame(|b| emit(out, b));
    }

    unsafe fn flush() {
        // Semihosting writes are blocking: nothing is buffered on the target.
    }

    unsafe fn release() {
        // SAFETY: called by defmt after `acquire`, inside the critical section.
        let s = unsafe { &mut *STATE.0.get() };
        match s.depth {
            0 => {}
            1 => {
                let State { encoder, out, .. } = s;
                encoder.end_frame(|b| emit(out, b));
                s.depth = 0;
                let restore = s.restore;
                // SAFETY: the outermost acquire's state, released exactly once.
                unsafe { critical_section::release(restore) };
            }
            _ => s.depth = s.depth.saturating_sub(1),
        }
    }

    unsafe fn write(bytes: &[u8]) {
        // SAFETY: called by defmt between `acquire` and `release`.
        let s = unsafe { &mut *STATE.0.get() };
        if s.depth == 1 {
            let State { encoder, out, .. } = s;
            encoder.write(bytes, |b| emit(out, b));
        }
    }
}
