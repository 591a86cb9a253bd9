//! A JSON walk that refuses an object naming a key twice. serde_json (like most JSON
//! readers) keeps the last value of a repeated key silently, so `{"mu": 0.9, …, "mu": 0.2}`
//! would run on μ = 0.2 with no word; a scenario must say each thing once.

use serde::de::{self, Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use std::collections::BTreeSet;
use std::fmt;

/// The message prefix of the error (the key follows in backquotes).
pub(crate) const DUPLICATE: &str = "duplicate field `";

/// Deserializes any JSON value, failing on the first object with a repeated key.
pub(crate) struct UniqueKeys;

impl<'de> Deserialize<'de> for UniqueKeys {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(Walk)
    }
}

struct Walk;

impl<'de> Visitor<'de> for Walk {
    type Value = UniqueKeys;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E>(self, _: bool) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_i64<E>(self, _: i64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_u64<E>(self, _: u64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_f64<E>(self, _: f64) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_str<E>(self, _: &str) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_unit<E>(self) -> Result<UniqueKeys, E> {
        Ok(UniqueKeys)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<UniqueKeys, A::Error> {
        while seq.next_element::<UniqueKeys>()?.is_some() {}
        Ok(UniqueKeys)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<UniqueKeys, A::Error> {
        let mut seen = BTreeSet::new();
        while let Some(key) = map.next_key::<String>()? {
            if seen.contains(&key) {
                return Err(de::Error::custom(format!("{DUPLICATE}{key}`")));
            }
            map.next_value::<UniqueKeys>()?;
            seen.insert(key);
        }
        Ok(UniqueKeys)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> Result<(), String> {
        let mut d = serde_json::Deserializer::from_str(text);
        serde_path_to_error::deserialize::<_, UniqueKeys>(&mut d)
            .map(|_| ())
            .map_err(|e| format!("{} @ {}", e.inner(), e.path()))
    }

    #[test]
    fn a_repeated_key_is_found_at_any_depth_and_named_with_its_parent() {
        assert!(check(r#"{"a": 1, "b": [1, {"c": null}], "d": {"a": 2}}"#).is_ok());
        let e = check(r#"{"mu": 0.9, "x": true, "mu": 0.2}"#).unwrap_err();
        assert!(
            e.starts_with("duplicate field `mu`") && e.ends_with("@ ."),
            "{e}"
        );
        let e = check(r#"{"road": {"lanes": 3, "lanes": 2}}"#).unwrap_err();
        assert!(e.contains("`lanes`") && e.ends_with("@ road"), "{e}");
        let e = check(r#"{"obstacles": [{}, {"body": {"x": 1, "x": 2}}]}"#).unwrap_err();
        assert!(e.ends_with("@ obstacles[1].body"), "{e}");
    }
}
