//! MGF colours: CIE xy chromaticities, from `cxy`, from spectra (`cspec`, `cct` blackbodies,
//! integrated with the CIE 1931 2° observer at 10 nm) or mixed (`cmix`, weighted in Y), and
//! their conversion to linear sRGB with equal-energy white mapped to grey and luminance
//! normalised to 1 (ρ = `rd` × colour, L_e = `ed` × colour / π).

use glam::DVec3;

/// CIE 1931 2° colour matching functions x̄, ȳ, z̄ at 380, 390, ..., 780 nm.
const CMF: [[f64; 3]; 41] = [
    [0.001368, 0.000039, 0.006450],
    [0.004243, 0.000120, 0.020050],
    [0.014310, 0.000396, 0.067850],
    [0.043510, 0.001210, 0.207400],
    [0.134380, 0.004000, 0.645600],
    [0.283900, 0.011600, 1.385600],
    [0.348280, 0.023000, 1.747060],
    [0.336200, 0.038000, 1.772110],
    [0.290800, 0.060000, 1.669200],
    [0.195360, 0.090980, 1.287640],
    [0.095640, 0.139020, 0.812950],
    [0.032010, 0.208020, 0.465180],
    [0.004900, 0.323000, 0.272000],
    [0.009300, 0.503000, 0.158200],
    [0.063270, 0.710000, 0.078250],
    [0.165500, 0.862000, 0.042160],
    [0.290400, 0.954000, 0.020300],
    [0.433450, 0.994950, 0.008750],
    [0.594500, 0.995000, 0.003900],
    [0.762100, 0.952000, 0.002100],
    [0.916300, 0.870000, 0.001650],
    [1.026300, 0.757000, 0.001100],
    [1.062200, 0.631000, 0.000800],
    [1.002600, 0.503000, 0.000340],
    [0.854450, 0.381000, 0.000190],
    [0.642400, 0.265000, 0.000050],
    [0.447900, 0.175000, 0.000020],
    [0.283500, 0.107000, 0.000000],
    [0.164900, 0.061000, 0.000000],
    [0.087400, 0.032000, 0.000000],
    [0.046770, 0.017000, 0.000000],
    [0.022700, 0.008210, 0.000000],
    [0.011359, 0.004102, 0.000000],
    [0.005790, 0.002091, 0.000000],
    [0.002899, 0.001047, 0.000000],
    [0.001440, 0.000520, 0.000000],
    [0.000690, 0.000249, 0.000000],
    [0.000332, 0.000120, 0.000000],
    [0.000166, 0.000060, 0.000000],
    [0.000083, 0.000030, 0.000000],
    [0.000042, 0.000015, 0.000000],
];

/// Smallest chromaticity y used in conversions (colours of y = 0 have no luminance).
pub(super) const MIN_Y: f64 = 1e-3;

/// A colour: CIE xy chromaticity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Xy {
    /// Chromaticity x.
    pub x: f64,
    /// Chromaticity y.
    pub y: f64,
}

impl Xy {
    /// Equal-energy white, the MGF default colour.
    pub const NEUTRAL: Xy = Xy {
        x: 1.0 / 3.0,
        y: 1.0 / 3.0,
    };
}

/// Chromaticity of a spectrum given by `f(λ)` (nm), integrated at 10 nm over 380–780 nm.
/// `None` when the spectrum has no visible energy.
pub fn spectrum_xy(f: impl Fn(f64) -> f64) -> Option<Xy> {
    let mut xyz = [0.0f64; 3];
    for (k, c) in CMF.iter().enumerate() {
        let s = f(380.0 + 10.0 * k as f64);
        for i in 0..3 {
            xyz[i] += s * c[i];
        }
    }
    let sum = xyz[0] + xyz[1] + xyz[2];
    (sum.is_finite() && sum > 0.0 && xyz[1] > 0.0).then(|| Xy {
        x: xyz[0] / sum,
        y: xyz[1] / sum,
    })
}

/// Chromaticity of a blackbody at `kelvin`.
pub fn blackbody_xy(kelvin: f64) -> Option<Xy> {
    const C2: f64 = 1.4388e7; // nm·K
    spectrum_xy(|l| l.powi(-5) / ((C2 / (l * kelvin)).exp() - 1.0))
}

/// Linear sRGB of a chromaticity at luminance 1, equal-energy white mapped to (1, 1, 1);
/// out-of-gamut (negative) channels are clipped to 0 before the luminance is renormalised.
pub fn xy_to_rgb(c: Xy) -> DVec3 {
    let m = |x: f64, y: f64| {
        let xyz = DVec3::new(x / y, 1.0, (1.0 - x - y) / y);
        DVec3::new(
            3.2404542 * xyz.x - 1.5371385 * xyz.y - 0.4985314 * xyz.z,
            -0.9692660 * xyz.x + 1.8760108 * xyz.y + 0.0415560 * xyz.z,
            0.0556434 * xyz.x - 0.2040259 * xyz.y + 1.0572252 * xyz.z,
        )
    };
    let white = m(1.0 / 3.0, 1.0 / 3.0);
    let rgb = (m(c.x, c.y.max(MIN_Y)) / white).max(DVec3::ZERO);
    let lum = rgb.dot(DVec3::new(0.2126, 0.7152, 0.0722));
    if lum > 0.0 && lum.is_finite() {
        rgb / lum
    } else {
        DVec3::ONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_energy_white_is_grey() {
        let c = spectrum_xy(|_| 1.0).unwrap();
        assert!(
            (c.x - 1.0 / 3.0).abs() < 2e-3 && (c.y - 1.0 / 3.0).abs() < 2e-3,
            "{c:?}"
        );
        let g = xy_to_rgb(Xy::NEUTRAL);
        assert!((g - DVec3::ONE).abs().max_element() < 1e-9, "{g}");
        // A 6500 K blackbody is close to D65 (0.3135, 0.3237).
        let d = blackbody_xy(6500.0).unwrap();
        assert!(
            (d.x - 0.3135).abs() < 3e-3 && (d.y - 0.3237).abs() < 3e-3,
            "{d:?}"
        );
    }
}
