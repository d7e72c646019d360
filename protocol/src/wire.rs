//! Building blocks for values that cross shared memory: enums carried as plain `u32`
//! fields and a fixed-capacity UTF-8 text field.
//!
//! Anything read from shared memory was written by another process that may be buggy or
//! from another build, so every bit pattern of a message must be a valid Rust value.
//! That rules out Rust enums, `bool` and pointer-like containers as message fields: an
//! enum discriminant of 7 or a `bool` of 2 would be undefined behaviour the moment the
//! message is copied. Instead enums travel as `u32` and are decoded with `TryFrom<u32>`,
//! so a garbage value is an ordinary validation error.

use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// A `u32` enum field held a value that no variant uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{enum_name} has no variant with value {value}")]
pub struct UnknownEnumValue {
    /// Name of the Rust enum the value was decoded into.
    pub enum_name: &'static str,
    /// The raw value found in the message.
    pub value: u32,
}

/// Declares a `#[repr(u32)]` enum with `TryFrom<u32>`, `From<Enum> for u32`, `ALL` and
/// `name()`. Variant values are explicit because they are part of the wire format.
macro_rules! wire_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $value:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default,
                 serde::Serialize, serde::Deserialize)]
        #[repr(u32)]
        pub enum $name {
            $( $(#[$vmeta])* $variant = $value ),+
        }

        impl $name {
            /// Every variant, in wire-value order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            /// The variant's name, for logs and operator output.
            pub const fn name(self) -> &'static str {
                match self { $( $name::$variant => stringify!($variant) ),+ }
            }

            /// The value carried in the message's `u32` field.
            pub const fn as_u32(self) -> u32 {
                self as u32
            }
        }

        impl TryFrom<u32> for $name {
            type Error = $crate::wire::UnknownEnumValue;

            fn try_from(value: u32) -> Result<Self, Self::Error> {
                match value {
                    $( $value => Ok($name::$variant), )+
                    _ => Err($crate::wire::UnknownEnumValue {
                        enum_name: stringify!($name),
                        value,
                    }),
                }
            }
        }

        impl From<$name> for u32 {
            fn from(v: $name) -> u32 {
                v as u32
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}
pub(crate) use wire_enum;

/// Fixed-capacity UTF-8 text, NUL-padded, safe to read whatever bytes it holds.
///
/// We do not use `iceoryx2_bb_container::StaticString` in messages: it stores its length
/// as a separate field and trusts it when reading, so a corrupt length from another
/// process would slice out of bounds. Here the length is implied by the first NUL and
/// decoding stops at the last complete UTF-8 character, so any byte pattern decodes to
/// a valid (possibly shortened) `&str`.
#[repr(C)]
#[derive(ZeroCopySend, Clone, Copy, PartialEq, Eq)]
pub struct FixedText<const N: usize> {
    bytes: [u8; N],
}

impl<const N: usize> FixedText<N> {
    /// Capacity in bytes (UTF-8), not characters.
    pub const CAPACITY: usize = N;

    /// An empty text.
    pub const fn new() -> Self {
        Self { bytes: [0; N] }
    }

    /// Text holding `s`, truncated as [`FixedText::set`] does.
    pub fn from_str_truncated(s: &str) -> Self {
        let mut t = Self::new();
        t.set(s);
        t
    }

    /// Stores `s` and returns the number of bytes stored. A text that does not fit is cut
    /// at a word boundary (or, in a word longer than half the room, at a character boundary)
    /// and ends in `...`, so a reader sees it was cut rather than a word that reads wrong
    /// (issue 27: "estimate af"). Interior NUL characters end the text (they are the
    /// terminator on the wire).
    pub fn set(&mut self, s: &str) -> usize {
        const ELLIPSIS: &str = "...";
        let s = s.split('\0').next().unwrap_or("");
        self.bytes = [0; N];
        if s.len() <= N {
            self.bytes[..s.len()].copy_from_slice(s.as_bytes());
            return s.len();
        }
        let Some(budget) = N.checked_sub(ELLIPSIS.len()) else {
            // Too small for an ellipsis: a plain cut at a character boundary.
            let mut len = N;
            while !s.is_char_boundary(len) {
                len -= 1;
            }
            self.bytes[..len].copy_from_slice(&s.as_bytes()[..len]);
            return len;
        };
        let mut cut = budget;
        while !s.is_char_boundary(cut) {
            cut -= 1;
        }
        let mid_word = !s[cut..].starts_with(char::is_whitespace);
        if mid_word {
            if let Some(space) = s[..cut].rfind(char::is_whitespace) {
                if space >= budget / 2 {
                    cut = space;
                }
            }
        }
        let kept = s[..cut].trim_end();
        let len = kept.len() + ELLIPSIS.len();
        self.bytes[..kept.len()].copy_from_slice(kept.as_bytes());
        self.bytes[kept.len()..len].copy_from_slice(ELLIPSIS.as_bytes());
        len
    }

    /// The stored text: bytes up to the first NUL, cut back to the longest valid UTF-8
    /// prefix if the sender wrote invalid bytes.
    pub fn as_str(&self) -> &str {
        let end = self.bytes.iter().position(|&b| b == 0).unwrap_or(N);
        let raw = &self.bytes[..end];
        match std::str::from_utf8(raw) {
            Ok(s) => s,
            // valid_up_to() is always a char boundary of a valid prefix, so this cannot fail.
            Err(e) => std::str::from_utf8(&raw[..e.valid_up_to()]).unwrap_or(""),
        }
    }

    /// True when the stored bytes (up to the first NUL) are valid UTF-8.
    pub fn is_valid_utf8(&self) -> bool {
        let end = self.bytes.iter().position(|&b| b == 0).unwrap_or(N);
        std::str::from_utf8(&self.bytes[..end]).is_ok()
    }

    /// True when no text is stored.
    pub fn is_empty(&self) -> bool {
        self.bytes[0] == 0
    }

    /// Raw bytes as they travel (for tests that inject garbage).
    pub fn as_bytes(&self) -> &[u8; N] {
        &self.bytes
    }

    /// Mutable raw bytes (for tests that inject garbage).
    pub fn as_bytes_mut(&mut self) -> &mut [u8; N] {
        &mut self.bytes
    }
}

impl<const N: usize> Default for FixedText<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> fmt::Debug for FixedText<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self.as_str(), f)
    }
}

