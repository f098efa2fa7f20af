//! One `nrw-etl` process timed whole by `/usr/bin/time`: wall seconds and peak resident MB,
//! for the benchmarks that compare stages or runs. Shared by `#[path]`.
#![allow(dead_code)]

/// Wall seconds and peak resident MB of `nrw-etl ARGS` (`exe` is the binary).
pub fn timed(exe: &str, args: &[&str]) -> (f64, f64) {
    timed_with(exe, args, &[])
}

/// [`timed`] with environment variables set for that process alone.
pub fn timed_with(exe: &str, args: &[&str], vars: &[(&str, &str)]) -> (f64, f64) {
    let o = std::process::Command::new("/usr/bin/time")
        .args(["-f", "%e %M", exe])
        .args(args)
        .envs(vars.iter().copied())
        .output()
        .expect("/usr/bin/time runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{args:?}: {err}");
    let last = err.lines().last().expect("time's line");
    let mut it = last.split_whitespace();
    let secs: f64 = it.next().unwrap().parse().unwrap();
    let kb: f64 = it.next().unwrap().parse().unwrap();
    (secs, kb / 1024.0)
}

/// `[PHOTOS POINTS]` from a benchmark's command line: 200 photos and 10⁷ points unless given.
pub fn photos_points() -> (usize, usize) {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    (
        args.first().copied().unwrap_or(200),
        args.get(1).copied().unwrap_or(10_000_000),
    )
}
