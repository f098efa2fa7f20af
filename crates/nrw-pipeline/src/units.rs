//! Work units: unit `I` of `N` does the groups `g` with `g mod N = I` of a stage whose work is
//! cut into groups (ingest: one group per shard; style: one per descriptor part).
//!
//! The groups themselves never depend on `N` — they are the same consecutive runs of image
//! ids a single process makes — so any number of units writes exactly the files one process
//! writes, and `finalize` only has to list them. Every machine derives the same groups from
//! the same model, so units agree without talking.

use std::collections::BTreeMap;
use std::fmt;

use nrw_dataset::units::{self, UnitRecord};
use nrw_dataset::Store;

use crate::error::{PipelineError, Result, Setting};

/// One unit of a stage's work, or the whole stage (`0/1`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unit {
    pub index: usize,
    pub count: usize,
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Written as `I/N` in summaries and JSON, as on the command line.
impl serde::Serialize for Unit {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl Unit {
    /// The whole stage in one process.
    pub const WHOLE: Unit = Unit { index: 0, count: 1 };

    /// Whether this unit does group `g`.
    pub fn owns(&self, g: usize) -> bool {
        g % self.count == self.index
    }

    /// Whether this is the whole stage.
    pub fn is_whole(&self) -> bool {
        self.count == 1
    }

    /// Parse `I/N` (0 ≤ I < N), or `auto`: the index and count from the scheduler's
    /// environment (`env` looks a variable up; the CLI passes `std::env::var`).
    ///
    /// `auto` reads Slurm array jobs (`SLURM_ARRAY_TASK_ID` minus `SLURM_ARRAY_TASK_MIN`, of
    /// `SLURM_ARRAY_TASK_COUNT`) or Kubernetes Indexed Jobs (`JOB_COMPLETION_INDEX`, of
    /// `count`, which Kubernetes does not export: pass the Job's `completions`).
    pub fn parse(
        text: &str,
        count: Option<usize>,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<Unit> {
        let bad = |problem: String| PipelineError::config(Setting::Unit, problem);
        let num = |name: &str, v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| bad(format!("{name}={v:?} is not a non-negative integer")))
        };
        let unit = if text == "auto" {
            if let Some(id) = env("SLURM_ARRAY_TASK_ID") {
                let id = num("SLURM_ARRAY_TASK_ID", &id)?;
                let min = env("SLURM_ARRAY_TASK_MIN")
                    .map(|m| num("SLURM_ARRAY_TASK_MIN", &m))
                    .transpose()?
                    .unwrap_or(0);
                let n = match (count, env("SLURM_ARRAY_TASK_COUNT")) {
                    (Some(n), _) => n,
                    (None, Some(c)) => num("SLURM_ARRAY_TASK_COUNT", &c)?,
                    (None, None) => {
                        return Err(PipelineError::config(
                            Setting::UnitCount,
                            "is needed: the unit is auto and SLURM_ARRAY_TASK_COUNT is not set",
                        ))
                    }
                };
                Unit {
                    index: id.checked_sub(min).ok_or_else(|| {
                        bad(format!(
                            "auto: SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
                        ))
                    })?,
                    count: n,
                }
            } else if let Some(idx) = env("JOB_COMPLETION_INDEX") {
                let n = count.ok_or_else(|| {
                    PipelineError::config(
                        Setting::UnitCount,
                        "is needed: the unit is auto and JOB_COMPLETION_INDEX is set, but Kubernetes does not export the Job's completions",
                    )
                })?;
                Unit {
                    index: num("JOB_COMPLETION_INDEX", &idx)?,
                    count: n,
                }
            } else {
                return Err(bad(
                    "auto: neither SLURM_ARRAY_TASK_ID (Slurm array job) nor JOB_COMPLETION_INDEX (Kubernetes Indexed Job) is set; give I/N".into(),
                ));
            }
        } else {
            let (i, n) = text
                .split_once('/')
                .ok_or_else(|| bad(format!("{text:?} is not I/N (e.g. 0/4) or auto")))?;
            Unit {
                index: num("I", i)?,
                count: num("N", n)?,
            }
        };
        if unit.count == 0 || unit.index >= unit.count {
            return Err(bad(format!(
                "{unit}: the index must be below the count (units are numbered 0 to N-1)"
            )));
        }
        Ok(unit)
    }
}

/// SHA-256 (hex) of the inputs and parameters ([`nrw_dataset::resume::fingerprint`]).
pub use nrw_dataset::resume::fingerprint;

pub(crate) fn units_error(dataset: &Store, problem: String) -> PipelineError {
    PipelineError::Units {
        dataset: dataset.root(),
        problem,
    }
}

pub(crate) fn names(units: &[&UnitRecord]) -> String {
    let n: Vec<String> = units
        .iter()
        .map(|u| format!("{}/{}", u.index, u.count))
        .collect();
    format!(
        "unit{} {}",
        if n.len() > 1 { "s" } else { "" },
        n.join(", ")
    )
}

