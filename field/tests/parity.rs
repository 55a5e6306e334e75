//! Parity with the official NeLF implementation: every tensor of each
//! `io_*.safetensors` fixture that the model produces (encoder, light aggregation,
//! per-point coarse and fine networks, coarse/fine render), recomputed from the
//! fixture's inputs and its paired `fixture_*.safetensors` weights, within the
//! tolerances the fixtures' README suggests.
//!
//! Fixtures are read from the repository's `data/nelf-oracle` or from
//! `NELF_ORACLE_FIXTURES`: a folder, or `io_*.safetensors` files separated by `:`.
//! Every `io_<case>.safetensors` is paired with `fixture_<case>.safetensors` in the
//! same folder (either may be zstd-compressed, `*.safetensors.zst`); missing
//! fixtures fail the tests; V, image size, rays and samples are read from the tensors.
//! `parity_generic.rs` runs the same checks through candle's generic ops (the code
//! path of non-CPU devices) instead of the fused CPU kernels.

mod common;

use common::{Fixture, check_encoder, check_points, check_rays, check_render, fixture_pairs};

#[test]
fn encoder_and_light_aggregation_match_the_official_model() {
    for (io, weights) in fixture_pairs() {
        check_encoder(&Fixture::load(&io, &weights));
    }
}

#[test]
fn per_point_networks_match_the_official_model() {
    for (io, weights) in fixture_pairs() {
        check_points(&Fixture::load(&io, &weights));
    }
}

#[test]
fn coarse_and_fine_renders_match_the_official_model() {
    for (io, weights) in fixture_pairs() {
        check_render(&Fixture::load(&io, &weights));
    }
}

#[test]
fn target_rays_match_pix_to_ray() {
    for (io, weights) in fixture_pairs() {
        check_rays(&Fixture::load(&io, &weights));
    }
}
