//! Synthetic scenes: load a spec (or the embedded demo) and generate it.

use std::path::Path;

use nrw_synth::{SceneSpec, SynthReport};

use crate::error::{PipelineError, Result};
use crate::Progress;

/// Load a spec file, or the embedded demo; `seed` overrides the spec's.
pub fn load_spec(path: Option<&Path>, seed: Option<u64>) -> Result<SceneSpec> {
    let mut spec = match path {
        None => SceneSpec::demo(),
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| PipelineError::input(p, format!("cannot read scene spec: {e}")))?;
            SceneSpec::from_toml(&text, &p.display().to_string())?
        }
    };
    if let Some(s) = seed {
        spec.seed = s;
    }
    Ok(spec)
}

/// Generate a scene into `out`, reporting progress over photos.
pub fn generate(spec: &SceneSpec, out: &Path, progress: &dyn Progress) -> Result<SynthReport> {
    progress.start("rendering", spec.cameras.count as u64, "photos");
    let report = nrw_synth::generate(spec, out, &|| progress.inc(1))?;
    progress.finish();
    Ok(report)
}
