//! SPEC.md §6 `META`: the rule for `\u` escapes of UTF-16 surrogates, pinned on our
//! reader (`serde_json`). A high surrogate escape (`\uD800`–`\uDBFF`) must be followed at
//! once by a low one (`\uDC00`–`\uDFFF`), the pair standing for one code point of
//! U+10000…U+10FFFF; every other surrogate escape refuses the file, in keys as in values.
#![allow(clippy::unwrap_used)]

mod common;

use common::FileParts;
use common::damage::encoded;
use nelf_format::spec::{KIND_METADATA, SectionCodec};
use nelf_format::{CoefficientEncoding, FormatError, read_asset_bytes};

/// The test file with its metadata replaced by `text` (raw).
fn with_metadata(text: &str) -> Vec<u8> {
    let (_, bytes) = encoded(CoefficientEncoding::U8Affine);
    let mut parts = FileParts::parse(&bytes);
    let n = text.len() as u64;
    parts.replace(KIND_METADATA, SectionCodec::Raw, 0, text.as_bytes().to_vec(), n);
    parts.build()
}

#[test]
fn paired_surrogate_escapes_are_one_code_point() {
    for (text, want) in [
        (r#"{"a":"\ud83d\ude00"}"#, "😀"),
        (r#"{"a":"\uD83D\uDE00"}"#, "😀"),
        (r#"{"a":"\ud800\udc00"}"#, "\u{10000}"),
        (r#"{"a":"\udbff\udfff"}"#, "\u{10FFFF}"),
        (r#"{"a":"x\ud83d\ude00y"}"#, "x😀y"),
        // Escapes of the code points next to the surrogate range are plain characters.
        (r#"{"a":"\ud7ff\ue000"}"#, "\u{D7FF}\u{E000}"),
    ] {
        let asset = read_asset_bytes(&with_metadata(text)).unwrap_or_else(|e| panic!("{text}: {e}"));
        assert_eq!(asset.metadata["a"], want, "{text}");
    }
    // In a key too.
    let asset = read_asset_bytes(&with_metadata(r#"{"\ud83d\ude00":1}"#)).unwrap();
    assert_eq!(asset.metadata["😀"], 1);
}

#[test]
fn unpaired_surrogate_escapes_refuse_the_file() {
    for (text, message) in [
        // A lone high surrogate: at the end of the string, before another character,
        // before a non-`u` escape.
        (r#"{"a":"\ud800"}"#, "unexpected end of hex escape"),
        (r#"{"a":"\ud800x"}"#, "unexpected end of hex escape"),
        (r#"{"a":"\ud800\n"}"#, "unexpected end of hex escape"),
        // A high surrogate followed by an escape that is not a low surrogate.
        (r#"{"a":"\ud800\u0041"}"#, "lone leading surrogate in hex escape"),
        (r#"{"a":"\ud800\ud800"}"#, "lone leading surrogate in hex escape"),
        (r#"{"a":"\ud800\ue000"}"#, "lone leading surrogate in hex escape"),
        // A lone low surrogate, alone or after a complete pair (serde_json's message calls
        // it "leading", too).
        (r#"{"a":"\udc00"}"#, "lone leading surrogate in hex escape"),
        (r#"{"a":"\udfff\ud800"}"#, "lone leading surrogate in hex escape"),
        (
            r#"{"a":"\ud83d\ude00\ude00"}"#,
            "lone leading surrogate in hex escape",
        ),
        // In a key.
        (r#"{"\ud800":1}"#, "unexpected end of hex escape"),
        (r#"{"\udc00":1}"#, "lone leading surrogate in hex escape"),
    ] {
        match read_asset_bytes(&with_metadata(text)) {
            Err(FormatError::Json(e)) => assert!(
                e.to_string().contains(message),
                "{text}: `{e}` does not say `{message}`"
            ),
            Err(e) => panic!("{text}: refused for another reason: {e}"),
            Ok(_) => panic!("{text}: accepted"),
        }
    }
}
