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
        for i in 0..reader.bricks().len() {
            if reader.read_brick(i).is_err() {
                break;
            }
        }
        let _ = reader.verify();
    }
});
