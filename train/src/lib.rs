//! `nelf-train`: trains the NeLF network (Sun et al., EGSR 2021) on our own
//! path-traced ground truth.
//!
//! * [`data`]: training triplets (five source views under one lighting, a novel view
//!   under the same lighting rotated, a novel view under another lighting) written
//!   once by the path tracer, cached and resumable, with held-out identities and
//!   lightings ([`data::generate`] writes a dataset folder, [`data::Dataset`] reads
//!   it back head by head).
//! * [`config`]: [`TrainConfig`], the one configuration of a run (widths, budget per
//!   step, optimiser, loss weights), saved with its checkpoints;
//! * [`forward`]: the network's forward pass with gradients (encoder, light
//!   estimate, differentiable feature gather, volume rendering);
//! * [`adam`]: Adam with a state that saves and restores exactly;
//! * [`domain`]: the domain-adaptation hook (an auto-encoding loss on real portraits);
//! * [`trainer`]: the paper's losses and modes, steps, checkpoints (split by job:
//!   head preparation, ray sampling, the loss, the trainable network, checkpoints,
//!   the optimiser step);
//! * [`run`]: the resumable loop with validation on held-out heads;
//! * [`eval`]: a network on held-out heads with 2–5 source views (the view-count table);
//! * [`finetune`]: test-time fine-tuning on one capture's own source views;
//! * [`cli`]: the `nelf train` subcommands (also the `nelf_train` example binary);
//! * [`error`]: the crate's error type, [`TrainError`];
//! * `files`: every file the crate writes whole goes through
//!   [`nelf_format::atomic`], errors naming the file.

pub mod adam;
pub mod cli;
pub mod config;
pub mod data;
pub mod domain;
pub mod error;
pub mod eval;
mod files;
pub mod finetune;
pub mod forward;
pub mod run;
pub mod trainer;

pub use config::TrainConfig;

pub use error::TrainError;
