//! One GEMM entry point for the crates that multiply matrices (style descriptors, neighbours,
//! segmentation), with the instruction set chosen once at run time: the widest this CPU has,
//! or a narrower one named by `NRW_ISA`, so one build computes what an AVX-512, an AVX2 or a
//! baseline machine computes (the golden tests and the benchmarks use that).
//!
//! The `gemm` crate picks its kernels by CPU detection alone. Its AVX-512 path is called as it
//! is; the AVX2 + FMA and baseline paths are the same generic driver (`gemm-common`) with the
//! same microkernels (`gemm-f32`, `gemm-f64`) that its dispatch runs on a machine without
//! AVX-512, called here directly, after the same operand normalisation as `gemm::gemm`.

use std::sync::OnceLock;

pub use gemm::Parallelism;

/// The environment variable that caps the instruction set (`avx512f`, `avx2+fma`, `baseline`).
pub const ISA_VAR: &str = "NRW_ISA";

/// The vector instructions the kernels run with, chosen once at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Isa {
    Baseline,
    Avx2,
    Avx512,
}

impl Isa {
    /// Every instruction set, narrowest first.
    pub const ALL: [Isa; 3] = [Isa::Baseline, Isa::Avx2, Isa::Avx512];

    /// The name reported with descriptors and benchmark figures, and accepted by `NRW_ISA`.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512f",
            Isa::Avx2 => "avx2+fma",
            Isa::Baseline => "baseline",
        }
    }

    /// The instruction set a name (as [`Isa::name`] prints it) stands for.
    pub fn from_name(name: &str) -> Option<Isa> {
        Isa::ALL.into_iter().find(|i| i.name() == name)
    }
}

/// Why `NRW_ISA` cannot be honoured.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum IsaError {
    #[error("{ISA_VAR}={value:?} names no instruction set (known: avx512f, avx2+fma, baseline)")]
    Unknown { value: String },
    #[error("{ISA_VAR}={} asks for instructions this CPU lacks: the widest it has is {}", .asked.name(), .widest.name())]
    Unavailable { asked: Isa, widest: Isa },
}

/// The widest instruction set this CPU has (AVX-512 needs F, VL and FMA; AVX2 needs FMA too).
pub fn widest() -> Isa {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("fma")
        {
            return Isa::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return Isa::Avx2;
        }
    }
    Isa::Baseline
}

/// The instruction set a value of `NRW_ISA` (None: unset) selects on a CPU whose widest is
/// `widest`: it may narrow the choice, never widen it.
pub fn choose(requested: Option<&str>, widest: Isa) -> Result<Isa, IsaError> {
    let Some(value) = requested.map(str::trim).filter(|v| !v.is_empty()) else {
        return Ok(widest);
    };
    let asked = Isa::from_name(value).ok_or_else(|| IsaError::Unknown {
        value: value.to_string(),
    })?;
    if asked > widest {
        return Err(IsaError::Unavailable { asked, widest });
    }
    Ok(asked)
}

/// The instruction set of this process, or why `NRW_ISA` is refused: binaries call it first,
/// so a bad value is an error before any work.
pub fn configured() -> Result<Isa, IsaError> {
    choose(std::env::var(ISA_VAR).ok().as_deref(), widest())
}

/// The instruction set every kernel of this process runs with ([`configured`]; where that is
/// an error, which the binaries report before any work, the widest the CPU has).
pub fn isa() -> Isa {
    static ISA: OnceLock<Isa> = OnceLock::new();
    *ISA.get_or_init(|| configured().unwrap_or_else(|_| widest()))
}

