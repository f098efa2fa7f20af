//! The machine a benchmark ran on, for its report: CPU model, cores and the SIMD flags the
//! figures depend on (some machines here have AVX-512, some only AVX2). Shared by `#[path]`.
#![allow(dead_code)]

/// "MODEL; N cores; flags: avx2, fma, avx512f, …" from /proc/cpuinfo.
pub fn describe() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .unwrap_or("?")
        .trim()
        .to_string();
    let flags = info.lines().find(|l| l.starts_with("flags")).unwrap_or("");
    let has: Vec<&str> = [
        "avx2",
        "fma",
        "avx512f",
        "avx512bw",
        "avx512_vnni",
        "pclmulqdq",
        "sha_ni",
    ]
    .into_iter()
    .filter(|f| flags.split_whitespace().any(|x| x == *f))
    .collect();
    format!(
        "{model}; {} cores; flags: {}",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        has.join(", ")
    )
}
