//! Deserializers shared by the configuration types, for values whose natural serde form accepts too much
//! or too little: a pair given as three numbers (the third was silently dropped), a seed the design loop
//! prints but TOML cannot write as a number (TOML integers are signed 64-bit).

use serde::de::{Deserialize, Deserializer, Error};

/// `[x, y]`: exactly two numbers (serde's own `[f64; 2]` reads the first two of a longer TOML array).
pub fn exact_pair<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    let n = v.len();
    <[f64; 2]>::try_from(v).map_err(|_| D::Error::invalid_length(n, &"two numbers, [x, y]"))
}

/// A 64-bit seed as a number or as text: the design loop's derived seeds (printed, and recorded in
/// `metrics.json`) reach 2⁶⁴ − 1, beyond TOML's largest integer 2⁶³ − 1, so `seed = "11400714819323198486"`
/// (or `--set facets.seed=11400714819323198486`) must give the arrangement back.
pub fn seed<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum Seed {
        Number(u64),
        Text(String),
    }
    match Seed::deserialize(d)? {
        Seed::Number(n) => Ok(n),
        Seed::Text(t) => t.trim().parse::<u64>().map_err(|_| {
            D::Error::custom(format!(
                "a seed is a whole number from 0 to {} (as text when above {}), got {t:?}",
                u64::MAX,
                i64::MAX
            ))
        }),
    }
}

#[cfg(test)]
mod tests {
    #[derive(serde::Deserialize, Debug)]
    struct T {
        #[serde(deserialize_with = "super::exact_pair", default)]
        pair: [f64; 2],
        #[serde(deserialize_with = "super::seed", default)]
        seed: u64,
    }

    #[test]
    fn a_pair_is_two_numbers_and_a_seed_may_be_text() {
        let t: T = toml::from_str("pair = [1.5, 2]\nseed = \"18446744073709551615\"").unwrap();
        assert_eq!((t.pair, t.seed), ([1.5, 2.0], u64::MAX));
        let t: T = toml::from_str("seed = 7").unwrap();
        assert_eq!(t.seed, 7);
        for bad in [
            "pair = [1, 2, 3]",
            "pair = [1]",
            "seed = \"-1\"",
            "seed = \"18446744073709551616\"",
            "seed = -3",
        ] {
            let e = toml::from_str::<T>(bad).unwrap_err().to_string();
            assert!(
                e.contains("two numbers") || e.contains("seed") || e.contains("u64"),
                "{bad}: {e}"
            );
        }
    }
}
