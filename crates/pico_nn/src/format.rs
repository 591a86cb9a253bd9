//! Reading and validating a `picopit-mlp` v3 file (`docs/model-format.md`).
//!
//! Validation happens here, once; what it returns is consistent by construction, so the
//! network code never checks again.

use crate::error::ModelError;
use safetensors::{Dtype, SafeTensors};
use std::collections::{BTreeMap, HashMap, HashSet};

/// The `format` metadata value.
pub const FORMAT: &str = "picopit-mlp";
/// The only `version` this loader reads. Version 2 (a fixed kinematic base, no `base`
/// tensor) and version 1 (no road μ) are refused: none is shipped any more, and
/// `models/regenerate.sh` writes version 3.
pub const VERSION: &str = "3";
/// The feature names, in the network's input order: the [`N_IN`] per-step features, then
/// the road adhesion μ (a property of the model instance, [`crate::SurrogateModel::set_mu`]).
pub const FEATURES: [&str; N_FEATURES] = [
    "vx", "vy", "r", "p", "phi", "delta", "T_b", "f_bx", "f_by", "M_z", "mu",
];
/// The output names, in the network's output order.
pub const OUTPUTS: [&str; 8] = ["dvx", "dvy", "dr", "dp", "dphi", "dpsi", "dx_b", "dy_b"];
/// The `kind` values a file may declare.
pub const KINDS: [&str; 2] = ["pinn", "picopinn"];
/// Number of network inputs (`layers` starts with it).
pub const N_FEATURES: usize = 11;
/// Number of per-step features (state, input and contact: every feature but μ).
pub const N_IN: usize = 10;
/// Index of μ among the features.
pub const MU: usize = 10;
/// Number of outputs.
pub const N_OUT: usize = 8;

/// Metadata keys that must be present.
const REQUIRED: [&str; 11] = [
    "format",
    "version",
    "kind",
    "activation",
    "layers",
    "features",
    "outputs",
    "dt",
    "param_set",
    "mu_range",
    "mu_default",
];

/// One dense layer, expanded: `weight` row-major `[out][in]`.
#[derive(Debug, Clone)]
pub(crate) struct DenseLayer {
    pub weight: Vec<f64>,
    pub bias: Vec<f64>,
}

/// A validated file.
#[derive(Debug, Clone)]
pub(crate) struct Parsed {
    pub metadata: BTreeMap<String, String>,
    pub kind: String,
    pub dt: f64,
    pub widths: Vec<usize>,
    pub n_free: usize,
    pub layers: Vec<DenseLayer>,
    pub mu_range: (f64, f64),
    pub mu_default: f64,
    pub in_mean: [f64; N_FEATURES],
    pub in_std: [f64; N_FEATURES],
    pub out_mean: [f64; N_OUT],
    pub out_std: [f64; N_OUT],
    /// The fixed linear base `o += B z` (rows: outputs, columns: all features).
    pub base: [[f64; N_FEATURES]; N_OUT],
}

fn container(e: impl std::fmt::Display) -> ModelError {
    ModelError::Container(e.to_string())
}

/// Reject tensor offsets past the end of the buffer before the safetensors crate adds
/// them up (a forged header could otherwise overflow its offset arithmetic).
fn prescreen(bytes: &[u8]) -> Result<(), ModelError> {
    let Some(len) = bytes.get(..8) else {
        return Err(container(format!(
            "{} bytes: too short for the 8-byte header length",
            bytes.len()
        )));
    };
    let n = u64::from_le_bytes(len.try_into().unwrap_or([0xff; 8]));
    let header = usize::try_from(n)
        .ok()
        .and_then(|n| n.checked_add(8))
        .and_then(|end| bytes.get(8..end))
        .ok_or_else(|| {
            container(format!(
                "header length {n} exceeds the {} bytes of the file",
                bytes.len()
            ))
        })?;
    let v: serde_json::Value = serde_json::from_slice(header)
        .map_err(|e| container(format!("header is not valid JSON: {e}")))?;
    let Some(obj) = v.as_object() else {
        return Err(container("header is not a JSON object"));
    };
    let data_len = (bytes.len() - 8 - header.len()) as u64;
    for (name, t) in obj {
        if name == "__metadata__" {
            continue;
        }
        let offsets = t.get("data_offsets").and_then(|o| o.as_array());
        for o in offsets.into_iter().flatten() {
            if o.as_u64().is_some_and(|o| o > data_len) {
                return Err(container(format!(
                    "tensor `{name}`: data_offsets {o} beyond the {data_len} data bytes"
                )));
            }
        }
    }
    Ok(())
}

fn dtype_name(d: Dtype) -> String {
    format!("{d:?}")
}

/// Look a tensor up and check its dtype and shape.
fn tensor<'a>(
    st: &SafeTensors<'a>,
    name: &str,
    dtype: Dtype,
    expected: &'static str,
    shape: &[usize],
) -> Result<&'a [u8], ModelError> {
    let t = st.tensor(name).map_err(|_| ModelError::MissingTensor {
        name: name.to_owned(),
    })?;
    if t.dtype() != dtype {
        return Err(ModelError::Dtype {
            name: name.to_owned(),
            found: dtype_name(t.dtype()),
            expected,
        });
    }
    if t.shape() != shape {
        return Err(ModelError::Shape {
            name: name.to_owned(),
            found: t.shape().to_vec(),
            expected: format!("{shape:?}"),
        });
    }
    Ok(t.data())
}

