//! The vector instructions the style kernels run with (nrw-gemm's choice, made once at run
//! time, so the transforms and the GEMMs agree), and `multiversion!`, which compiles a
//! function body for each (AVX-512, AVX2 + FMA, baseline).

pub use nrw_gemm::{isa, Isa};

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