impl<const N: usize> fmt::Display for FixedText<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl<const N: usize> Serialize for FixedText<N> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de, const N: usize> Deserialize<'de> for FixedText<N> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let s = String::deserialize(deserializer)?;
        Ok(Self::from_str_truncated(&s))
    }
}

/// On the wire a JSON string of at most `N` bytes of UTF-8 (what `Serialize` writes).
#[cfg(feature = "schema")]
impl<const N: usize> schemars::JsonSchema for FixedText<N> {
    fn inline_schema() -> bool {
        true
    }

    fn schema_name() -> std::borrow::Cow<'static, str> {
        format!("FixedText{N}").into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "type": "string",
            "description": format!("UTF-8 text of at most {N} bytes"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_round_trips_and_truncates_at_char_boundary() {
        let mut t = FixedText::<8>::new();
        assert_eq!(t.set("hello"), 5);
        assert_eq!(t.as_str(), "hello");
        // "aaaaaaé" is 6 + 2 = 8 bytes: fits exactly.
        assert_eq!(t.set("aaaaaaé"), 8);
        assert_eq!(t.as_str(), "aaaaaaé");
        // 7 ASCII + 2-byte char = 9 bytes: cut, marked with an ellipsis.
        assert_eq!(t.set("aaaaaaaé"), 8);
        assert_eq!(t.as_str(), "aaaaa...");
        // At a word when the word is short, never splitting a character.
        assert_eq!(t.set("ab cdefgh"), 5);
        assert_eq!(t.as_str(), "ab...");
        assert_eq!(t.set("abcdéfgh"), 7);
        assert_eq!(t.as_str(), "abcd...");
        // Shorter text after longer text leaves no tail behind.
        t.set("ab");
        assert_eq!(t.as_str(), "ab");
        assert_eq!(&t.as_bytes()[2..], &[0u8; 6]);
    }

    #[test]
    fn garbage_bytes_decode_to_valid_prefix() {
        let mut t = FixedText::<8>::new();
        *t.as_bytes_mut() = [b'o', b'k', 0xff, 0xfe, b'x', b'y', b'z', b'w'];
        assert_eq!(t.as_str(), "ok");
        assert!(!t.is_valid_utf8());
        // No NUL at all: the whole buffer is the text.
        *t.as_bytes_mut() = *b"abcdefgh";
        assert_eq!(t.as_str(), "abcdefgh");
        assert!(t.is_valid_utf8());
    }

    #[test]
    fn interior_nul_ends_text() {
        let t = FixedText::<16>::from_str_truncated("abc\0def");
        assert_eq!(t.as_str(), "abc");
    }
}