/// An F64 tensor of `shape`, every element finite.
fn f64s(st: &SafeTensors<'_>, name: &str, shape: &[usize]) -> Result<Vec<f64>, ModelError> {
    let data = tensor(st, name, Dtype::F64, "F64", shape)?;
    data.chunks_exact(8)
        .enumerate()
        .map(|(index, c)| {
            let mut b = [0u8; 8];
            b.copy_from_slice(c);
            let value = f64::from_le_bytes(b);
            if value.is_finite() {
                Ok(value)
            } else {
                Err(ModelError::NonFinite {
                    name: name.to_owned(),
                    index,
                    value,
                })
            }
        })
        .collect()
}

/// An F64 statistics vector of length `N`; `positive` requires every entry > 0.
fn stats<const N: usize>(
    st: &SafeTensors<'_>,
    name: &str,
    positive: bool,
) -> Result<[f64; N], ModelError> {
    let v = f64s(st, name, &[N])?;
    let mut out = [0.0; N];
    for (index, (&value, o)) in v.iter().zip(out.iter_mut()).enumerate() {
        if positive && value <= 0.0 {
            return Err(ModelError::NonPositiveStd {
                name: name.to_owned(),
                index,
                value,
            });
        }
        *o = value;
    }
    Ok(out)
}

/// Expand `ŵ = sign · θ[idx]` for the tensor pair `{prefix}.idx` / `{prefix}.sign`.
fn gather(
    st: &SafeTensors<'_>,
    prefix: &str,
    shape: &[usize],
    theta: &[f64],
) -> Result<Vec<f64>, ModelError> {
    let idx_name = format!("{prefix}.idx");
    let sign_name = format!("{prefix}.sign");
    let idx = tensor(st, &idx_name, Dtype::I32, "I32", shape)?;
    let sign = tensor(st, &sign_name, Dtype::I8, "I8", shape)?;
    let mut out = Vec::with_capacity(sign.len());
    for (index, (i, &s)) in idx.chunks_exact(4).zip(sign).enumerate() {
        let i = i32::from_le_bytes([i[0], i[1], i[2], i[3]]);
        let value = usize::try_from(i).ok().and_then(|i| theta.get(i)).ok_or(
            ModelError::IndexOutOfBounds {
                name: idx_name.clone(),
                index,
                value: i64::from(i),
                len: theta.len(),
            },
        )?;
        let s = s as i8;
        let w = match s {
            -1 => -value,
            0 => 0.0,
            1 => *value,
            _ => {
                return Err(ModelError::BadSign {
                    name: sign_name,
                    index,
                    value: i64::from(s),
                })
            }
        };
        out.push(w);
    }
    Ok(out)
}

fn meta<'m>(m: &'m HashMap<String, String>, key: &'static str) -> &'m str {
    // Presence is checked up front for every REQUIRED key.
    m.get(key).map_or("", String::as_str)
}

fn bad(key: &'static str, value: &str, reason: impl Into<String>) -> ModelError {
    ModelError::BadMetadata {
        key,
        value: value.to_owned(),
        reason: reason.into(),
    }
}

/// A comma-separated list that must equal `expected` item for item.
fn check_names(
    m: &HashMap<String, String>,
    key: &'static str,
    expected: &[&str],
) -> Result<(), ModelError> {
    let value = meta(m, key);
    let found: Vec<&str> = value.split(',').map(str::trim).collect();
    if found != expected {
        return Err(bad(key, value, format!("must be {}", expected.join(","))));
    }
    Ok(())
}

/// `lo,hi` with `0 < lo ≤ hi`, both finite.
fn parse_mu_range(value: &str) -> Result<(f64, f64), ModelError> {
    let parts: Vec<&str> = value.split(',').map(str::trim).collect();
    let [lo, hi] = parts[..] else {
        return Err(bad("mu_range", value, "must be two numbers lo,hi"));
    };
    let num = |s: &str| {
        s.parse::<f64>()
            .map_err(|e| bad("mu_range", value, format!("not a number ({e})")))
    };
    let (lo, hi) = (num(lo)?, num(hi)?);
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
        return Err(bad("mu_range", value, "must be finite with 0 < lo <= hi"));
    }
    Ok((lo, hi))
}

fn parse_widths(value: &str) -> Result<Vec<usize>, ModelError> {
    let widths = value
        .split(',')
        .map(|w| w.trim().parse::<usize>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| bad("layers", value, format!("not a list of widths ({e})")))?;
    if widths.len() < 2 {
        return Err(bad(
            "layers",
            value,
            "needs at least the input and output widths",
        ));
    }
    if widths[0] != N_FEATURES || widths[widths.len() - 1] != N_OUT {
        return Err(bad(
            "layers",
            value,
            format!("must start with {N_FEATURES} (features) and end with {N_OUT} (outputs)"),
        ));
    }
    if widths.contains(&0) {
        return Err(bad("layers", value, "a width of 0"));
    }
    Ok(widths)
}

