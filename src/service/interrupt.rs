//! A clean stop on SIGINT or SIGTERM: a batch system's time limit (Slurm sends SIGTERM,
//! then SIGKILL after its grace period) or Ctrl-C.
//!
//! While [`while_computing`] runs its work, the first of these signals only sets a flag. The compute
//! threads then take no new row and hand over the rows they have finished; the I/O
//! master hands out no more work, writes what it received and closes the file with its
//! index, as after a failed worker; the run ends with [`super::ServiceError::Interrupted`],
//! and `--resume` computes the rest without scanning the file. The handler gives both
//! signals their default action back when it runs, so a second one of either kind ends
//! the process at once (the file then stays readable by a scan, as after SIGKILL).
//!
//! Under MPI every rank installs it. A worker rank that is signalled hands over its
//! finished rows and says done; rank 0, signalled, stops handing out rows, waits for
//! every worker's done, closes the file and lets the workers finalise. A batch
//! system's direct launch (srun) signals every rank; Open MPI's `mpirun` forwards
//! SIGINT and SIGTERM to every rank as SIGTERM, then ends the job about two seconds
//! later. If only workers are signalled, rank 0 finds rows missing at the end and says
//! so (an error, not a complete file).
//!
//! A signal that is ignored when the work starts (SIGINT for a job started in the
//! background of a non-interactive shell) stays ignored.

use std::sync::atomic::{AtomicI32, Ordering};

/// The first signal caught, or 0.
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// The signal that asked the run to stop, if one did.
pub fn interrupted() -> Option<i32> {
    match SIGNAL.load(Ordering::Relaxed) {
        0 => None,
        s => Some(s),
    }
}

/// The signal's name: "SIGINT", "SIGTERM", else "signal N".
pub fn signal_name(signal: i32) -> String {
    #[cfg(unix)]
    match signal {
        libc::SIGINT => return "SIGINT".into(),
        libc::SIGTERM => return "SIGTERM".into(),
        _ => {}
    }
    format!("signal {signal}")
}

/// The signals caught, and whether [`catch_signals`] installed the handler for each.
#[cfg(unix)]
const CAUGHT: [libc::c_int; 2] = [libc::SIGINT, libc::SIGTERM];
#[cfg(unix)]
static INSTALLED: [std::sync::atomic::AtomicBool; 2] = [
    std::sync::atomic::AtomicBool::new(false),
    std::sync::atomic::AtomicBool::new(false),
];

#[cfg(unix)]
extern "C" fn on_signal(signal: libc::c_int) {
    // Lock-free atomics, signal(2) and raise(3): all async-signal-safe.
    let first = SIGNAL
        .compare_exchange(0, signal, Ordering::Relaxed, Ordering::Relaxed)
        .is_ok();
    for (k, &s) in CAUGHT.iter().enumerate() {
        if INSTALLED[k].load(Ordering::Relaxed) {
            // SAFETY: signal(2) with a valid signal number and SIG_DFL.
            unsafe {
                libc::signal(s, libc::SIG_DFL);
            }
        }
    }
    if !first {
        // A second signal that reached another thread before the reset above (the
        // mask that blocks both during the handler holds for one thread only): its
        // default action, once this handler returns.
        // SAFETY: raise(3) with a valid signal number.
        unsafe {
            libc::raise(signal);
        }
    }
}

/// Runs `work` with the handler in place (see the module documentation): installed
/// before, and the signals given their default action back after ([`release`]), so a
/// later phase, such as `run`'s solve, stops on Ctrl-C at once again. A signal caught
/// during `work` stays recorded ([`interrupted`]).
///
/// # Errors
/// sigaction(2) failed (it should not); `work` has not run.
pub fn while_computing<T>(work: impl FnOnce() -> T) -> std::io::Result<T> {
    catch_signals()?;
    let done = work();
    release();
    Ok(done)
}

/// Installs the handler for SIGINT and SIGTERM; a no-op where there are no such
/// signals.
fn catch_signals() -> std::io::Result<()> {
    #[cfg(unix)]
    for (k, &signal) in CAUGHT.iter().enumerate() {
        // SAFETY: sigaction(2) with a zeroed struct whose handler is an extern "C" fn
        // that only stores to an atomic, its mask emptied by sigemptyset, and valid
        // pointers for the new and the old action.
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(signal, std::ptr::null(), &mut old) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if old.sa_sigaction == libc::SIG_IGN {
                continue;
            }
            let mut new: libc::sigaction = std::mem::zeroed();
            new.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            new.sa_flags = libc::SA_RESTART;
            // Both blocked while it runs: the other is handled after the reset.
            libc::sigemptyset(&mut new.sa_mask);
            for &s in &CAUGHT {
                libc::sigaddset(&mut new.sa_mask, s);
            }
            INSTALLED[k].store(true, Ordering::Relaxed);
            if libc::sigaction(signal, &new, std::ptr::null_mut()) != 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
    }
    Ok(())
}

/// Gives the signals [`catch_signals`] caught their default action back.
fn release() {
    #[cfg(unix)]
    for (k, &signal) in CAUGHT.iter().enumerate() {
        if INSTALLED[k].swap(false, Ordering::Relaxed) {
            // SAFETY: signal(2) with a valid signal number and SIG_DFL.
            unsafe {
                libc::signal(signal, libc::SIG_DFL);
            }
        }
    }
}
