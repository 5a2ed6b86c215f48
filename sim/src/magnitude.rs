//! Magnitudes: how a scenario writes a number it wants drawn (see [`crate::scenario`], "Magnitudes").
//!
//! Below the effects (each effect's scenario section holds magnitudes) and the scenario; it reads only
//! the errors and the seeds. Also reachable as `sim::scenario::magnitude`.

use crate::error::{Result, scenario_err};
use crate::seeds::{STREAM_PARAMETERS, rng_for};
use rand::RngExt;
use rand_distr::StandardNormal;
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

/// A fixed value, a random draw, or a list of magnitudes (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum Magnitude {
    /// The same value for every entry.
    Number(f64),
    /// An independent draw for every entry.
    Draw(Draw),
    /// One item per entry of the leading dimension.
    List(Vec<Magnitude>),
}

/// A random draw.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Draw {
    /// Uniform on `[low, high]`.
    Uniform([f64; 2]),
    /// Normal with `[mean, standard deviation]`.
    Normal([f64; 2]),
}

impl Serialize for Magnitude {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Magnitude::Number(x) => s.serialize_f64(*x),
            Magnitude::Draw(d) => d.serialize(s),
            Magnitude::List(v) => v.serialize(s),
        }
    }
}

struct MagnitudeVisitor;

impl<'de> Visitor<'de> for MagnitudeVisitor {
    type Value = Magnitude;
    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(
            "a number, a list, or a random draw { uniform = [low, high] } or { normal = [mean, sd] }",
        )
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<Magnitude, E> {
        Ok(Magnitude::Number(v))
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Magnitude, E> {
        Ok(Magnitude::Number(v as f64))
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Magnitude, E> {
        Ok(Magnitude::Number(v as f64))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<Magnitude, A::Error> {
        let mut v = Vec::new();
        while let Some(m) = seq.next_element::<Magnitude>()? {
            v.push(m);
        }
        Ok(Magnitude::List(v))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> std::result::Result<Magnitude, A::Error> {
        const KINDS: &[&str] = &["uniform", "normal"];
        let Some(kind) = map.next_key::<String>()? else {
            return Err(de::Error::custom(
                "empty table: a draw is { uniform = [low, high] } or { normal = [mean, sd] }",
            ));
        };
        let params: [f64; 2] = map.next_value()?;
        let draw = match kind.as_str() {
            "uniform" => Draw::Uniform(params),
            "normal" => Draw::Normal(params),
            _ => return Err(de::Error::unknown_field(&kind, KINDS)),
        };
        if let Some(extra) = map.next_key::<String>()? {
            return Err(de::Error::custom(format!(
                "a draw has exactly one key (uniform or normal); found also `{extra}`"
            )));
        }
        Ok(Magnitude::Draw(draw))
    }
}

impl<'de> Deserialize<'de> for Magnitude {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Magnitude, D::Error> {
        d.deserialize_any(MagnitudeVisitor)
    }
}

/// FNV-1a, 64 bit: a stable hash for stream ids and file fingerprints.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

impl Magnitude {
    /// Resolves to `shape.iter().product()` numbers, row-major, drawing from a generator seeded by
    /// `seed` and `key`. `file` and `key` name errors.
    pub fn resolve(&self, seed: u64, file: &str, key: &str, shape: &[usize]) -> Result<Vec<f64>> {
        let mut rng = rng_for(seed, STREAM_PARAMETERS, fnv1a64(key.as_bytes()));
        let mut out = Vec::with_capacity(shape.iter().product());
        self.fill(&mut rng, file, key, shape, &mut out)?;
        Ok(out)
    }

    fn fill<R: rand::Rng>(
        &self,
        rng: &mut R,
        file: &str,
        key: &str,
        shape: &[usize],
        out: &mut Vec<f64>,
    ) -> Result<()> {
        let e = |m: String| scenario_err(file, key, m);
        match self {
            Magnitude::Number(x) => {
                if x.is_nan() {
                    return Err(e("NaN is not a value".into()));
                }
                out.extend(std::iter::repeat_n(*x, shape.iter().product()));
            }
            Magnitude::Draw(d) => {
                let count: usize = shape.iter().product();
                match *d {
                    Draw::Uniform([lo, hi]) => {
                        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                            return Err(e(format!(
                                "uniform = [{lo}, {hi}] needs finite bounds with low ≤ high"
                            )));
                        }
                        for _ in 0..count {
                            let u: f64 = rng.random();
                            out.push(lo + (hi - lo) * u);
                        }
                    }
                    Draw::Normal([mean, sd]) => {
                        if !(mean.is_finite() && sd.is_finite() && sd >= 0.0) {
                            return Err(e(format!(
                                "normal = [{mean}, {sd}] needs a finite mean and a standard deviation ≥ 0"
                            )));
                        }
                        for _ in 0..count {
                            let z: f64 = rng.sample(StandardNormal);
                            out.push(mean + sd * z);
                        }
                    }
                }
            }
            Magnitude::List(items) => {
                let Some((&first, rest)) = shape.split_first() else {
                    return Err(e(format!(
                        "a list of {} where one value is expected",
                        items.len()
                    )));
                };
                if items.len() != first {
                    return Err(e(format!(
                        "{} entries, expected {first} (or one value or draw for all)",
                        items.len()
                    )));
                }
                for (i, m) in items.iter().enumerate() {
                    m.fill(rng, file, &format!("{key}[{i}]"), rest, out)?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magnitudes_broadcast_and_lists_nest() {
        let m: Magnitude = toml::from_str::<toml::Table>("a = [[1, 2, 3], 4]")
            .unwrap()
            .get("a")
            .unwrap()
            .clone()
            .try_into()
            .unwrap();
        assert_eq!(
            m.resolve(0, "f", "a", &[2, 3]).unwrap(),
            vec![1.0, 2.0, 3.0, 4.0, 4.0, 4.0]
        );
        let e = m.resolve(0, "f", "a", &[3, 3]).unwrap_err().to_string();
        assert!(e.contains("a: 2 entries, expected 3"), "{e}");
    }
}
