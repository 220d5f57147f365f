//! IEEE arithmetic for the length of a run, whatever the calling thread set. A host may run its
//! threads with subnormals flushed to zero (XLA does, so a `hybc.jax` call arrives that way;
//! so can a numerical library loaded beside us). A run then computes other numbers than the CLI,
//! and the searches that step one spacing of `t` at a time see `0.next_up() - 0 == 0`: the knot
//! queue's search from `t = 0` never moved and a JAX call hung. [`IeeeArithmetic::enter`]
//! clears the flush-to-zero and denormals-are-zero bits of the thread's floating-point control
//! register and puts the caller's back when dropped, so a run is bit for bit the same from every
//! front end. Two register accesses per run; on other targets it does nothing (their default
//! mode is IEEE and a host that changes it is not caught).

#![allow(unsafe_code)]

/// The caller's floating-point control word, restored on drop when the guard changed it.
pub(crate) struct IeeeArithmetic {
    #[cfg_attr(not(any(target_arch = "x86_64", target_arch = "aarch64")), allow(dead_code))]
    saved: Option<u64>,
}

#[cfg(target_arch = "x86_64")]
mod register {
    /// MXCSR's flush-to-zero (bit 15) and denormals-are-zero (bit 6).
    const FLUSH: u32 = (1 << 15) | (1 << 6);

    pub fn read() -> u64 {
        let mut csr: u32 = 0;
        // SAFETY: `stmxcsr` stores the 32-bit MXCSR to the given address, a live local (SSE is
        // part of x86_64's baseline).
        unsafe { core::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags)) };
        u64::from(csr)
    }

    pub fn write(word: u64) {
        let csr = word as u32;
        // SAFETY: `ldmxcsr` loads a value read by `stmxcsr` with only the flush bits changed,
        // both of which are defined bits of MXCSR.
        unsafe { core::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, preserves_flags)) };
    }

    pub fn ieee(word: u64) -> u64 {
        word & !u64::from(FLUSH)
    }
}

#[cfg(target_arch = "aarch64")]
mod register {
    /// FPCR's flush-to-zero (bit 24) and half-precision flush (bit 19).
    const FLUSH: u64 = (1 << 24) | (1 << 19);

    pub fn read() -> u64 {
        let fpcr: u64;
        // SAFETY: reading FPCR has no side effect.
        unsafe { core::arch::asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack, preserves_flags)) };
        fpcr
    }

    pub fn write(word: u64) {
        // SAFETY: writes back a value read from FPCR with only its flush bits changed.
        unsafe { core::arch::asm!("msr fpcr, {}", in(reg) word, options(nomem, nostack, preserves_flags)) };
    }

    pub fn ieee(word: u64) -> u64 {
        word & !FLUSH
    }
}

impl IeeeArithmetic {
    /// Subnormals computed and read as themselves until the guard is dropped.
    pub(crate) fn enter() -> IeeeArithmetic {
        #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
        {
            let word = register::read();
            let ieee = register::ieee(word);
            if ieee == word {
                return IeeeArithmetic { saved: None };
            }
            register::write(ieee);
            IeeeArithmetic { saved: Some(word) }
        }
        #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
        IeeeArithmetic { saved: None }
    }
}

impl Drop for IeeeArithmetic {
    fn drop(&mut self) {
        // The caller's exception flags come back with its mode: what the run raised is not theirs.
        #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
        if let Some(word) = self.saved {
            register::write(word);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `x` through an opaque path, so the compiler cannot fold the arithmetic at build time.
    fn opaque(x: f64) -> f64 {
        std::hint::black_box(x)
    }

    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    #[test]
    fn a_flushing_thread_gets_subnormals_inside_the_guard_and_its_mode_back_after() {
        let caller = register::read();
        // The mode of a host that flushes (what XLA's threads run with).
        #[cfg(target_arch = "x86_64")]
        let flushing = caller | (1 << 15) | (1 << 6);
        #[cfg(target_arch = "aarch64")]
        let flushing = caller | (1 << 24);
        register::write(flushing);
        let tiny = opaque(f64::MIN_POSITIVE);
        let flushed = opaque(tiny) / opaque(4.0);
        {
            let _ieee = IeeeArithmetic::enter();
            let kept = opaque(tiny) / opaque(4.0);
            assert_eq!(kept, f64::MIN_POSITIVE / 4.0, "a subnormal quotient inside the guard");
            assert!(kept > 0.0);
            assert_eq!(opaque(0.0f64).next_up() - opaque(0.0), 5e-324);
        }
        let after = register::read();
        register::write(caller);
        assert_eq!(flushed, 0.0, "the host's mode flushes (else the test proves nothing)");
        // MXCSR's low six bits are sticky exception flags, not mode.
        #[cfg(target_arch = "x86_64")]
        let mode = |word: u64| word & !0x3f;
        #[cfg(target_arch = "aarch64")]
        let mode = |word: u64| word;
        assert_eq!(mode(after), mode(flushing), "the host's mode is back after the guard");
    }
}
