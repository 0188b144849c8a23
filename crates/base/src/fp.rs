//! The floating-point mode of compute threads: subnormal numbers flushed to zero.
//!
//! Training drives some values (Adam's second moments of tiny gradients, saturated gates) into
//! the subnormal range below 1.2e-38. Intel cores take a microcode assist for every operation
//! on such a number, so a predictor epoch of the demo slowed from 6 s to 10 s as training went
//! on (BENCHMARKS.md, "Subnormal numbers"). Setting the CPU's flush-to-zero and
//! denormals-are-zero flags keeps every epoch at 6 s; the demo's report was identical to the
//! last digit. GPUs and PyTorch's `set_flush_denormal(True)` do the same.
//!
//! The flags belong to a thread, and a thread inherits them from the thread that spawns it
//! (POSIX `pthread_create`; a test below checks it). So [`flush_subnormals`] called first thing
//! in `main` covers every worker pool and scoped thread the process starts afterwards. The
//! libraries never call it: a host process (the Python module's interpreter) keeps IEEE
//! subnormals unless it asks otherwise.

/// Environment variable that keeps IEEE subnormals in the `scbg` binary (any value but empty or
/// `0`), for measuring what the flags buy.
pub const KEEP_SUBNORMALS_ENV: &str = "SCBG_KEEP_SUBNORMALS";

/// Whether [`KEEP_SUBNORMALS_ENV`] asks to keep subnormals.
pub fn keep_subnormals_requested() -> bool {
    asks_to_keep(std::env::var_os(KEEP_SUBNORMALS_ENV).as_deref())
}

fn asks_to_keep(value: Option<&std::ffi::OsStr>) -> bool {
    value.is_some_and(|v| !v.is_empty() && v != "0")
}

/// Flushes subnormal results and inputs to zero on the calling thread and on the threads it
/// spawns afterwards. Returns `false` (and changes nothing) on a CPU architecture without
/// support here (anything but x86-64 and AArch64).
pub fn flush_subnormals() -> bool {
    set_mode(true)
}

/// Restores IEEE subnormals on the calling thread (the default of every new process).
pub fn keep_subnormals() -> bool {
    set_mode(false)
}

/// Whether the calling thread flushes subnormals to zero.
pub fn flushes_subnormals() -> bool {
    imp::get().is_some_and(|bits| bits & imp::FLUSH == imp::FLUSH)
}

fn set_mode(flush: bool) -> bool {
    let Some(bits) = imp::get() else {
        return false;
    };
    imp::set(if flush {
        bits | imp::FLUSH
    } else {
        bits & !imp::FLUSH
    });
    true
}

#[cfg(target_arch = "x86_64")]
mod imp {
    /// MXCSR's flush-to-zero (bit 15) and denormals-are-zero (bit 6) flags. They govern SSE,
    /// AVX and AVX-512 arithmetic alike.
    pub const FLUSH: u32 = (1 << 15) | (1 << 6);

    pub fn get() -> Option<u32> {
        let mut csr: u32 = 0;
        // SAFETY: `stmxcsr` stores the 32-bit MXCSR register at the given address, which
        // points at a live, aligned `u32`; every x86-64 CPU has it.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
        }
        Some(csr)
    }

    pub fn set(csr: u32) {
        // SAFETY: `ldmxcsr` loads MXCSR from a live `u32`. Only the two flush flags differ
        // from the value just read, and neither can raise an exception.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!(
                "ldmxcsr [{}]",
                in(reg) &csr,
                options(nostack, readonly, preserves_flags)
            );
        }
    }
}

#[cfg(target_arch = "aarch64")]
mod imp {
    /// FPCR's FZ flag (bit 24): subnormal inputs and results are flushed to zero.
    pub const FLUSH: u64 = 1 << 24;

    pub fn get() -> Option<u64> {
        let fpcr: u64;
        // SAFETY: reading FPCR has no side effect.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack, preserves_flags));
        }
        Some(fpcr)
    }

    pub fn set(fpcr: u64) {
        // SAFETY: writes back the value just read with only FZ changed.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!("msr fpcr, {}", in(reg) fpcr, options(nomem, nostack, preserves_flags));
        }
    }
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
mod imp {
    pub const FLUSH: u32 = 0;

    pub fn get() -> Option<u32> {
        None
    }

    pub fn set(_: u32) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hint::black_box;

    /// The smallest positive normal f32 halved: a subnormal (5.9e-39).
    fn half_min_positive() -> f32 {
        black_box(f32::MIN_POSITIVE) * black_box(0.5)
    }

    // Each test runs on its own thread, so the flags never leak into another test.
    #[test]
    fn subnormals_survive_by_default_and_flush_when_asked() {
        assert!(!flushes_subnormals());
        let sub = half_min_positive();
        assert!(
            sub > 0.0 && !sub.is_normal(),
            "IEEE gives a subnormal: {sub:e}"
        );
        assert!(flush_subnormals());
        assert!(flushes_subnormals());
        assert_eq!(half_min_positive(), 0.0, "a subnormal result is flushed");
        // Denormals-are-zero (x86-64) / FZ (AArch64): a subnormal input reads as zero.
        let input = black_box(f32::from_bits(1));
        assert_eq!(input * black_box(2.0f32), 0.0);
        // Normal arithmetic is untouched.
        assert_eq!(black_box(1.5f32) * black_box(2.0), 3.0);
        assert!(keep_subnormals());
        assert!(!flushes_subnormals());
        assert!(half_min_positive() > 0.0);
    }

    #[test]
    fn spawned_threads_inherit_the_mode() {
        flush_subnormals();
        let (flag, value) = std::thread::spawn(|| (flushes_subnormals(), half_min_positive()))
            .join()
            .unwrap();
        assert!(flag, "a thread spawned after flush_subnormals flushes too");
        assert_eq!(value, 0.0);
        keep_subnormals();
        let flag = std::thread::spawn(flushes_subnormals).join().unwrap();
        assert!(!flag);
    }

    #[test]
    fn the_environment_variable_keeps_subnormals_unless_empty_or_zero() {
        use std::ffi::OsStr;
        assert!(!asks_to_keep(None));
        assert!(!asks_to_keep(Some(OsStr::new(""))));
        assert!(!asks_to_keep(Some(OsStr::new("0"))));
        assert!(asks_to_keep(Some(OsStr::new("1"))));
        assert!(asks_to_keep(Some(OsStr::new("yes"))));
    }
}
