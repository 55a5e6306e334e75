//! Orbit views, `AZ,EL[,DIST]`: a camera on a sphere around a point, given by azimuth and
//! elevation in degrees and, optionally, the distance in metres. One parser for every
//! place a person types one (`nelf render --orbit`, the web page's `?orbit=`), so they
//! accept and refuse the same views.

/// Largest `|elevation|` of an orbit, degrees (exclusive): the view direction must not
/// be parallel to +y, the up vector.
pub const MAX_ORBIT_ELEVATION_DEG: f64 = 89.9;

/// An orbit view, checked: finite azimuth, `|elevation| <` [`MAX_ORBIT_ELEVATION_DEG`],
/// a positive finite distance if any.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    /// Azimuth, degrees.
    pub azimuth_deg: f64,
    /// Elevation, degrees.
    pub elevation_deg: f64,
    /// Distance from the centre, metres (`None`: the viewer's default).
    pub distance_m: Option<f64>,
}

/// An orbit that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OrbitError {
    /// Not two or three numbers.
    #[error("orbit {spec:?}: expected two or three numbers AZ,EL[,DIST]")]
    Syntax {
        /// The text.
        spec: String,
    },
    /// Angles out of range.
    #[error(
        "orbit {azimuth_deg},{elevation_deg}: azimuth must be finite and elevation within (-89.9, 89.9) degrees"
    )]
    Angles {
        /// Azimuth, degrees.
        azimuth_deg: f64,
        /// Elevation, degrees.
        elevation_deg: f64,
    },
    /// Distance not positive and finite.
    #[error("orbit distance {distance_m} must be positive and finite (metres)")]
    Distance {
        /// The distance, metres.
        distance_m: f64,
    },
}

impl Orbit {
    /// Checks the ranges.
    pub fn new(azimuth_deg: f64, elevation_deg: f64, distance_m: Option<f64>) -> Result<Self, OrbitError> {
        if !(azimuth_deg.is_finite()
            && elevation_deg.is_finite()
            && elevation_deg.abs() < MAX_ORBIT_ELEVATION_DEG)
        {
            return Err(OrbitError::Angles {
                azimuth_deg,
                elevation_deg,
            });
        }
        if let Some(d) = distance_m
            && !(d.is_finite() && d > 0.0)
        {
            return Err(OrbitError::Distance { distance_m: d });
        }
        Ok(Self {
            azimuth_deg,
            elevation_deg,
            distance_m,
        })
    }

    /// Parses `AZ,EL[,DIST]` (spaces allowed around the numbers) and checks the ranges.
    pub fn parse(spec: &str) -> Result<Self, OrbitError> {
        let syntax = || OrbitError::Syntax {
            spec: spec.to_string(),
        };
        let numbers = spec
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|_| syntax())?;
        match numbers[..] {
            [a, e] => Self::new(a, e, None),
            [a, e, d] => Self::new(a, e, Some(d)),
            _ => Err(syntax()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbits_parse_and_bad_ones_are_refused() {
        let orbit = |a, e, d| Orbit {
            azimuth_deg: a,
            elevation_deg: e,
            distance_m: d,
        };
        assert_eq!(Orbit::parse("30,-10"), Ok(orbit(30.0, -10.0, None)));
        assert_eq!(Orbit::parse(" 1, 2 ,3"), Ok(orbit(1.0, 2.0, Some(3.0))));
        assert_eq!(Orbit::parse("0,-89.8"), Ok(orbit(0.0, -89.8, None)));
        for spec in ["a,b", "1", "", "1,2,3,4", "1;2", "1,,2"] {
            let error = Orbit::parse(spec).unwrap_err();
            assert!(matches!(error, OrbitError::Syntax { .. }), "{spec}: {error}");
            assert!(error.to_string().contains("AZ,EL"), "{error}");
        }
        for spec in ["0,90", "0,89.9", "10,-89.95", "inf,0", "NaN,3"] {
            let error = Orbit::parse(spec).unwrap_err();
            assert!(matches!(error, OrbitError::Angles { .. }), "{spec}: {error}");
            assert!(error.to_string().contains("elevation"), "{error}");
        }
        for spec in ["0,0,0", "0,0,-1", "0,0,inf"] {
            let error = Orbit::parse(spec).unwrap_err();
            assert!(matches!(error, OrbitError::Distance { .. }), "{spec}: {error}");
        }
    }
}
