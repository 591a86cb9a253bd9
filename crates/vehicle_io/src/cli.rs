//! What the two binaries share: loading the scenario by id, settings files, summaries.

use sim::Scenario;
use std::path::Path;

/// The scenario `id` of the JSON-lines file `file` (errors name the file, line and field).
///
/// # Errors
/// A message naming what is wrong.
pub fn load_scenario(file: &Path, id: &str) -> Result<Scenario, String> {
    let all = sim::load_jsonl(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let n = all.len();
    all.into_iter().find(|s| s.id == id).ok_or_else(|| {
        format!(
            "{}: no scenario with id {id:?} (the file holds {n} scenarios)",
            file.display()
        )
    })
}

/// Read a settings file.
///
/// # Errors
/// A message naming the file.
pub fn read_text(path: &Path) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Write `value` as pretty JSON to `path` (atomically: a temporary file, then a rename).
///
/// # Errors
/// A message naming the file.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), String> {
    let text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text + "\n")
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Check, before the run, that `write_json` will be able to write `path`: not a folder, and
/// its temporary file can be created beside it (it is removed again).
///
/// # Errors
/// A message naming `option` and the file.
pub fn check_writable(path: &Path, option: &str) -> Result<(), String> {
    if path.is_dir() {
        return Err(format!("{option} {}: is a folder", path.display()));
    }
    let tmp = path.with_extension("json.tmp");
    std::fs::File::create(&tmp)
        .and_then(|_| std::fs::remove_file(&tmp))
        .map_err(|e| format!("{option} {}: cannot write: {e}", path.display()))
}

/// Print `message` to stderr and exit with status 2 (bad input or settings).
pub fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(2)
}