/// Parse and validate a whole file.
pub(crate) fn parse(bytes: &[u8]) -> Result<Parsed, ModelError> {
    prescreen(bytes)?;
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(container)?;
    let st = SafeTensors::deserialize(bytes).map_err(container)?;
    let empty = HashMap::new();
    let m = header.metadata().as_ref().unwrap_or(&empty);

    // Format and version first: a file of another version may differ in anything else.
    for key in ["format", "version"] {
        if !m.contains_key(key) {
            return Err(ModelError::MissingKey { key });
        }
    }
    if meta(m, "format") != FORMAT {
        return Err(ModelError::Unsupported {
            key: "format",
            value: meta(m, "format").to_owned(),
        });
    }
    if meta(m, "version").trim() != VERSION {
        return Err(ModelError::Unsupported {
            key: "version",
            value: meta(m, "version").to_owned(),
        });
    }
    if let Some(key) = REQUIRED.into_iter().find(|k| !m.contains_key(*k)) {
        return Err(ModelError::MissingKey { key });
    }
    let kind = meta(m, "kind").trim();
    if !KINDS.contains(&kind) {
        return Err(bad("kind", kind, "must be pinn or picopinn"));
    }
    let activation = meta(m, "activation");
    if activation.trim() != "tanh" {
        return Err(bad("activation", activation, "version 3 knows only tanh"));
    }
    check_names(m, "features", &FEATURES)?;
    check_names(m, "outputs", &OUTPUTS)?;
    let dt_s = meta(m, "dt");
    let dt: f64 = dt_s
        .trim()
        .parse()
        .map_err(|e| bad("dt", dt_s, format!("not a number ({e})")))?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(bad("dt", dt_s, "must be finite and > 0"));
    }
    if meta(m, "param_set").trim().is_empty() {
        return Err(bad("param_set", "", "must name a parameter set"));
    }
    let mu_range = parse_mu_range(meta(m, "mu_range"))?;
    let mu_s = meta(m, "mu_default");
    let mu_default: f64 = mu_s
        .trim()
        .parse()
        .map_err(|e| bad("mu_default", mu_s, format!("not a number ({e})")))?;
    if !(mu_range.0..=mu_range.1).contains(&mu_default) {
        return Err(bad(
            "mu_default",
            mu_s,
            format!("must lie in mu_range [{}, {}]", mu_range.0, mu_range.1),
        ));
    }
    let layers_s = meta(m, "layers");
    let widths = parse_widths(layers_s)?;
    let n_layers = widths.len() - 1;

    // No tensor beyond what the format defines for these widths.
    let mut known: HashSet<String> = ["theta", "in_mean", "in_std", "out_mean", "out_std", "base"]
        .into_iter()
        .map(str::to_owned)
        .collect();
    for l in 1..=n_layers {
        for part in ["weight", "bias"] {
            for field in ["idx", "sign"] {
                known.insert(format!("layer{l}.{part}.{field}"));
            }
        }
    }
    let mut names = st.names();
    names.sort_unstable();
    if let Some(name) = names.into_iter().find(|n| !known.contains(*n)) {
        return Err(ModelError::UnexpectedTensor {
            name: name.to_owned(),
            layers: layers_s.to_owned(),
        });
    }

    let theta_shape = st
        .tensor("theta")
        .map_err(|_| ModelError::MissingTensor {
            name: "theta".into(),
        })?
        .shape()
        .to_vec();
    if theta_shape.len() != 1 {
        return Err(ModelError::Shape {
            name: "theta".into(),
            found: theta_shape,
            expected: "[n_free]".into(),
        });
    }
    let theta = f64s(&st, "theta", &theta_shape)?;
    let in_mean = stats::<N_FEATURES>(&st, "in_mean", false)?;
    let in_std = stats::<N_FEATURES>(&st, "in_std", true)?;
    let out_mean = stats::<N_OUT>(&st, "out_mean", false)?;
    let out_std = stats::<N_OUT>(&st, "out_std", true)?;
    let b = f64s(&st, "base", &[N_OUT, N_FEATURES])?;
    let base: [[f64; N_FEATURES]; N_OUT] =
        std::array::from_fn(|k| std::array::from_fn(|j| b[k * N_FEATURES + j]));

    let mut layers = Vec::with_capacity(n_layers);
    for l in 1..=n_layers {
        let (n_in, n_out) = (widths[l - 1], widths[l]);
        let weight = gather(&st, &format!("layer{l}.weight"), &[n_out, n_in], &theta)?;
        let bias = gather(&st, &format!("layer{l}.bias"), &[n_out], &theta)?;
        layers.push(DenseLayer { weight, bias });
    }

    Ok(Parsed {
        metadata: m.iter().map(|(k, v)| (k.clone(), v.clone())).collect(),
        kind: kind.to_owned(),
        dt,
        widths,
        n_free: theta.len(),
        layers,
        mu_range,
        mu_default,
        in_mean,
        in_std,
        out_mean,
        out_std,
        base,
    })
}
