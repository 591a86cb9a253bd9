//! The JSON-lines loader: one scenario per line, every error naming the line and the
//! field.

use super::{Scenario, ScenarioError};
use std::path::Path;

/// Read and validate a JSON-lines file of scenarios. Blank lines are skipped; ids must be
/// unique.
///
/// # Errors
/// [`ScenarioError::Io`] if the file cannot be read, [`ScenarioError::Empty`] if it holds
/// no scenario, otherwise the first bad line's error (line number and field).
pub fn load_jsonl(path: impl AsRef<Path>) -> Result<Vec<Scenario>, ScenarioError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    let out = parse_jsonl(&text)?;
    if out.is_empty() {
        return Err(ScenarioError::Empty {
            path: path.display().to_string(),
        });
    }
    Ok(out)
}

/// Parse JSON-lines text (as [`load_jsonl`], without the empty-file check).
///
/// # Errors
/// The first bad line's error.
pub fn parse_jsonl(text: &str) -> Result<Vec<Scenario>, ScenarioError> {
    let mut out = Vec::new();
    let mut seen = std::collections::HashMap::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        if raw.trim().is_empty() {
            continue;
        }
        let sc = Scenario::from_json_line(raw, line)?;
        if let Some(&first) = seen.get(&sc.id) {
            return Err(ScenarioError::DuplicateId {
                line,
                id: sc.id,
                first,
            });
        }
        seen.insert(sc.id.clone(), line);
        out.push(sc);
    }
    Ok(out)
}

impl Scenario {
    /// Parse and validate one JSON line; errors are reported on line `line`.
    ///
    /// # Errors
    /// [`ScenarioError::Syntax`] if the text is not JSON, [`ScenarioError::Field`] naming the
    /// field otherwise.
    pub fn from_json_line(text: &str, line: usize) -> Result<Self, ScenarioError> {
        // A key named twice (JSON readers keep the last silently) is refused by name.
        let mut keys = serde_json::Deserializer::from_str(text);
        if let Err(e) =
            serde_path_to_error::deserialize::<_, crate::unique_keys::UniqueKeys>(&mut keys)
        {
            let message = strip_position(&e.inner().to_string());
            if message.starts_with(crate::unique_keys::DUPLICATE) {
                return Err(ScenarioError::Field {
                    line,
                    field: field_of(&e.path().to_string(), &message),
                    message: "named twice in its object (a scenario says each thing once)"
                        .to_owned(),
                });
            }
        }
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| ScenarioError::Syntax {
                line,
                column: e.column(),
                message: strip_position(&e.to_string()),
            })?;
        let scenario: Self = serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            let message = e.inner().to_string();
            ScenarioError::Field {
                line,
                field: field_of(&path, &message),
                message,
            }
        })?;
        scenario.validate(line)?;
        Ok(scenario)
    }
}

/// serde_json appends " at line L column C"; the line is always 1 within one record.
fn strip_position(msg: &str) -> String {
    match msg.rfind(" at line ") {
        Some(i) => msg[..i].to_owned(),
        None => msg.to_owned(),
    }
}

/// The field a deserialisation error is about: the path, extended by the name in a
/// "missing field `x`" / "unknown field `x`" message (whose path is the parent object).
fn field_of(path: &str, message: &str) -> String {
    let parent = if path == "." { "" } else { path };
    for prefix in [
        "missing field `",
        "unknown field `",
        crate::unique_keys::DUPLICATE,
    ] {
        if let Some(rest) = message.strip_prefix(prefix) {
            if let Some(end) = rest.find('`') {
                let name = &rest[..end];
                // serde_path_to_error already puts an unknown field on the path.
                if parent == name || parent.ends_with(&format!(".{name}")) {
                    return parent.to_owned();
                }
                return if parent.is_empty() {
                    name.to_owned()
                } else {
                    format!("{parent}.{name}")
                };
            }
        }
    }
    if parent.is_empty() {
        "(record)".to_owned()
    } else {
        parent.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_of_extends_missing_and_unknown() {
        assert_eq!(field_of(".", "missing field `mu`"), "mu");
        assert_eq!(field_of("road", "missing field `lanes`"), "road.lanes");
        assert_eq!(
            field_of("target.z", "unknown field `z`, expected one of `s`"),
            "target.z"
        );
        assert_eq!(field_of("road.lanes", "invalid type: string"), "road.lanes");
    }
}
