//! Why a model file was refused. Every message names the file part at fault (the
//! metadata key or the tensor and, where it applies, the element).

use std::path::PathBuf;

/// A model file (or byte buffer) that cannot be used, see `docs/model-format.md`.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The file could not be read.
    #[error("cannot read model file {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The bytes are not a well-formed safetensors container (header length, JSON header,
    /// tensor offsets).
    #[error("not a valid safetensors file: {0}")]
    Container(String),
    /// A required key is absent from the header's `__metadata__`.
    #[error("metadata key `{key}` is missing")]
    MissingKey { key: &'static str },
    /// A metadata value this loader does not accept.
    #[error("metadata `{key}` = {value:?}: {reason}")]
    BadMetadata {
        key: &'static str,
        value: String,
        reason: String,
    },
    /// `format`/`version` name a file layout this loader does not read.
    #[error("metadata `{key}` = {value:?}: unsupported; this loader reads format `picopit-mlp` version 3 (regenerate older files with models/regenerate.sh)")]
    Unsupported { key: &'static str, value: String },
    /// A required tensor is absent.
    #[error("tensor `{name}` is missing")]
    MissingTensor { name: String },
    /// A tensor the format does not define (or a layer beyond the `layers` metadata).
    #[error("tensor `{name}` is not part of format picopit-mlp v3 with layers {layers}")]
    UnexpectedTensor { name: String, layers: String },
    /// A tensor of the wrong element type.
    #[error("tensor `{name}` has dtype {found}, expected {expected}")]
    Dtype {
        name: String,
        found: String,
        expected: &'static str,
    },
    /// A tensor whose shape disagrees with the format or with the `layers` metadata.
    #[error("tensor `{name}` has shape {found:?}, expected {expected}")]
    Shape {
        name: String,
        found: Vec<usize>,
        expected: String,
    },
    /// NaN or ±inf in `theta` or a statistics tensor.
    #[error("tensor `{name}`[{index}] = {value}: must be finite")]
    NonFinite {
        name: String,
        index: usize,
        value: f64,
    },
    /// A standard deviation ≤ 0.
    #[error("tensor `{name}`[{index}] = {value}: a standard deviation must be > 0")]
    NonPositiveStd {
        name: String,
        index: usize,
        value: f64,
    },
    /// An `idx` entry outside `0 .. len(theta)`.
    #[error("tensor `{name}`[{index}] = {value}: index out of bounds for `theta` of length {len}")]
    IndexOutOfBounds {
        name: String,
        index: usize,
        value: i64,
        len: usize,
    },
    /// The network does not run: a non-finite output (or input-Jacobian row) on its own
    /// normalisation statistics, although every number in the file is finite.
    #[error("the network gives {output} = {value} at {at}: a model must give finite outputs on its own normalisation statistics (are its weights absurd?)")]
    DoesNotRun {
        at: &'static str,
        output: &'static str,
        value: f64,
    },
    /// A road adhesion outside the model's trained range (or not finite).
    #[error("mu = {value}: must be finite and within the model's mu_range [{lo}, {hi}] (the road adhesion it was trained on)")]
    Mu { value: f64, lo: f64, hi: f64 },
    /// A `sign` entry other than −1, 0, +1.
    #[error("tensor `{name}`[{index}] = {value}: a sign must be -1, 0 or 1")]
    BadSign {
        name: String,
        index: usize,
        value: i64,
    },
}
