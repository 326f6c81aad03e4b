//! The previous version's data points and final parameters, as the state store keeps them.

/// Data points of a grid fit and their final (corrected) parameters, in single precision:
/// enough to start a new version's foot-point searches in the right place.
///
/// Why: the correction rounds move parameters by up to a few cells where the scan is steep
/// to the plane, and a foot-point search started from the new version's mapped parameter
/// there settles on another local minimum (bun000 with 12 um of noise: RMS 165 um at the
/// previous surface instead of 66). Started from the parameter of the nearest previous
/// point it lands where the previous version's did.
///
/// In the state file both arrays are hex strings of their little-endian bytes: a 40k-point
/// scan's state took ~5 ms to write and ~6 ms to read as JSON numbers.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WarmFeet {
    /// The data points.
    #[serde(with = "hex_f32")]
    pub points: Vec<[f32; 3]>,
    /// Their final parameters.
    #[serde(with = "hex_f32")]
    pub params: Vec<[f32; 2]>,
    /// The geometric RMS error the previous version's fit ended at (0: unknown, states
    /// written before it was kept).
    #[serde(default)]
    pub rms: f64,
}

/// Arrays of f32 as one hex string of their little-endian bytes.
mod hex_f32 {
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    const DIGITS: &[u8; 16] = b"0123456789abcdef";

    pub fn serialize<S: Serializer, const N: usize>(
        values: &[[f32; N]],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let mut text = Vec::with_capacity(values.len() * N * 8);
        for byte in values.iter().flatten().flat_map(|x| x.to_le_bytes()) {
            text.push(DIGITS[(byte >> 4) as usize]);
            text.push(DIGITS[(byte & 15) as usize]);
        }
        // Hex digits are ASCII: the conversion cannot fail.
        s.serialize_str(&String::from_utf8(text).unwrap_or_default())
    }

    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        d: D,
    ) -> Result<Vec<[f32; N]>, D::Error> {
        let text = String::deserialize(d)?;
        let bytes = text.as_bytes();
        if bytes.len() % (8 * N) != 0 {
            return Err(D::Error::custom(format!(
                "{} hex digits are no whole number of {N}-float entries",
                bytes.len()
            )));
        }
        const INVALID: u8 = 0xff;
        let mut value = [INVALID; 256];
        for (v, &c) in DIGITS.iter().enumerate() {
            value[c as usize] = v as u8;
        }
        let mut raw = Vec::with_capacity(bytes.len() / 2);
        for pair in bytes.chunks_exact(2) {
            let (hi, lo) = (value[pair[0] as usize], value[pair[1] as usize]);
            if hi == INVALID || lo == INVALID {
                return Err(D::Error::custom(format!(
                    "not hex digits: {:?}",
                    String::from_utf8_lossy(pair)
                )));
            }
            raw.push(hi << 4 | lo);
        }
        Ok(raw
            .chunks_exact(4 * N)
            .map(|entry| {
                let mut out = [0f32; N];
                for (x, le) in out.iter_mut().zip(entry.chunks_exact(4)) {
                    *x = f32::from_le_bytes([le[0], le[1], le[2], le[3]]);
                }
                out
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::WarmFeet;

    /// The hex form keeps every bit (signed zeros, subnormals, infinities) and refuses
    /// what is not whole entries of hex digits.
    #[test]
    fn warm_feet_round_trip_through_their_hex_form() {
        let feet = WarmFeet {
            points: vec![
                [1.5, -0.0, f32::MIN_POSITIVE / 2.0],
                [f32::INFINITY, 3.0e-7, -123.456],
            ],
            params: vec![[0.25, 17.0], [-2.5, 1.0e30]],
            rms: 6.6e-5,
        };
        let text = serde_json::to_string(&feet).expect("serialises");
        let back: WarmFeet = serde_json::from_str(&text).expect("parses");
        let bits = |f: &WarmFeet| -> Vec<u32> {
            f.points
                .iter()
                .flatten()
                .chain(f.params.iter().flatten())
                .map(|x| x.to_bits())
                .collect()
        };
        assert_eq!(bits(&back), bits(&feet));
        assert_eq!(back.rms, feet.rms);
        for bad in [
            r#"{"points":"0000803","params":"","rms":0}"#,
            r#"{"points":"0000803g0000000000000000","params":"","rms":0}"#,
            r#"{"points":[[1,2,3]],"params":"","rms":0}"#,
        ] {
            assert!(serde_json::from_str::<WarmFeet>(bad).is_err(), "{bad}");
        }
    }
}