/// The element types the GEMM takes.
pub trait Element: Copy + Send + Sync + 'static + sealed::Sealed {
    /// dst := alpha·dst + beta·lhs·rhs with the AVX2 + FMA kernels, operands normalised.
    #[doc(hidden)]
    unsafe fn narrow(p: Operands<Self>, par: Parallelism);
    /// The same with the scalar kernels.
    #[doc(hidden)]
    unsafe fn scalar(p: Operands<Self>, par: Parallelism);
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// A GEMM's operands after normalisation: the destination column-preferring and every stride
/// non-negative, as `gemm::gemm` hands them to its kernels.
#[doc(hidden)]
#[derive(Clone, Copy)]
pub struct Operands<T> {
    m: usize,
    n: usize,
    k: usize,
    dst: *mut T,
    dst_cs: isize,
    dst_rs: isize,
    read_dst: bool,
    lhs: *const T,
    lhs_cs: isize,
    lhs_rs: isize,
    rhs: *const T,
    rhs_cs: isize,
    rhs_rs: isize,
    alpha: T,
    beta: T,
}

/// gemm-common's generic driver over normalised operands `$p` with the SIMD value `$simd`,
/// `$n` lanes a register and the microkernel module `$k` (its `UKR`, `H_UKR` and sizes): what
/// gemm's own `gemm_basic` of that kernel family runs.
macro_rules! drive {
    ($ty:ident, $simd:expr, $n:expr, $k:ident, $p:ident, $par:ident) => {
        gemm_common::gemm::gemm_basic_generic::<
            _,
            $ty,
            { $n },
            { $k::MR_DIV_N * $n },
            { $k::NR },
            { $k::MR_DIV_N },
            { $k::H_M },
            { $k::H_N },
        >(
            $simd,
            $p.m,
            $p.n,
            $p.k,
            $p.dst,
            $p.dst_cs,
            $p.dst_rs,
            $p.read_dst,
            $p.lhs,
            $p.lhs_cs,
            $p.lhs_rs,
            $p.rhs,
            $p.rhs_cs,
            $p.rhs_rs,
            $p.alpha,
            $p.beta,
            false,
            false,
            false,
            |a, b, c| a * b + c,
            &$k::UKR,
            &$k::H_UKR,
            false,
            $par,
        )
    };
}

/// Implements [`Element`] for one type from gemm's microkernels of that type: `$n` is the
/// lanes of one AVX2 register (what gemm's `gemm_def!` passes as `4 × multiplier`).
macro_rules! element {
    ($ty:ident, $kernels:ident, $n:expr) => {
        impl Element for $ty {
            unsafe fn narrow(p: Operands<$ty>, par: Parallelism) {
                #[cfg(target_arch = "x86_64")]
                {
                    use $kernels::microkernel::fma::$ty as k;
                    let simd = <gemm_common::simd::V3 as gemm_common::simd::MixedSimd<
                        $ty,
                        $ty,
                        $ty,
                        $ty,
                    >>::try_new()
                    .expect("the AVX2 + FMA kernels run only where isa() found them");
                    drive!($ty, simd, $n, k, p, par);
                }
                #[cfg(not(target_arch = "x86_64"))]
                Self::scalar(p, par)
            }

            unsafe fn scalar(p: Operands<$ty>, par: Parallelism) {
                use $kernels::microkernel::scalar::$ty as k;
                drive!($ty, gemm_common::simd::Scalar, 1, k, p, par);
            }
        }
    };
}

element!(f32, gemm_f32, 8);
element!(f64, gemm_f64, 4);

/// dst := alpha·dst + beta·lhs·rhs (dst read only when `read_dst`), with `gemm::gemm`'s
/// arguments and strides, run with the kernels of [`isa`].
///
/// # Safety
/// As `gemm::gemm`: every element the strides reach lies inside its allocation, and `dst`
/// aliases neither operand.
#[allow(clippy::too_many_arguments)]
pub unsafe fn gemm<T: Element>(
    m: usize,
    n: usize,
    k: usize,
    dst: *mut T,
    dst_cs: isize,
    dst_rs: isize,
    read_dst: bool,
    lhs: *const T,
    lhs_cs: isize,
    lhs_rs: isize,
    rhs: *const T,
    rhs_cs: isize,
    rhs_rs: isize,
    alpha: T,
    beta: T,
    par: Parallelism,
) {
    gemm_with(
        isa(),
        Operands {
            m,
            n,
            k,
            dst,
            dst_cs,
            dst_rs,
            read_dst,
            lhs,
            lhs_cs,
            lhs_rs,
            rhs,
            rhs_cs,
            rhs_rs,
            alpha,
            beta,
        },
        par,
    )
}

