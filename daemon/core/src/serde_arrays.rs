//! Serde for the arrays serde itself does not cover (it stops at 32 elements): the dynamic
//! model's 38 terms and the monitor's 38 x 38 normal equations. Only the machine checkpoint
//! (`machine::checkpoint`) serialises them; each is written as a flat sequence and its length
//! checked when read back.

use serde::de::Error;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

fn exact<E: Error, T, const N: usize>(v: Vec<T>) -> Result<[T; N], E> {
    let len = v.len();
    v.try_into()
        .map_err(|_| E::invalid_length(len, &"the array's length"))
}

/// `[T; N]` of any length.
pub mod array {
    use super::*;

    pub fn serialize<S: Serializer, T: Serialize, const N: usize>(
        a: &[T; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(a.iter())
    }

    pub fn deserialize<'de, D: Deserializer<'de>, T: Deserialize<'de>, const N: usize>(
        d: D,
    ) -> Result<[T; N], D::Error> {
        exact(Vec::<T>::deserialize(d)?)
    }
}

/// `[[f64; N]; M]`, row after row.
pub mod matrix {
    use super::*;

    pub fn serialize<S: Serializer, const N: usize, const M: usize>(
        a: &[[f64; N]; M],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(a.iter().flatten())
    }

    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize, const M: usize>(
        d: D,
    ) -> Result<[[f64; N]; M], D::Error> {
        let flat = Vec::<f64>::deserialize(d)?;
        if flat.len() != N * M {
            return Err(D::Error::invalid_length(flat.len(), &"rows times columns"));
        }
        let mut out = [[0.0; N]; M];
        for (row, chunk) in out.iter_mut().zip(flat.chunks_exact(N)) {
            row.copy_from_slice(chunk);
        }
        Ok(out)
    }
}

/// `Option<([f64; N], f64)>`.
pub mod option_array_f64 {
    use super::*;

    pub fn serialize<S: Serializer, const N: usize>(
        a: &Option<([f64; N], f64)>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        a.as_ref().map(|(v, x)| (&v[..], *x)).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        d: D,
    ) -> Result<Option<([f64; N], f64)>, D::Error> {
        match Option::<(Vec<f64>, f64)>::deserialize(d)? {
            None => Ok(None),
            Some((v, x)) => Ok(Some((exact(v)?, x))),
        }
    }
}
