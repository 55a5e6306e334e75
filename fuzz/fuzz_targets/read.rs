//! Fuzz target for the `.nelf` reader: arbitrary bytes through the whole-file reader
//! and the random-access reader (every brick, then `verify`). Any panic, abort,
//! out-of-memory or timeout is a bug; errors are the expected outcome.
//!
//! Run (stable toolchain, see format/SPEC.md "Fuzzing"):
//! `cd fuzz && RUSTC_BOOTSTRAP=1 cargo fuzz run read -- -max_total_time=60`
#![no_main]

use std::io::Cursor;

use libfuzzer_sys::fuzz_target;
use nelf_format::{AssetReader, read_asset_bytes};

fuzz_target!(|data: &[u8]| {
    if let Ok(asset) = read_asset_bytes(data) {
        // Whatever the reader accepts must be a valid asset.
        assert!(asset.validate().is_ok());
    }
    if let Ok(mut reader) = AssetReader::new(Cursor::new(data)) {
        // A fine density (format 1.4) gives 512·F³ values a brick, F = 2 or 4; none, none.
        let factor = reader.header().fine_density_factor as usize;
        assert!([0, 2, 4].contains(&factor));
        for i in 0..reader.bricks().len() {
            match reader.read_brick(i) {
                Ok(brick) => assert_eq!(brick.fine_density.len(), 512 * factor.pow(3)),
                Err(_) => break,
            }
        }
        let _ = reader.verify();
    }
});
