//! Writing the crate's files: every file `nelf-train` writes whole (checkpoints,
//! exported weights, dataset files, run settings) goes through the project's one
//! atomic writer, [`nelf_format::atomic`] (a temporary file in the destination's
//! folder, synced, renamed over the destination; readers see the old file or the
//! whole new one), and every error names the destination.

use std::collections::HashMap;
use std::path::Path;

use candle_core::Tensor;

use crate::error::TrainError;

/// Writes `bytes` to `path` atomically ([`nelf_format::atomic::write_bytes_atomically`]).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    nelf_format::atomic::write_bytes_atomically(path, bytes).map_err(|e| TrainError::io(path, e))
}

/// Writes `tensors` to `path` as a safetensors file, atomically: encoded to bytes by
/// the `safetensors` crate (the encoder `candle_core::safetensors::save` calls, so the
/// bytes are candle's), then written through [`write_bytes`].
pub fn write_tensors(tensors: &HashMap<String, Tensor>, path: &Path) -> Result<(), TrainError> {
    let bytes = safetensors::tensor::serialize(tensors, None)
        .map_err(|e| TrainError::file(path, format!("encoding the tensors: {e}")))?;
    write_bytes(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn tensors_are_written_as_candle_encodes_them_and_no_temporary_file_is_left() {
        let dir = tempfile::tempdir().unwrap();
        let tensors: HashMap<String, Tensor> = [
            (
                "b".to_string(),
                Tensor::new(&[1.5f32, -2.0], &Device::Cpu).unwrap(),
            ),
            ("a".to_string(), Tensor::new(&[7.0f64], &Device::Cpu).unwrap()),
        ]
        .into_iter()
        .collect();
        let direct = dir.path().join("direct.safetensors");
        candle_core::safetensors::save(&tensors, &direct).unwrap();
        let path = dir.path().join("weights.safetensors");
        write_tensors(&tensors, &path).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&direct).unwrap());
        // Replacing an existing file works too.
        write_tensors(&tensors, &path).unwrap();
        let mut names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["direct.safetensors", "weights.safetensors"]);
        // A missing folder is an error naming the file.
        let missing = dir.path().join("no/such/weights.safetensors");
        let err = write_tensors(&tensors, &missing).unwrap_err().to_string();
        assert!(err.contains("weights.safetensors"), "{err}");
        let err = write_bytes(&missing, b"x").unwrap_err().to_string();
        assert!(err.contains("no/such/weights.safetensors"), "{err}");
    }
}
