//! The seam every group stage plugs into. A stage whose work is cut into groups of image
//! ids (ingest: one shard per group; style: one descriptor part per group) implements
//! [`GroupStage`]; [`drive`] runs the groups a work unit owns, skipping those already done, and
//! [`merge_stage`] runs the stage's merge once its units have run (`finalize`). A new group
//! stage writes its group, its "already done" test and its merge; the unit arithmetic,
//! resumption, progress and the unit record are shared.

use nrw_dataset::units::{self, UnitRecord};
use nrw_dataset::Store;

use crate::error::Result;
use crate::{Progress, Unit};

/// A stage whose work is cut into groups that work units share.
pub trait GroupStage {
    /// The stage's name in the dataset's unit records (`units::INGEST`, `units::STYLE`).
    const STAGE: &'static str;
    /// What the progress bar counts (views, photos).
    const ITEMS: &'static str;
    /// What the stage's merge reports.
    type Merge;

    /// Whether group `g` (image ids `ids`) is already done with this run's inputs and
    /// settings, so a rerun skips it.
    fn done(&self, g: usize, ids: &[u32]) -> Result<bool>;

    /// Do group `g`; returns how many items it produced (views kept, photos described).
    fn run(&self, g: usize, ids: &[u32], progress: &dyn Progress) -> Result<usize>;

    /// Merge every unit's output into the dataset's tables and manifest (what `finalize`
    /// runs): the bytes one process writes, or an error naming the unit to run again.
    fn merge(dataset: &Store) -> Result<Self::Merge>;
}

/// What one unit's drive did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Driven {
    /// Groups the unit owns.
    pub owned: usize,
    /// Of those, groups already done (skipped).
    pub resumed: usize,
    /// Groups run now.
    pub ran: usize,
    /// Items the groups run now produced.
    pub items: usize,
}

/// Run the groups of `per_group` consecutive ids that `unit` owns and that are not done yet,
/// in order, under one progress bar labelled `label`. `after_group(ran, todo)` is called after
/// each group (ran of todo): a caller's pause or stop.
pub fn drive<S: GroupStage>(
    stage: &S,
    unit: Unit,
    ids: &[u32],
    per_group: usize,
    label: &str,
    progress: &dyn Progress,
    after_group: &dyn Fn(usize, usize) -> Result<()>,
) -> Result<Driven> {
    let owned: Vec<(usize, &[u32])> = ids
        .chunks(per_group)
        .enumerate()
        .filter(|(g, _)| unit.owns(*g))
        .collect();
    let mut todo = Vec::new();
    for (g, group) in &owned {
        if !stage.done(*g, group)? {
            todo.push((*g, *group));
        }
    }
    progress.start(
        label,
        todo.iter().map(|(_, g)| g.len() as u64).sum(),
        S::ITEMS,
    );
    let mut items = 0;
    for (ran, (g, group)) in todo.iter().enumerate() {
        items += stage.run(*g, group, progress)?;
        if let Err(e) = after_group(ran + 1, todo.len()) {
            progress.finish();
            return Err(e);
        }
    }
    progress.finish();
    Ok(Driven {
        owned: owned.len(),
        resumed: owned.len() - todo.len(),
        ran: todo.len(),
        items,
    })
}

/// Record that `unit` of stage `S` is done (what `finalize` checks and merges by).
pub fn record_unit<S: GroupStage>(store: &Store, unit: Unit, record: &UnitRecord) -> Result<()> {
    let rel = units::unit_record_path(S::STAGE, unit.index, unit.count);
    Ok(units::write_record(store, &rel, record)?)
}

/// The whole stage in this process: earlier unfinished unit runs' records are cleared (this
/// run owns the dataset; their group outputs are reused when they match), `run_whole` runs
/// unit 0 of 1, and the stage's merge makes the dataset whole.
pub fn whole<S: GroupStage, T>(
    dataset: &Store,
    run_whole: impl FnOnce() -> Result<T>,
) -> Result<(T, S::Merge)> {
    units::remove_unit_records(dataset, S::STAGE, None)?;
    let done = run_whole()?;
    Ok((done, S::merge(dataset)?))
}

/// Whether units of stage `S` started in `dataset` (its unit folder holds files) although
/// none has finished (no unit record): merging would be premature.
pub fn started_unfinished<S: GroupStage>(dataset: &Store) -> Result<bool> {
    Ok(!dataset.list(&units::stage_dir(S::STAGE))?.is_empty()
        && units::unit_records(dataset, S::STAGE)?.is_empty())
}

/// Merge stage `S` when any of its units has run here; None when none has.
pub fn merge_stage<S: GroupStage>(dataset: &Store) -> Result<Option<S::Merge>> {
    if units::unit_records(dataset, S::STAGE)?.is_empty() {
        return Ok(None);
    }
    S::merge(dataset).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// Groups whose first id is even count as done; running a group records it.
    struct Fake {
        ran: Mutex<Vec<usize>>,
    }

    impl GroupStage for Fake {
        const STAGE: &'static str = "fake";
        const ITEMS: &'static str = "items";
        type Merge = ();

        fn done(&self, _g: usize, ids: &[u32]) -> Result<bool> {
            Ok(ids[0].is_multiple_of(2))
        }

        fn run(&self, g: usize, ids: &[u32], _p: &dyn Progress) -> Result<usize> {
            self.ran.lock().unwrap().push(g);
            Ok(ids.len())
        }

        fn merge(_dataset: &Store) -> Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_unit_runs_the_groups_it_owns_that_are_not_done_in_order() {
        // Groups of 2: [1,2] [3,4] [6,7] [9,10] [11]; group 2 ([6,7]) is done.
        let ids = [1, 2, 3, 4, 6, 7, 9, 10, 11];
        let fake = Fake {
            ran: Mutex::new(Vec::new()),
        };
        let unit = Unit { index: 0, count: 2 }; // owns groups 0, 2, 4
        let d = drive(&fake, unit, &ids, 2, "t", &crate::Silent, &|_, _| Ok(())).unwrap();
        assert_eq!(*fake.ran.lock().unwrap(), vec![0, 4]);
        assert_eq!(
            d,
            Driven {
                owned: 3,
                resumed: 1,
                ran: 2,
                items: 3
            }
        );
        // A stop after the first group ends the drive with its error.
        let fake = Fake {
            ran: Mutex::new(Vec::new()),
        };
        let stop = |ran: usize, _todo: usize| {
            if ran == 1 {
                Err(crate::PipelineError::Interrupted("stop".into()))
            } else {
                Ok(())
            }
        };
        assert!(drive(&fake, Unit::WHOLE, &ids, 2, "t", &crate::Silent, &stop).is_err());
        assert_eq!(*fake.ran.lock().unwrap(), vec![0]);
    }
}
