//! Range checks that run inside deserialisation, so an out-of-range value is reported with
//! the line of the value (toml attaches the span) and the key (in the message).

/// Defines `fn $name(deserializer) -> Result<$ty, _>` accepting `$lo..=$hi` only (NaN and
/// infinities fail the comparison and are refused too).
macro_rules! ranged {
    ($name:ident, $key:literal, $ty:ty, $lo:expr, $hi:expr, $unit:literal) => {
        pub(crate) fn $name<'de, D: serde::Deserializer<'de>>(d: D) -> Result<$ty, D::Error> {
            let v = <$ty as serde::Deserialize>::deserialize(d)?;
            if ($lo..=$hi).contains(&v) {
                Ok(v)
            } else {
                Err(serde::de::Error::custom(format!(
                    "{}: must be in [{}, {}]{}, got {}",
                    $key, $lo, $hi, $unit, v
                )))
            }
        }
    };
}

pub(crate) use ranged;
