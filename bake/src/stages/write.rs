//! Stage 8, **write**: the asset written atomically and, beside it, the
//! `.bake.json` sidecar with the configuration and the report (timings included;
//! they stay out of the asset, so baking twice gives byte-identical files).

use std::path::{Path, PathBuf};
use std::time::Instant;

use nelf_format::{WriteOptions, WriteReport, write_asset};

use crate::config::BakeConfig;
use crate::error::{BakeError, Result, io_error};
use crate::stages::outputs::BakeOutput;

/// Where the bake's settings and report are saved beside an asset: the asset's path
/// with its extension replaced by `bake.json` (`head.nelf` → `head.bake.json`).
pub fn sidecar_path(asset_path: &Path) -> PathBuf {
    asset_path.with_extension("bake.json")
}

/// Writes the asset atomically (default [`WriteOptions`]) and, beside it,
/// `<asset>.bake.json` with the configuration and the report (timings included).
/// Fills in `write_secs` and `file_size`.
pub fn write_bake(output: &mut BakeOutput, config: &BakeConfig, path: &Path) -> Result<WriteReport> {
    let t = Instant::now();
    let written = write_asset(path, &output.asset, &WriteOptions::default())?;
    output.report.timings.write_secs = t.elapsed().as_secs_f64();
    output.report.file_size = written.file_size;
    let sidecar = sidecar_path(path);
    let json = serde_json::json!({
        "asset": path.display().to_string(),
        "config": config,
        "source": output.asset.metadata.get("source"),
        "choice": output.asset.metadata.get("choice"),
        "report": output.report,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| BakeError::Json {
        path: sidecar.clone(),
        message: e.to_string(),
    })?;
    nelf_format::atomic::write_bytes_atomically(&sidecar, (text + "\n").as_bytes())
        .map_err(|e| io_error(&sidecar, e))?;
    Ok(written)
}
