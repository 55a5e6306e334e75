//! The parity checks of `parity.rs` through candle's generic tensor ops (the code
//! path every non-CPU device takes, e.g. CUDA) instead of the fused CPU kernels:
//! the fused kernels are switched off for this whole test process.

mod common;

use common::{Fixture, check_encoder, check_points, check_render, fixture_pairs};

#[test]
fn generic_ops_match_the_official_model() {
    nelf_field::cpu::set_fused_kernels(false);
    for (io, weights) in fixture_pairs() {
        let fx = Fixture::load(&io, &weights);
        check_encoder(&fx);
        check_points(&fx);
        check_render(&fx);
    }
}
