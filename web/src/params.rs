//! The web page's URL parameters: which asset and environment map to fetch, and the
//! camera, lighting and display to start with, so that a view is a link.
//!
//! `?asset=URL&env=URL&orbit=AZ,EL[,DIST]&rotate=DEG&exposure=EV&tonemap=aces|linear`
//! `&background=R,G,B&jitter=0|1&continuous=0|1`. Values are percent-decoded; unknown
//! keys are errors (a typo should not silently show another view); a key given twice
//! takes its last value, so an exported page's defaults (its `nelf-defaults` meta tag,
//! read first) yield to the link's own parameters.

use nelf_format::orbit::Orbit;
use nelf_viewer::{OrbitStart, StartView, ToneMap};

/// What the URL asks for.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WebParams {
    /// The `.nelf` to fetch (relative URLs are the page's).
    pub asset: Option<String>,
    /// The `.exr`/`.hdr` environment map to fetch.
    pub env: Option<String>,
    /// Camera, lighting and display at start.
    pub start: StartView,
}

/// A parameter the page cannot use.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("URL parameter {key}={value:?}: {reason}")]
pub struct ParamError {
    /// The key.
    pub key: String,
    /// Its (decoded) value.
    pub value: String,
    /// What is wrong.
    pub reason: &'static str,
}

impl WebParams {
    /// Parses a query string (`location.search`, with or without the leading `?`).
    pub fn parse(query: &str) -> Result<Self, ParamError> {
        let mut params = Self::default();
        let query = query.strip_prefix('?').unwrap_or(query);
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, raw) = pair.split_once('=').unwrap_or((pair, ""));
            let key = percent_decode(key);
            let value = percent_decode(raw);
            let bad = |reason| ParamError {
                key: key.clone(),
                value: value.clone(),
                reason,
            };
            match key.as_str() {
                "asset" => params.asset = Some(value.clone()),
                "env" => params.env = Some(value.clone()),
                "orbit" => {
                    // The same parser and ranges as `nelf render --orbit`.
                    let orbit = Orbit::parse(&value).map_err(|_| {
                        bad("expected AZ,EL or AZ,EL,DIST (degrees, degrees within ±89.9, metres > 0)")
                    })?;
                    params.start.orbit = Some(OrbitStart {
                        azimuth_deg: orbit.azimuth_deg,
                        elevation_deg: orbit.elevation_deg,
                        distance_m: orbit.distance_m,
                    });
                }
                "rotate" => {
                    params.start.rotation_deg =
                        parse_finite(&value).ok_or_else(|| bad("expected degrees"))?;
                }
                "exposure" => {
                    params.start.exposure_ev = parse_finite(&value).ok_or_else(|| bad("expected stops"))?;
                }
                "tonemap" => {
                    params.start.tone_map = match value.as_str() {
                        "aces" => ToneMap::Aces,
                        "linear" => ToneMap::Linear,
                        _ => return Err(bad("expected aces or linear")),
                    }
                }
                "background" => {
                    params.start.background =
                        parse_rgb(&value).ok_or_else(|| bad("expected R,G,B (linear, ≥ 0)"))?;
                }
                "jitter" => params.start.jitter = parse_flag(&value).ok_or_else(|| bad("expected 0 or 1"))?,
                "continuous" => {
                    params.start.continuous = parse_flag(&value).ok_or_else(|| bad("expected 0 or 1"))?;
                }
                _ => {
                    return Err(bad(
                        "unknown parameter (asset, env, orbit, rotate, exposure, tonemap, background, jitter, continuous)",
                    ));
                }
            }
        }
        Ok(params)
    }
}

fn parse_finite(value: &str) -> Option<f32> {
    value.trim().parse::<f32>().ok().filter(|v| v.is_finite())
}

fn parse_rgb(value: &str) -> Option<[f32; 3]> {
    let parts: Vec<f32> = value
        .split(',')
        .map(|p| parse_finite(p).filter(|v| *v >= 0.0))
        .collect::<Option<_>>()?;
    parts.try_into().ok()
}

fn parse_flag(value: &str) -> Option<bool> {
    match value {
        "1" | "true" => Some(true),
        "0" | "false" => Some(false),
        _ => None,
    }
}

/// Decodes `%XX` escapes and `+` (a space in query strings); malformed escapes stay as
/// they are.
fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => out.push(b' '),
            b'%' => {
                let hex = text
                    .get(i + 1..i + 3)
                    .and_then(|h| u8::from_str_radix(h, 16).ok());
                match hex {
                    Some(b) => {
                        out.push(b);
                        i += 3;
                        continue;
                    }
                    None => out.push(b'%'),
                }
            }
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_link_sets_asset_map_camera_and_lighting() {
        let p = WebParams::parse("?asset=head.nelf&env=maps%2Fstudio.exr&orbit=30,-10,0.9&rotate=45&exposure=-1.5&tonemap=linear&background=0,0.5,1&jitter=0&continuous=1").unwrap();
        assert_eq!(p.asset.as_deref(), Some("head.nelf"));
        assert_eq!(p.env.as_deref(), Some("maps/studio.exr"));
        assert_eq!(
            p.start.orbit,
            Some(OrbitStart {
                azimuth_deg: 30.0,
                elevation_deg: -10.0,
                distance_m: Some(0.9)
            })
        );
        assert_eq!(p.start.rotation_deg, 45.0);
        assert_eq!(p.start.exposure_ev, -1.5);
        assert_eq!(p.start.tone_map, ToneMap::Linear);
        assert_eq!(p.start.background, [0.0, 0.5, 1.0]);
        assert!(!p.start.jitter && p.start.continuous);
    }

    #[test]
    fn an_empty_query_is_the_default_view() {
        assert_eq!(WebParams::parse("").unwrap(), WebParams::default());
        assert_eq!(WebParams::parse("?").unwrap(), WebParams::default());
        let p = WebParams::parse("orbit=10,5").unwrap();
        assert_eq!(p.start.orbit.and_then(|o| o.distance_m), None);
    }

    #[test]
    fn later_keys_override_earlier_ones() {
        let p = WebParams::parse("asset=a.nelf&rotate=10&asset=b.nelf").unwrap();
        assert_eq!(p.asset.as_deref(), Some("b.nelf"));
        assert_eq!(p.start.rotation_deg, 10.0);
    }

    #[test]
    fn bad_values_and_unknown_keys_are_named() {
        for (query, key) in [
            ("orbit=10", "orbit"),
            ("orbit=1,2,-3", "orbit"),
            ("orbit=a,b", "orbit"),
            ("orbit=0,95", "orbit"),
            ("rotate=NaN", "rotate"),
            ("tonemap=filmic", "tonemap"),
            ("jitter=maybe", "jitter"),
            ("background=1,1", "background"),
            ("background=1,-1,0", "background"),
            ("camera=1", "camera"),
        ] {
            let err = WebParams::parse(query).unwrap_err();
            assert_eq!(err.key, key, "{query}");
            assert!(err.to_string().contains(key), "{err}");
        }
    }

    #[test]
    fn percent_escapes_decode_and_malformed_ones_stay() {
        assert_eq!(percent_decode("a%20b+c"), "a b c");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("%zz%4"), "%zz%4");
        assert_eq!(percent_decode("%C3%A9"), "é");
    }
}
