//! The VGG weights a tier runs (refusing a missing file or another convention), and the Gram
//! matrices of one image.

use std::path::Path;

use nrw_style::{Convention, Preprocess, Tier, Vgg};

use crate::error::{PipelineError, Result, Setting};

/// Load the weights a tier needs, refusing a missing file or another architecture.
pub fn load_weights(path: Option<&Path>, tier: &Tier) -> Result<Option<Vgg>> {
    match (tier.needs_weights(), path) {
        (false, _) => Ok(None),
        (true, None) => Err(PipelineError::config(Setting::Weights, format!(
            "FILE is required for tier {} (the tool never downloads weights; any safetensors with torchvision VGG16 names works); {} color-stats is the explicit non-neural fallback",
            tier.name(),
            Setting::Key("style.tier")
        ))),
        (true, Some(p)) => {
            let net = Vgg::load(p)?;
            if let Some(want) = tier.convention().filter(|c| *c != net.convention) {
                return Err(PipelineError::Weights {
                    path: p.into(),
                    problem: convention_mismatch(tier, want),
                });
            }
            if let Some(arch) = tier.arch().filter(|a| *a != net.arch) {
                return Err(PipelineError::Weights {
                    path: p.into(),
                    problem: format!(
                        "these are {} weights but tier {} needs {}",
                        net.arch.name(),
                        tier.name(),
                        arch.name()
                    ),
                });
            }
            Ok(Some(net))
        }
    }
}

/// Why a weights file of the other convention is refused for `tier`.
fn convention_mismatch(tier: &Tier, want: Convention) -> String {
    match want {
        Convention::Caffe => format!(
            "tier {} reproduces the published code's distance, which runs tensorflow-vgg's Caffe-trained vgg16.npy (the file its README downloads); these are torchvision weights, which expect other input",
            tier.name()
        ),
        Convention::Torchvision => format!(
            "this is tensorflow-vgg's vgg16.npy (Caffe convention), which only the official tiers run; tier {} takes torchvision VGG weights as safetensors",
            tier.name()
        ),
    }
}

/// The five Gram matrices of one image as given, written atomically to `out` as safetensors
/// (whichever VGG the weights are).
pub fn image_grams(
    weights: Option<&Path>,
    image: &Path,
    pre: Preprocess,
    out: &Path,
) -> Result<()> {
    let net = load_weights(weights, &Tier::reference())
        .or_else(|_| load_weights(weights, &Tier::parse("vgg19-512").expect("valid tier")))?
        .expect("VGG tier");
    let bytes = nrw_style::image_grams_safetensors(&net, image, pre)?;
    nrw_dataset::atomic::write_bytes_atomic(out, &bytes)?;
    Ok(())
}