/// The first way `b` differs from `a`: a parameter (named with both values) or an input file.
pub(crate) fn difference(a: &UnitRecord, b: &UnitRecord) -> String {
    let keys: std::collections::BTreeSet<&String> =
        a.parameters.keys().chain(b.parameters.keys()).collect();
    for k in keys {
        let (va, vb) = (a.parameters.get(k), b.parameters.get(k));
        if va != vb {
            let show =
                |v: Option<&serde_json::Value>| v.map_or("(unset)".to_string(), |v| v.to_string());
            return format!("{k} = {} vs {k} = {}", show(vb), show(va));
        }
    }
    for ia in &a.inputs {
        match b.inputs.iter().find(|ib| ib.path == ia.path) {
            Some(ib) if ib.sha256 == ia.sha256 => {}
            Some(_) => return format!("input {} had other contents", ia.path),
            None => return format!("input {} was not read", ia.path),
        }
    }
    "other inputs".into()
}

/// Check a stage's unit records agree and are complete; returns one of them.
pub(crate) fn check_units(dataset: &Store, stage: &str) -> Result<UnitRecord> {
    let records = units::unit_records(dataset, stage)?;
    let first = records
        .first()
        .cloned()
        .ok_or_else(|| units_error(dataset, format!("no {stage} unit has run here")))?;
    let counts: std::collections::BTreeSet<usize> = records.iter().map(|r| r.count).collect();
    if counts.len() > 1 {
        let by = |n: usize| names(&records.iter().filter(|r| r.count == n).collect::<Vec<_>>());
        let shown: Vec<String> = counts.iter().map(|n| by(*n)).collect();
        return Err(units_error(dataset, format!(
            "{stage} units were run with different unit counts ({}); run every unit with the same unit count N of I/N",
            shown.join("; ")
        )));
    }
    // The largest group of agreeing units is taken as the intended run.
    let mut by_fp: BTreeMap<&str, Vec<&UnitRecord>> = BTreeMap::new();
    for r in &records {
        by_fp.entry(r.fingerprint.as_str()).or_default().push(r);
    }
    if by_fp.len() > 1 {
        let mut groups: Vec<Vec<&UnitRecord>> = by_fp.into_values().collect();
        groups.sort_by_key(|g| std::cmp::Reverse(g.len()));
        let (main, odd) = (&groups[0], &groups[1]);
        return Err(units_error(
            dataset,
            format!(
            "{stage} {} ran with other parameters than {}: {}; run {} again with the same settings",
            names(odd),
            names(main),
            difference(main[0], odd[0]),
            if odd.len() > 1 { "them" } else { "it" },
        ),
        ));
    }
    let missing: Vec<String> = (0..first.count)
        .filter(|i| !records.iter().any(|r| r.index == *i))
        .map(|i| format!("{i}/{}", first.count))
        .collect();
    if !missing.is_empty() {
        return Err(units_error(dataset, format!(
            "{stage} unit{} {} {} not run (or not finished): run {} as that unit, then finalize again",
            if missing.len() > 1 { "s" } else { "" },
            missing.join(", "),
            if missing.len() > 1 { "have" } else { "has" },
            if missing.len() > 1 { "them" } else { "it" },
        )));
    }
    Ok(first)
}

/// Record the units' summed time as the stage's, and remove their records (merged).
pub(crate) fn close_stage(dataset: &Store, stage: &str) -> Result<()> {
    let seconds: f64 = units::unit_records(dataset, stage)?
        .iter()
        .map(|r| r.seconds)
        .sum();
    crate::timing::record_timing(dataset, stage, seconds);
    Ok(units::clear_stage(dataset, stage)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(vars: &'static [(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn explicit_units_parse_and_own_their_groups() {
        let u = Unit::parse("2/3", None, &env(&[])).unwrap();
        assert_eq!(u, Unit { index: 2, count: 3 });
        assert_eq!(
            (0..9).filter(|g| u.owns(*g)).collect::<Vec<_>>(),
            vec![2, 5, 8]
        );
        for bad in ["3/3", "0/0", "x/2", "2", "-1/2"] {
            let e = Unit::parse(bad, None, &env(&[])).unwrap_err().to_string();
            assert!(e.starts_with("`unit` "), "{bad}: {e}");
        }
    }

    #[test]
    fn auto_reads_slurm_arrays_and_kubernetes_indexed_jobs() {
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "8"),
        ]);
        assert_eq!(
            Unit::parse("auto", None, &slurm).unwrap(),
            Unit { index: 4, count: 8 }
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "3")]);
        assert_eq!(
            Unit::parse("auto", Some(4), &k8s).unwrap(),
            Unit { index: 3, count: 4 }
        );
        let e = Unit::parse("auto", None, &k8s).unwrap_err().to_string();
        assert!(e.starts_with("`unit_count` is needed"), "{e}");
        let e = Unit::parse("auto", None, &env(&[]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("SLURM_ARRAY_TASK_ID") && e.contains("JOB_COMPLETION_INDEX"),
            "{e}"
        );
        let e = Unit::parse("auto", Some(4), &env(&[("JOB_COMPLETION_INDEX", "4")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("4/4"), "{e}");
    }
}
