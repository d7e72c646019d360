//! Figures over many seeds (`thrusterctl experiment NAME --seeds 1-10`): a single seed varies
//! a lot (the misaligned experiment's yaw error moved by 2x between seeds), so a figure in
//! docs/ is given as mean, standard deviation and range over seeds, each run reproducible
//! exactly since the lab steps the simulator's vehicle time.

use std::ops::RangeInclusive;

use anyhow::{bail, Result};
use serde_json::{json, Map, Value};

/// Parses `A-B` (or a single seed `A`) into a range of at most 1000 seeds.
pub fn parse_range(text: &str) -> Result<RangeInclusive<u64>> {
    let (a, b) = text.split_once('-').unwrap_or((text, text));
    let (Ok(a), Ok(b)) = (a.trim().parse::<u64>(), b.trim().parse::<u64>()) else {
        bail!("--seeds must be A-B (e.g. 1-10) or one seed, got {text:?}");
    };
    if a > b || b - a >= 1000 {
        bail!("--seeds {text:?}: expected A <= B and at most 1000 seeds");
    }
    Ok(a..=b)
}

/// Mean, sample standard deviation, least and largest of `xs` (finite values only), and how
/// many there were.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    pub n: usize,
    pub mean: f64,
    pub sd: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    pub fn of(xs: &[f64]) -> Option<Spread> {
        let xs: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
        if xs.is_empty() {
            return None;
        }
        let n = xs.len();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let sd = if n > 1 {
            (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        let min = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let max = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Some(Spread {
            n,
            mean,
            sd,
            min,
            max,
        })
    }

    fn json(&self) -> Value {
        json!({"n": self.n, "mean": self.mean, "sd": self.sd, "min": self.min, "max": self.max})
    }
}

/// The numeric fields of every seed's `headline` (nested objects' as `outer.inner`), in the
/// order of the first seed's, each with its spread over the seeds (a field missing or null in
/// a seed is left out of it).
pub fn headline_spread(headlines: &[Value]) -> Vec<(String, Spread)> {
    let Some(first) = headlines.first() else {
        return Vec::new();
    };
    let mut paths = Vec::new();
    numeric_paths(first, "", &mut paths);
    paths
        .into_iter()
        .filter_map(|path| {
            let xs: Vec<f64> = headlines
                .iter()
                .filter_map(|h| lookup(h, &path).and_then(Value::as_f64))
                .collect();
            Spread::of(&xs).map(|s| (path, s))
        })
        .collect()
}

/// Dotted paths of the fields of `v` that are numbers, or null (a figure a seed could not
/// measure, which another seed may have).
fn numeric_paths(v: &Value, prefix: &str, out: &mut Vec<String>) {
    if let Value::Object(map) = v {
        for (k, x) in map {
            let path = if prefix.is_empty() {
                k.clone()
            } else {
                format!("{prefix}.{k}")
            };
            match x {
                Value::Object(_) => numeric_paths(x, &path, out),
                Value::Number(_) | Value::Null => out.push(path),
                _ => {}
            }
        }
    }
}

fn lookup<'a>(v: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.').try_fold(v, |x, k| x.get(k))
}

/// The JSON of a many-seed run: each seed's headline, and the spread of each figure.
pub fn summary(experiment: &str, seeds: &[u64], headlines: &[Value]) -> Value {
    let mut stats = Map::new();
    for (k, s) in headline_spread(headlines) {
        stats.insert(k, s.json());
    }
    json!({
        "experiment": experiment,
        "seeds": seeds,
        "headline_per_seed": headlines,
        "headline_over_seeds": stats,
    })
}

/// The report: one row per figure, `mean +- sd (min - max)`.
pub fn table(experiment: &str, seeds: &[u64], headlines: &[Value]) -> String {
    let (first, last) = (seeds.first().unwrap_or(&0), seeds.last().unwrap_or(&0));
    let mut t = format!(
        "{experiment}: {} seeds ({first}-{last})\n\n| figure | mean | sd | min | max | seeds |\n|---|---|---|---|---|---|\n",
        seeds.len()
    );
    for (k, s) in headline_spread(headlines) {
        t += &format!(
            "| {k} | {:.4} | {:.4} | {:.4} | {:.4} | {} |\n",
            s.mean, s.sd, s.min, s.max, s.n
        );
    }
    if let Some(claim) = headlines
        .first()
        .and_then(|h| h.get("claim"))
        .and_then(Value::as_str)
    {
        t += &format!("\nclaim: {claim}\n");
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_range_of_seeds_is_a_to_b_or_one_seed() {
        assert_eq!(parse_range("1-10").unwrap(), 1..=10);
        assert_eq!(parse_range("7").unwrap(), 7..=7);
        for bad in ["10-1", "a-3", "1-", "0-5000", ""] {
            assert!(parse_range(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn the_spread_is_the_sample_mean_sd_and_range_of_the_finite_values() {
        let s = Spread::of(&[1.0, 2.0, 3.0, 4.0, f64::NAN]).unwrap();
        assert_eq!((s.n, s.mean, s.min, s.max), (4, 2.5, 1.0, 4.0));
        assert!((s.sd - 1.290_994_448_7).abs() < 1e-9, "{}", s.sd);
        assert_eq!(Spread::of(&[5.0]).unwrap().sd, 0.0);
        assert!(Spread::of(&[f64::NAN]).is_none());
    }

    #[test]
    fn every_numeric_headline_field_gets_its_spread_and_text_is_left_out() {
        let h = [
            json!({"claim": "c", "a": 1.0, "b": null, "run": {"t": 4.0, "u": null}}),
            json!({"claim": "c", "a": 3.0, "b": 2.0, "run": {"t": 6.0, "u": null}}),
        ];
        let spread = headline_spread(&h);
        assert_eq!(spread.len(), 3, "{spread:?}");
        assert_eq!((spread[2].0.as_str(), spread[2].1.mean), ("run.t", 5.0));
        assert_eq!(spread[0].0, "a");
        assert_eq!(spread[0].1.mean, 2.0);
        assert_eq!((spread[1].0.as_str(), spread[1].1.n), ("b", 1));
        let t = table("x", &[1, 2], &h);
        assert!(
            t.contains("| a | 2.0000 | 1.4142 | 1.0000 | 3.0000 | 2 |"),
            "{t}"
        );
        assert!(t.contains("claim: c"), "{t}");
    }
}
