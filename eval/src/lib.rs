//! `nelf-eval`: what `nelf eval` measures and how it reports it.
//!
//! * [`input`]: what is evaluated (a capture, a mesh, a procedural head) and the
//!   synthetic captures made from it.
//! * [`measure`]: scoring an asset (PSNR, SSIM, ꟻLIP, baseline) and timing it.
//! * [`pareto`]: `nelf eval pareto`, resolution × rank × encoding against accuracy.
//! * [`stability`]: `nelf eval stability`, accuracy along axes where methods fail.
//! * [`network`]: `nelf eval network`, the NeLF network and its bake against the
//!   ground truth on held-out captures (through `nelf-pipeline`).
//! * [`error`]: the errors.
//! * [`front`]: Pareto fronts of cost against quality.
//! * [`merge`]: sweeps run in parts (`nelf batch`) merged into one report.
//! * [`perturb`]: the stability axes' building blocks (pose noise, mask edits, a sun
//!   of shrinking size, target views at an angle from the sources).
//! * [`report`]: CSV, JSON, SVG charts and the self-contained HTML report.
//! * [`rows`]: the measured rows (one per sweep setting or stability point).

pub mod error;
pub mod front;
pub mod input;
pub mod measure;
pub mod merge;
pub mod network;
pub mod pareto;
pub mod perturb;
pub mod report;
pub mod rows;
pub mod stability;

pub use error::{EvalError, Result};
pub use network::{NetworkEvalConfig, TargetScores, run_network};
pub use pareto::{ParetoConfig, ParetoResults, run_pareto};
pub use stability::{StabilityConfig, StabilityResults, StabilitySource, run_stability};
