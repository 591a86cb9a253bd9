//! What the process tests share: paths, service prefixes, bounded waits, summaries and MCAP
//! counts.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus};
use std::time::{Duration, Instant};

pub const TRIALS: &str = "data/trials/half_scale.jsonl";
pub const HALF: &str = "configs/controller_half_scale.toml";

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A fresh folder for test `name` of suite `suite`.
pub fn out_dir(suite: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("picopit-{suite}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A service prefix no other test or run uses.
pub fn prefix(suite: &str, name: &str) -> String {
    format!("picopit-test-{suite}-{}-{name}", std::process::id())
}

/// Wait for `child` at most `limit`; a child still running then is killed and the test
/// fails naming `what`.
pub fn wait(child: &mut Child, limit: Duration, what: &str) -> ExitStatus {
    try_wait(child, limit).unwrap_or_else(|| panic!("{what} did not finish within {limit:?}"))
}

/// Wait for `child` at most `limit`; `None` (and the child killed) if it was still running.
pub fn try_wait(child: &mut Child, limit: Duration) -> Option<ExitStatus> {
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return Some(st);
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// Send `sig` to `child`.
pub fn signal(child: &Child, sig: libc::c_int) {
    // SAFETY: kill(2) on our own child's pid.
    let rc = unsafe { libc::kill(child.id() as i32, sig) };
    assert_eq!(rc, 0, "kill({}, {sig})", child.id());
}

/// Messages on `topic` in an MCAP file read as a stream, and whether the stream ended
/// cleanly (a footer) rather than at a truncation. Every JSON message must decode as JSON,
/// every protobuf one as the Foxglove type its schema names (`schema_check::decodes`).
pub fn count_messages(path: &Path, topic: &str) -> (usize, bool) {
    let Ok(bytes) = std::fs::read(path) else {
        return (0, false);
    };
    let mut n = 0;
    let mut clean = true;
    let Ok(stream) = mcap::MessageStream::new(&bytes) else {
        return (0, false);
    };
    for m in stream {
        match m {
            Ok(m) => {
                if m.channel.message_encoding == "json" {
                    let _: serde_json::Value =
                        serde_json::from_slice(&m.data).unwrap_or_else(|e| {
                            panic!(
                                "{}: message on {} is not JSON: {e}",
                                path.display(),
                                m.channel.topic
                            )
                        });
                } else {
                    let schema = m.channel.schema.as_ref().map_or("", |s| s.name.as_str());
                    assert!(
                        schema_check::decodes(schema, &m.data),
                        "{}: message on {} does not decode as {schema}",
                        path.display(),
                        m.channel.topic
                    );
                }
                if m.channel.topic == topic {
                    n += 1;
                }
            }
            Err(_) => {
                clean = false;
                break;
            }
        }
    }
    (n, clean)
}

/// Wait until the recording at `path` holds at least `n` messages on `topic`.
pub fn wait_for_messages(path: &Path, topic: &str, n: usize, limit: Duration) {
    let t0 = Instant::now();
    while count_messages(path, topic).0 < n {
        assert!(
            t0.elapsed() < limit,
            "{}: fewer than {n} messages on {topic} after {limit:?}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}
pub mod schema_check;
