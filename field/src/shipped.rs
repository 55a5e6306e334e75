//! The network shipped with the tool: `models/nelf-small.safetensors`, trained by
//! `nelf train` on our own path-traced heads (its card: `models/README.md`), built
//! into the library so that a capture with no ground truth bakes on any machine
//! without a file beside the binary. `--weights FILE` swaps in other weights.

use std::path::Path;

use candle_core::Device;

use crate::{Model, NelfConfig, NetError};

/// How the shipped weights are named in reports and errors.
pub const SHIPPED_WEIGHTS_NAME: &str = "models/nelf-small.safetensors (built in)";

/// The shipped weights: safetensors, official key names, with the image size they
/// were trained at ([`crate::model::WORKING_IMAGE_SIZE_KEY`]).
pub static SHIPPED_WEIGHTS: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../models/nelf-small.safetensors"
));

/// The shipped network on `device`.
pub fn load_shipped(config: NelfConfig, device: &Device) -> Result<Model, NetError> {
    Model::from_safetensors_bytes(SHIPPED_WEIGHTS, Path::new(SHIPPED_WEIGHTS_NAME), config, device)
}

/// The network in `weights`, or the shipped one when none is given; with the name
/// to report it by.
pub fn load_or_shipped(
    weights: Option<&Path>,
    config: NelfConfig,
    device: &Device,
) -> Result<(Model, String), NetError> {
    match weights {
        Some(path) => Ok((Model::load(path, config, device)?, path.display().to_string())),
        None => Ok((load_shipped(config, device)?, SHIPPED_WEIGHTS_NAME.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_weights_load_with_their_working_size() {
        let model = load_shipped(NelfConfig::default(), &Device::Cpu).unwrap();
        let size = model.working_image_size().unwrap();
        assert!((16..=512).contains(&size), "{size}");
        // Smaller than the official network (the card's `small` configuration).
        assert!(model.config().architecture != crate::Architecture::OFFICIAL);
        // Its last steps trained through the shading prior of the training weight, with
        // normals over 8 mm (the card; bakes take a weight and step of their own since).
        assert_eq!(
            model.trained_shading_prior(),
            Some(crate::prior::ShadingPrior {
                step_mm: 8.0,
                weight: crate::prior::TRAINING_WEIGHT,
            })
        );
    }
}
