//! What `run` checks before its first stage, from the pipeline and the scene's model alone,
//! every problem at once: an hour of densify never ends in a refusal that a second's reading
//! of the model would have given.
//!
//! A validation count the model's registered photos cannot hold is refused here; what only
//! the kept photos show is left to the stages (split refuses, triplets lowers k): see
//! pipelines/README.md, "Asking for more photos than there are".

use std::path::Path;

use super::pipeline::Pipeline;
use crate::error::{PipelineError, Result, Setting};

/// Refuse the run, listing every problem, when a setting cannot work on this scene.
pub(super) fn preflight(p: &Pipeline, scene: &Path) -> Result<()> {
    let mut problems = Vec::new();
    if let Some(d) = &p.densify {
        if let Err(e) = crate::densify::check(&d.config(scene)) {
            problems.push(e.to_string());
        }
    }
    if let Some(s) = &p.split {
        if let Err(e) = s.check() {
            problems.push(e.to_string());
        }
        if let Some(registered) = registered_photos(scene) {
            problems.extend(val_problem(s.val_count(), registered));
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(PipelineError::Preflight { problems })
    }
}

/// The photos the scene's model registers; `None` when it cannot be read (the first stage
/// that reads it says why).
fn registered_photos(scene: &Path) -> Option<usize> {
    let model = nrw_colmap::Scene::find(scene).ok()?.read(None).ok()?;
    Some(model.images.len())
}

/// A validation count of at least the registered photos leaves none to train on.
fn val_problem(val: Option<usize>, registered: usize) -> Option<String> {
    let val = val.filter(|&v| v > 0 && v >= registered)?;
    let fits = (registered / 5).max(1);
    Some(format!(
        "{} is {val}, but the scene's model registers {registered} photos (ingest keeps at most those, and training needs at least one): set it lower, e.g. split.val={fits} (a fifth), or split.val_fraction",
        Setting::Key("split.val")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_validation_count_the_model_cannot_hold_is_named_with_the_count() {
        let e = val_problem(Some(100), 40).expect("refused");
        assert!(
            e.contains("`split.val` is 100") && e.contains("registers 40 photos"),
            "{e}"
        );
        assert!(e.contains("split.val=8"), "{e}");
        assert!(val_problem(Some(40), 40).is_some());
        assert_eq!(val_problem(Some(39), 40), None);
        assert_eq!(val_problem(Some(0), 0), None);
        assert_eq!(val_problem(None, 3), None);
    }
}
