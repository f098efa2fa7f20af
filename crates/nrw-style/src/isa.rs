//! The vector instructions the style kernels are compiled for, chosen once at run time, and
//! `multiversion!`, which compiles a function body for each (AVX-512, AVX2 + FMA, baseline).

/// The vector instructions the transforms are compiled for, chosen once at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    Avx512,
    Avx2,
    Baseline,
}

impl Isa {
    /// The name reported with benchmark figures.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512f",
            Isa::Avx2 => "avx2+fma",
            Isa::Baseline => "baseline",
        }
    }
}

/// The widest instruction set this machine and build allow: AVX-512 only with the crate's
/// `avx512` feature (on by default; off, the `gemm` crate's AVX-512 kernels are off too, which
/// is how a benchmark measures an AVX2-only machine on an AVX-512 one).
pub fn isa() -> Isa {
    static ISA: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
    *ISA.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            if cfg!(feature = "avx512")
                && std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Isa::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    })
}

#[cfg(test)]
thread_local! {
    /// Tests force an instruction set on their own thread to compare the three builds.
    pub(crate) static FORCE: std::cell::Cell<Option<Isa>> = const { std::cell::Cell::new(None) };
}

/// The instruction set the transforms run with on this thread: [`isa`], or in tests a forced one.
pub(crate) fn current_isa() -> Isa {
    #[cfg(test)]
    if let Some(forced) = FORCE.get() {
        return forced;
    }
    isa()
}

/// Defines `$name` with the given body compiled three times (AVX-512, AVX2 + FMA, baseline)
/// and run in the build [`isa`] chose. Rust never contracts a·b + c into an FMA by itself, so
/// the three give the same bits.
macro_rules! multiversion {
    ($(#[$meta:meta])* fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {
        $(#[$meta])*
        fn $name($($arg: $ty),*) {
            #[inline(always)]
            fn imp($($arg: $ty),*) $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
                unsafe fn wide($($arg: $ty),*) {
                    imp($($arg),*)
                }
                #[target_feature(enable = "avx2,fma")]
                unsafe fn narrow($($arg: $ty),*) {
                    imp($($arg),*)
                }
                match $crate::isa::current_isa() {
                    // SAFETY: isa() detected these instructions on this CPU (tests force
                    // only what it allows).
                    $crate::isa::Isa::Avx512 => return unsafe { wide($($arg),*) },
                    $crate::isa::Isa::Avx2 => return unsafe { narrow($($arg),*) },
                    $crate::isa::Isa::Baseline => {}
                }
            }
            imp($($arg),*)
        }
    };
}
