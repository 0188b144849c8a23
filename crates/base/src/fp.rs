//! The floating-point mode of compute threads: subnormal numbers flushed to zero.
//!
//! Training drives some values into the subnormal range below 1.2e-38 (Adam's moment
//! estimates: 15 % of the demo's final optimizer state). Intel cores take a microcode assist
//! for every operation on such a number, so a predictor epoch of the demo grew from 6 s to
//! 10 s as training went on (docs/findings.md, *Subnormal floats*). Setting the CPU's
//! flush-to-zero and denormals-are-zero flags keeps every epoch at 6 s; the demo's report was
//! identical to the last digit. PyTorch's `torch.set_flush_denormal(True)` and CUDA's
//! `-ftz` make the same trade.
//!
//! The flags belong to a thread. The `scbg` binary calls [`flush_subnormals`] first thing in
//! `main`; code that starts threads carries the starting thread's [`Mode`] over to them
//! (`Mode::current()` before, `Mode::apply()` on the new thread), because only Linux hands a
//! new thread its creator's flags (macOS and Windows start it with the defaults). The libraries
//! never choose the mode themselves: a host process (the Python module's interpreter) keeps
//! IEEE subnormals unless it asks otherwise.
//!
//! Rust and LLVM assume the default floating-point environment: a value folded at compile time
//! keeps its IEEE subnormal while the same expression at run time flushes. Only subnormal
//! values, already below f32's resolution around any normal number, can differ.

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

/// Flushes subnormal results and inputs to zero on the calling thread (and, on Linux, on the
/// threads it spawns afterwards). Returns `false` (and changes nothing) on a CPU architecture
/// without support here (anything but x86-64 and AArch64).
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

/// A thread's floating-point mode, to carry over to the threads it starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mode {
    /// Subnormals flushed to zero.
    pub flush_subnormals: bool,
}

impl Mode {
    /// The calling thread's mode.
    pub fn current() -> Self {
        Self {
            flush_subnormals: flushes_subnormals(),
        }
    }

    /// Makes it the calling thread's mode (nothing on an architecture without support).
    pub fn apply(self) {
        set_mode(self.flush_subnormals);
    }
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
        // points at a live, aligned `u32`; every x86-64 CPU has it. Reading changes nothing.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
        }
        Some(csr)
    }

    pub fn set(csr: u32) {
        // SAFETY: `ldmxcsr` loads MXCSR from a live `u32`. Only the two flush flags differ
        // from the value just read (the exception flags raised since may be cleared: the
        // asm does not claim to preserve them), and neither flush flag can raise an
        // exception. Memory safety does not depend on the floating-point mode; the module's
        // docs say which results may differ from code folded at compile time.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, readonly));
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
            core::arch::asm!(
                "mrs {}, fpcr",
                out(reg) fpcr,
                options(nomem, nostack, preserves_flags)
            );
        }
        Some(fpcr)
    }

    pub fn set(fpcr: u64) {
        // SAFETY: writes back the value just read with only FZ changed (see the x86-64
        // `set` on the mode and compile-time folding).
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!(
                "msr fpcr, {}",
                in(reg) fpcr,
                options(nomem, nostack, preserves_flags)
            );
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

    /// The smallest positive normal f32 halved: a subnormal (5.9e-39) under IEEE rules.
    fn half_min_positive() -> f32 {
        black_box(f32::MIN_POSITIVE) * black_box(0.5)
    }

    /// The smallest subnormal scaled up by 2^100: the normal 2^-49 under IEEE rules, zero when
    /// subnormal inputs read as zero.
    fn scaled_smallest_subnormal() -> f32 {
        black_box(f32::from_bits(1)) * black_box(2f32.powi(100))
    }

    // Each test runs on its own thread, so the flags never leak into another test. Results
    // are compared by their bits: a comparison of floats would itself read a subnormal as 0.
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    #[test]
    fn subnormals_survive_by_default_and_flush_when_asked() {
        assert!(!flushes_subnormals());
        let sub = half_min_positive();
        assert_eq!(sub.to_bits(), 1 << 22, "IEEE gives a subnormal: {sub:e}");
        assert_eq!(scaled_smallest_subnormal(), 2f32.powi(-49));
        assert!(flush_subnormals());
        assert!(flushes_subnormals());
        assert_eq!(
            half_min_positive().to_bits(),
            0,
            "a subnormal result is flushed"
        );
        assert_eq!(
            scaled_smallest_subnormal().to_bits(),
            0,
            "a subnormal input reads as zero"
        );
        assert_eq!(black_box(1.5f32) * black_box(2.0), 3.0, "normal arithmetic");
        assert!(keep_subnormals());
        assert!(!flushes_subnormals());
        assert_eq!(half_min_positive().to_bits(), 1 << 22);
    }

    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    #[test]
    fn a_mode_carries_over_to_a_new_thread() {
        flush_subnormals();
        let mode = Mode::current();
        assert!(mode.flush_subnormals);
        let bits = std::thread::spawn(move || {
            keep_subnormals(); // whatever the platform handed over
            mode.apply();
            (flushes_subnormals(), half_min_positive().to_bits())
        })
        .join()
        .unwrap();
        assert_eq!(bits, (true, 0));
        keep_subnormals();
        let mode = Mode::current();
        let bits = std::thread::spawn(move || {
            flush_subnormals();
            mode.apply();
            (flushes_subnormals(), half_min_positive().to_bits())
        })
        .join()
        .unwrap();
        assert_eq!(bits, (false, 1 << 22));
    }

    /// What the binary relies on for threads it does not start itself on Linux.
    #[cfg(all(
        target_os = "linux",
        any(target_arch = "x86_64", target_arch = "aarch64")
    ))]
    #[test]
    fn linux_threads_inherit_the_mode() {
        flush_subnormals();
        let bits = std::thread::spawn(|| (flushes_subnormals(), half_min_positive().to_bits()))
            .join()
            .unwrap();
        assert_eq!(bits, (true, 0));
    }

    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    #[test]
    fn other_architectures_report_no_support() {
        assert!(!flush_subnormals());
        assert!(!flushes_subnormals());
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