/// [`gemm`] with the kernels of `isa` (never wider than [`widest`]).
unsafe fn gemm_with<T: Element>(isa: Isa, p: Operands<T>, par: Parallelism) {
    match isa {
        Isa::Avx512 => gemm::gemm(
            p.m, p.n, p.k, p.dst, p.dst_cs, p.dst_rs, p.read_dst, p.lhs, p.lhs_cs, p.lhs_rs, p.rhs,
            p.rhs_cs, p.rhs_rs, p.alpha, p.beta, false, false, false, par,
        ),
        Isa::Avx2 => T::narrow(normalised(p), par),
        Isa::Baseline => T::scalar(normalised(p), par),
    }
}

/// The operands as `gemm::gemm` hands them to its kernels: transposed when the destination's
/// rows are closer than its columns (the microkernels prefer column-major), then every
/// negative stride turned positive from the other end.
fn normalised<T>(p: Operands<T>) -> Operands<T> {
    let mut q = if p.dst_cs.abs() < p.dst_rs.abs() {
        Operands {
            m: p.n,
            n: p.m,
            dst_cs: p.dst_rs,
            dst_rs: p.dst_cs,
            lhs: p.rhs,
            lhs_cs: p.rhs_rs,
            lhs_rs: p.rhs_cs,
            rhs: p.lhs,
            rhs_cs: p.lhs_rs,
            rhs_rs: p.lhs_cs,
            ..p
        }
    } else {
        p
    };
    if q.dst_rs < 0 && q.m > 0 {
        q.dst = q.dst.wrapping_offset((q.m - 1) as isize * q.dst_rs);
        q.dst_rs = -q.dst_rs;
        q.lhs = q.lhs.wrapping_offset((q.m - 1) as isize * q.lhs_rs);
        q.lhs_rs = -q.lhs_rs;
    }
    if q.dst_cs < 0 && q.n > 0 {
        q.dst = q.dst.wrapping_offset((q.n - 1) as isize * q.dst_cs);
        q.dst_cs = -q.dst_cs;
        q.rhs = q.rhs.wrapping_offset((q.n - 1) as isize * q.rhs_cs);
        q.rhs_cs = -q.rhs_cs;
    }
    if q.lhs_cs < 0 && q.k > 0 {
        q.lhs = q.lhs.wrapping_offset((q.k - 1) as isize * q.lhs_cs);
        q.lhs_cs = -q.lhs_cs;
        q.rhs = q.rhs.wrapping_offset((q.k - 1) as isize * q.rhs_rs);
        q.rhs_rs = -q.rhs_rs;
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic operand of `len` values in [-1, 1).
    fn values(len: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..len)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            })
            .collect()
    }

    /// dst (m × n, row-major) = a (m × k, row-major) · bᵀ (b: n × k, row-major), f32, with
    /// the kernels of `isa`.
    fn product_abt(isa: Isa, a: &[f32], b: &[f32], m: usize, n: usize, k: usize) -> Vec<f32> {
        let mut dst = vec![0f32; m * n];
        // SAFETY: dst is m × n row-major, a m × k row-major, b n × k row-major (read as k × n).
        unsafe {
            gemm_with(
                isa,
                Operands {
                    m,
                    n,
                    k,
                    dst: dst.as_mut_ptr(),
                    dst_cs: 1,
                    dst_rs: n as isize,
                    read_dst: false,
                    lhs: a.as_ptr(),
                    lhs_cs: 1,
                    lhs_rs: k as isize,
                    rhs: b.as_ptr(),
                    rhs_cs: k as isize,
                    rhs_rs: 1,
                    alpha: 0.0,
                    beta: 1.0,
                },
                Parallelism::None,
            )
        };
        dst
    }

    #[test]
    fn every_instruction_set_this_cpu_has_computes_the_product_and_they_differ_only_by_rounding() {
        let (m, n, k) = (37, 29, 301);
        let a64 = values(m * k, 1);
        let b64 = values(n * k, 2);
        let a: Vec<f32> = a64.iter().map(|v| *v as f32).collect();
        let b: Vec<f32> = b64.iter().map(|v| *v as f32).collect();
        let exact = |i: usize, j: usize| -> f64 {
            (0..k)
                .map(|t| a[i * k + t] as f64 * b[j * k + t] as f64)
                .sum()
        };
        let runs: Vec<(Isa, Vec<f32>)> = Isa::ALL
            .into_iter()
            .filter(|i| *i <= widest())
            .map(|i| (i, product_abt(i, &a, &b, m, n, k)))
            .collect();
        for (isa, got) in &runs {
            for i in 0..m {
                for j in 0..n {
                    let want = exact(i, j);
                    // f32 accumulation of k products of magnitude ≤ 1: within k·2⁻²³ of exact.
                    assert!(
                        (got[i * n + j] as f64 - want).abs() <= k as f64 * f32::EPSILON as f64,
                        "{}: ({i}, {j}) = {} against {want}",
                        isa.name(),
                        got[i * n + j]
                    );
                }
            }
        }
        // The kernels really differ: the baseline (one lane, no FMA) rounds differently from
        // the vector kernels somewhere in 1,073 dot products of 301 terms.
        if widest() >= Isa::Avx2 {
            let base = &runs[0].1;
            let avx2 = &runs[1].1;
            assert!(base
                .iter()
                .zip(avx2)
                .any(|(x, y)| x.to_bits() != y.to_bits()));
        }
    }

    #[test]
    fn negative_strides_and_a_column_major_destination_give_the_row_major_product() {
        let (m, n, k) = (5, 7, 9);
        let a: Vec<f64> = values(m * k, 3);
        let b: Vec<f64> = values(k * n, 4);
        for isa in Isa::ALL.into_iter().filter(|i| *i <= widest()) {
            // dst column-major (dst_rs 1, dst_cs m), lhs read bottom-up through a negative row
            // stride (row i of the product is row m-1-i of a).
            let mut dst = vec![0f64; m * n];
            // SAFETY: every (i, j, t) reaches inside a, b and dst for these strides.
            unsafe {
                gemm_with(
                    isa,
                    Operands {
                        m,
                        n,
                        k,
                        dst: dst.as_mut_ptr(),
                        dst_cs: m as isize,
                        dst_rs: 1,
                        read_dst: false,
                        lhs: a.as_ptr().add((m - 1) * k),
                        lhs_cs: 1,
                        lhs_rs: -(k as isize),
                        rhs: b.as_ptr(),
                        rhs_cs: 1,
                        rhs_rs: n as isize,
                        alpha: 0.0,
                        beta: 1.0,
                    },
                    Parallelism::None,
                )
            };
            for i in 0..m {
                for j in 0..n {
                    let want: f64 = (0..k).map(|t| a[(m - 1 - i) * k + t] * b[t * n + j]).sum();
                    let got = dst[j * m + i];
                    assert!((got - want).abs() < 1e-12, "{}: ({i}, {j})", isa.name());
                }
            }
        }
    }

    #[test]
    fn nrw_isa_narrows_the_choice_and_refuses_names_it_does_not_know_or_instructions_the_cpu_lacks()
    {
        assert_eq!(choose(None, Isa::Avx512), Ok(Isa::Avx512));
        assert_eq!(choose(Some(""), Isa::Avx2), Ok(Isa::Avx2));
        assert_eq!(choose(Some("avx2+fma"), Isa::Avx512), Ok(Isa::Avx2));
        assert_eq!(choose(Some("baseline"), Isa::Avx2), Ok(Isa::Baseline));
        let unknown = choose(Some("avx2"), Isa::Avx512).unwrap_err();
        assert_eq!(
            unknown.to_string(),
            "NRW_ISA=\"avx2\" names no instruction set (known: avx512f, avx2+fma, baseline)"
        );
        let wider = choose(Some("avx512f"), Isa::Avx2).unwrap_err();
        assert_eq!(
            wider.to_string(),
            "NRW_ISA=avx512f asks for instructions this CPU lacks: the widest it has is avx2+fma"
        );
    }
}
