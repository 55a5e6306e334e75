//! Allocation bound of the reader: a damaged or hostile file never makes the reader
//! allocate more than reading the intact file does, plus at most one chunk's
//! decoded size (`MAX_CHUNK_RAW_BYTES`); hostile header fields are refused before
//! anything proportional to them is allocated.
//!
//! Counting every allocation needs a global allocator, whose trait is `unsafe`; the
//! wrapper below only forwards to the system allocator and keeps two atomics. This
//! file holds a single test so no other test allocates concurrently.
#![allow(unsafe_code, clippy::unwrap_used)]

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use common::{FileParts, boundaries, damage, resign, small_asset, with_fine_density};
use nelf_format::spec::{
    HEADER_SIZE, KIND_FINE_DENSITY, KIND_VIEW_COEFFICIENTS, MAX_CHUNK_RAW_BYTES, SECTION_ENTRY_SIZE,
};
use nelf_format::synthetic::synthetic_view;
use nelf_format::{CoefficientEncoding, WriteOptions, encode_asset, read_asset_bytes};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = CURRENT.fetch_add(by, Ordering::SeqCst) + by;
    PEAK.fetch_max(now, Ordering::SeqCst);
}

// SAFETY: every method forwards to `System` with the caller's arguments unchanged.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) };
        CURRENT.fetch_sub(layout.size(), Ordering::SeqCst);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            CURRENT.fetch_sub(layout.size(), Ordering::SeqCst);
            grew(new_size);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Peak bytes allocated above the starting level while reading `bytes`.
fn peak_while_reading(bytes: &[u8]) -> (usize, bool) {
    let base = CURRENT.load(Ordering::SeqCst);
    PEAK.store(base, Ordering::SeqCst);
    let ok = read_asset_bytes(bytes).is_ok();
    (PEAK.load(Ordering::SeqCst) - base, ok)
}

#[test]
fn damaged_files_never_allocate_more_than_intact_ones() {
    let mut rng = Pcg64::seed_from_u64(3);
    let mut worst = 0usize;
    let cases = [
        (CoefficientEncoding::U8Affine, false, false),
        (CoefficientEncoding::F16, false, false),
        (CoefficientEncoding::U8Affine, true, false),
        (CoefficientEncoding::F16, true, false),
        (CoefficientEncoding::U8Affine, false, true),
        (CoefficientEncoding::F16, false, true),
    ];
    for (encoding, view, fine) in cases {
        let mut asset = small_asset(encoding, 8, 4);
        if view {
            // Format 1.2: a view part of 4 lobes × rank 6 (24 coefficients per voxel).
            asset.view = Some(synthetic_view(&asset, 4, 6, encoding, 2).unwrap());
        }
        if fine {
            // Format 1.4: a fine density at factor 2 (8 KiB a brick).
            asset = with_fine_density(asset, 2, false);
        }
        let options = WriteOptions {
            chunk_bricks: 2,
            ..WriteOptions::default()
        };
        let bytes = encode_asset(&asset, &options).unwrap().0;
        let (intact, ok) = peak_while_reading(&bytes);
        assert!(ok);
        let bound = intact + MAX_CHUNK_RAW_BYTES as usize;

        let mut damaged: Vec<Vec<u8>> = Vec::new();
        for cut in boundaries(&bytes) {
            damaged.push(bytes[..cut.min(bytes.len() - 1)].to_vec());
        }
        for _ in 0..200 {
            let mut b = bytes.clone();
            let at = rng.random_range(0..b.len());
            b[at] ^= 1 << rng.random_range(0..8);
            damaged.push(b);
        }
        // Extreme values in every aligned header and table field, re-signed.
        let sections = u32::from_le_bytes(bytes[16..20].try_into().unwrap()) as usize;
        let table_end = HEADER_SIZE + sections * SECTION_ENTRY_SIZE;
        for at in (8..table_end.min(bytes.len())).step_by(4) {
            for v in [u64::MAX, u64::from(u32::MAX), 1 << 40] {
                for width in [4, 8] {
                    let mut b = bytes.clone();
                    let end = (at + width).min(b.len());
                    b[at..end].copy_from_slice(&v.to_le_bytes()[..end - at]);
                    resign(&mut b);
                    damaged.push(b);
                }
            }
        }
        if view {
            // VCOF lying about its sizes, with valid checksums: every chunk-table length
            // and offset (each chunk claiming the whole rest of the section, or nothing),
            // and the section's declared decoded length.
            let parts = FileParts::parse(&bytes);
            let (entry, table) = parts
                .sections
                .iter()
                .find(|(e, _)| e.kind == KIND_VIEW_COEFFICIENTS)
                .unwrap()
                .clone();
            let chunks = asset.bricks.len().div_ceil(2);
            for chunk in 0..chunks {
                for (field, value) in [(8, entry.stored_length), (8, 0), (8, 1), (0, 24), (8, u64::MAX)] {
                    let mut lying = table.clone();
                    let at = 24 * chunk + field;
                    lying[at..at + 8].copy_from_slice(&value.to_le_bytes());
                    let mut p = parts.clone();
                    p.replace(
                        KIND_VIEW_COEFFICIENTS,
                        entry.codec,
                        entry.shuffle,
                        lying,
                        entry.raw_length,
                    );
                    damaged.push(p.build());
                }
            }
            for raw in [0, entry.raw_length / 2, entry.raw_length * 2, u64::MAX / 2] {
                let mut p = parts.clone();
                p.section_mut(KIND_VIEW_COEFFICIENTS).0.raw_length = raw;
                damaged.push(p.build());
            }
            // And every hostile view-dependent file (VDEP claiming other sizes included).
            damaged.extend(
                damage::hostile_view_sections()
                    .into_iter()
                    .filter(|case| matches!(case.expect, damage::Expect::Error(_)))
                    .map(|case| case.bytes),
            );
        }
        if fine {
            // DNSF lying about its decoded length, and every hostile fine density (header
            // factors and chunk sizes included).
            let parts = FileParts::parse(&bytes);
            for raw in [0, 8192, u64::from(u32::MAX), u64::MAX / 2] {
                let mut p = parts.clone();
                p.section_mut(KIND_FINE_DENSITY).0.raw_length = raw;
                damaged.push(p.build());
            }
            damaged.extend(
                damage::hostile_fine_density_sections()
                    .into_iter()
                    .filter(|case| matches!(case.expect, damage::Expect::Error(_)))
                    .map(|case| case.bytes),
            );
        }
        for b in &damaged {
            let (peak, ok) = peak_while_reading(b);
            assert!(
                !ok || b.len() == bytes.len() || view,
                "a damaged file was accepted"
            );
            assert!(peak <= bound, "peak {peak} bytes > intact {intact} + one chunk");
            worst = worst.max(peak);
        }
        eprintln!(
            "{encoding:?} (view part: {view}, fine density: {fine}): file {} bytes, intact read peak {intact} bytes, worst damaged {worst} bytes over {} cases",
            bytes.len(),
            damaged.len()
        );
    }
}
