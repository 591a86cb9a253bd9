//! The loader refuses every malformed file with an error naming the key or tensor, and
//! never panics: hand-made defects of each kind, then seeded random truncation and
//! corruption.

mod common;

use common::{clustered, random_teacher, Raw, Spec};
use dynamics::geometry::Vec2;
use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
use pico_nn::{ModelError, SurrogateModel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use safetensors::Dtype;

const WIDTHS: [usize; 4] = [11, 12, 12, 8];

fn base() -> Spec {
    random_teacher(&WIDTHS, &mut ChaCha8Rng::seed_from_u64(21))
}

/// Load `spec`, expect an error whose message contains every one of `needles`.
fn refuse(spec: &Spec, needles: &[&str]) -> ModelError {
    refuse_bytes(&spec.to_bytes(), needles)
}

fn refuse_bytes(bytes: &[u8], needles: &[&str]) -> ModelError {
    match SurrogateModel::from_bytes(bytes) {
        Ok(_) => panic!("accepted a bad file (expected an error naming {needles:?})"),
        Err(e) => {
            let msg = e.to_string();
            for n in needles {
                assert!(msg.contains(n), "error {msg:?} does not name {n:?}");
            }
            e
        }
    }
}

/// Exercise a model that loaded: step and step_jac must not panic.
fn exercise(m: &mut SurrogateModel) {
    let x = TargetState::from([12.0, 0.3, 0.5, 0.1, 0.02, 0.01, 3.0, -1.0]);
    let c = ContactInput {
        fc: Vec2::new(5000.0, 800.0),
        gamma: 1.8,
        point_in_body: Vec2::new(-2.0, -0.8),
    };
    let mut jac = TargetJacobians::default();
    let _ = m.step(&x, &TargetInput::new(0.05, 300.0), &c);
    let _ = m.step_jac(&x, &TargetInput::new(0.05, 300.0), &c, &mut jac);
}

#[test]
fn the_base_file_loads() {
    let mut m = SurrogateModel::from_bytes(&base().to_bytes()).unwrap();
    assert_eq!(m.layers(), WIDTHS);
    assert_eq!(m.name(), "pinn");
    assert_eq!(m.metadata()["seed"], "7");
    exercise(&mut m);
}

#[test]
fn from_path_reads_files_and_names_missing_ones() {
    let dir = std::env::temp_dir().join(format!("pico_nn_loader_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.safetensors");
    std::fs::write(&path, base().to_bytes()).unwrap();
    assert!(SurrogateModel::from_path(&path).is_ok());
    let missing = dir.join("nope.safetensors");
    let e = SurrogateModel::from_path(&missing).unwrap_err();
    assert!(matches!(e, ModelError::Io { .. }));
    assert!(e.to_string().contains("nope.safetensors"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn missing_metadata_keys_are_named() {
    for key in [
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
    ] {
        let mut s = base();
        s.metadata.remove(key);
        let e = refuse(&s, &[key]);
        assert!(matches!(e, ModelError::MissingKey { .. }), "{key}: {e:?}");
    }
    // No metadata at all.
    let mut s = base();
    s.metadata.clear();
    refuse(&s, &["format"]);
}

#[test]
fn unknown_format_or_version_is_refused() {
    for (key, value) in [
        ("version", "1"),
        ("version", "2"),
        ("version", "4"),
        ("version", "0"),
        ("version", ""),
        ("format", "onnx"),
    ] {
        let mut s = base();
        s.metadata.insert(key.into(), value.into());
        let e = refuse(&s, &[key, "unsupported"]);
        assert!(matches!(e, ModelError::Unsupported { .. }));
    }
}

#[test]
fn bad_metadata_values_are_named() {
    let cases: &[(&str, &str)] = &[
        ("kind", "teacher"),
        ("activation", "relu"),
        ("features", "vx,vy,r,p,phi,delta,T_b,f_bx,f_by,M_z"),
        ("features", "vy,vx,r,p,phi,delta,T_b,f_bx,f_by,M_z,mu"),
        ("features", "mu,vx,vy,r,p,phi,delta,T_b,f_bx,f_by,M_z"),
        ("outputs", "dvx,dvy,dr,dp,dphi,dpsi,dx_b"),
        ("dt", "0"),
        ("dt", "-0.05"),
        ("dt", "NaN"),
        ("dt", "inf"),
        ("dt", "fast"),
        ("layers", "11,12,12"),
        ("layers", "10,12,12,8"),
        ("layers", "11,12,x,8"),
        ("layers", "11,0,12,8"),
        ("layers", "11"),
        ("layers", ""),
        ("param_set", " "),
        ("mu_range", "0.15"),
        ("mu_range", "0.15,1.0,2.0"),
        ("mu_range", "0,1.0"),
        ("mu_range", "1.0,0.15"),
        ("mu_range", "0.15,inf"),
        ("mu_range", "low,high"),
        ("mu_default", "1.2"),
        ("mu_default", "0.1"),
        ("mu_default", "NaN"),
        ("mu_default", "dry"),
    ];
    for (key, value) in cases {
        let mut s = base();
        s.metadata.insert((*key).into(), (*value).into());
        let e = refuse(&s, &[key]);
        assert!(
            matches!(e, ModelError::BadMetadata { .. }),
            "{key}={value}: {e:?}"
        );
    }
}

#[test]
fn layers_inconsistent_with_tensors_are_refused() {
    // Metadata says wider than the tensors are.
    let mut s = base();
    s.metadata.insert("layers".into(), "11,16,12,8".into());
    refuse(&s, &["layer1.weight.idx", "shape"]);
    // Metadata says fewer layers than the file holds.
    let mut s = base();
    s.metadata.insert("layers".into(), "11,12,8".into());
    let e = refuse(&s, &["layer"]);
    assert!(
        matches!(
            e,
            ModelError::Shape { .. } | ModelError::UnexpectedTensor { .. }
        ),
        "{e:?}"
    );
    // An extra, unknown tensor.
    let mut s = base();
    s.tensors.push(Raw::f64s("layer4.weight.idx", &[1], &[0.0]));
    refuse(&s, &["layer4.weight.idx"]);
}

#[test]
fn missing_tensors_are_named() {
    let names: Vec<String> = base().tensors.iter().map(|t| t.name.clone()).collect();
    assert_eq!(names.len(), 3 * 4 + 6);
    for name in names {
        let e = refuse(&base().without_tensor(&name), &[&name]);
        assert!(
            matches!(e, ModelError::MissingTensor { .. }),
            "{name}: {e:?}"
        );
    }
}

#[test]
fn wrong_dtypes_are_named() {
    let cases = [
        ("theta", Dtype::F32, 4),
        ("in_std", Dtype::F32, 4),
        ("out_mean", Dtype::I64, 8),
        ("base", Dtype::F32, 4),
        ("layer2.weight.idx", Dtype::I64, 8),
        ("layer2.weight.idx", Dtype::U32, 4),
        ("layer1.bias.sign", Dtype::U8, 1),
        ("layer3.bias.sign", Dtype::I32, 4),
    ];
    for (name, dtype, size) in cases {
        let mut s = base();
        let t = s.tensor_mut(name);
        let n: usize = t.shape.iter().product();
        t.dtype = dtype;
        t.data = vec![0; n * size];
        let e = refuse(&s, &[name, "dtype"]);
        assert!(matches!(e, ModelError::Dtype { .. }), "{name}: {e:?}");
    }
}

#[test]
fn wrong_shapes_are_named() {
    let mut rng = ChaCha8Rng::seed_from_u64(22);
    for name in [
        "in_mean",
        "in_std",
        "out_mean",
        "out_std",
        "base",
        "layer1.weight.idx",
        "layer2.weight.sign",
        "layer3.bias.idx",
        "layer1.bias.sign",
    ] {
        for reshape in [0, 1, 2] {
            let mut s = base();
            let t = s.tensor_mut(name);
            let n: usize = t.shape.iter().product();
            let elem = t.data.len() / n;
            // One element more, one less, or the same count in another rank.
            let new_shape = match reshape {
                0 => vec![n + 1],
                1 => vec![n - 1],
                _ if t.shape.len() == 2 => vec![n],
                _ => vec![1, n],
            };
            let count: usize = new_shape.iter().product();
            t.data = (0..count * elem)
                .map(|_| if elem == 8 { 0 } else { rng.random_range(0..2) })
                .collect();
            if elem == 8 {
                // Valid values for the statistics so that only the shape is wrong.
                t.data = (0..count).flat_map(|_| 1.0f64.to_le_bytes()).collect();
            }
            t.shape = new_shape;
            let e = refuse(&s, &[name, "shape"]);
            assert!(matches!(e, ModelError::Shape { .. }), "{name}: {e:?}");
        }
    }
    // theta must be one-dimensional.
    let mut s = base();
    let t = s.tensor_mut("theta");
    let n = t.shape[0];
    t.shape = vec![1, n];
    refuse(&s, &["theta", "shape"]);
}

#[test]
fn non_finite_theta_and_statistics_are_named() {
    for name in ["theta", "in_mean", "in_std", "out_mean", "out_std", "base"] {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut s = base();
            let t = s.tensor_mut(name);
            let n = t.data.len() / 8;
            let i = n / 2;
            t.data[i * 8..i * 8 + 8].copy_from_slice(&bad.to_le_bytes());
            let e = refuse(&s, &[name, &format!("[{i}]"), "finite"]);
            assert!(matches!(e, ModelError::NonFinite { .. }), "{name}: {e:?}");
        }
        // Entirely NaN.
        let mut s = base();
        let t = s.tensor_mut(name);
        let n = t.data.len() / 8;
        t.data = (0..n).flat_map(|_| f64::NAN.to_le_bytes()).collect();
        refuse(&s, &[name]);
    }
}

#[test]
fn non_positive_std_is_named() {
    for name in ["in_std", "out_std"] {
        for bad in [0.0, -0.0, -1.0] {
            let mut s = base();
            s.tensor_mut(name).data[8..16].copy_from_slice(&f64::to_le_bytes(bad));
            let e = refuse(&s, &[name, "[1]"]);
            assert!(
                matches!(e, ModelError::NonPositiveStd { .. }),
                "{name}: {e:?}"
            );
        }
    }
}

#[test]
fn out_of_range_indices_and_signs_are_named() {
    let (spec, _) = clustered(&WIDTHS, 9, &mut ChaCha8Rng::seed_from_u64(23));
    assert!(SurrogateModel::from_bytes(&spec.to_bytes()).is_ok());
    for name in ["layer1.weight.idx", "layer3.bias.idx"] {
        for bad in [9i32, 10_000, -1, i32::MIN, i32::MAX] {
            let mut s = spec.clone();
            s.tensor_mut(name).data[4..8].copy_from_slice(&bad.to_le_bytes());
            let e = refuse(&s, &[name, "[1]", &bad.to_string(), "out of bounds"]);
            assert!(
                matches!(e, ModelError::IndexOutOfBounds { .. }),
                "{name}: {e:?}"
            );
        }
    }
    // A pruned weight (sign 0) must still index inside theta.
    let mut s = spec.clone();
    s.tensor_mut("layer2.weight.sign").data[0] = 0;
    s.tensor_mut("layer2.weight.idx").data[0..4].copy_from_slice(&99i32.to_le_bytes());
    refuse(&s, &["layer2.weight.idx", "[0]"]);
    for bad in [2i8, -2, i8::MIN, i8::MAX] {
        let mut s = spec.clone();
        s.tensor_mut("layer2.bias.sign").data[3] = bad as u8;
        let e = refuse(&s, &["layer2.bias.sign", "[3]", &bad.to_string()]);
        assert!(matches!(e, ModelError::BadSign { .. }), "{e:?}");
    }
}

#[test]
fn forged_headers_are_refused() {
    let good = base().to_bytes();
    // Header length beyond the file, and absurd.
    for n in [good.len() as u64, u64::MAX, 1 << 40] {
        let mut b = good.clone();
        b[..8].copy_from_slice(&n.to_le_bytes());
        refuse_bytes(&b, &["safetensors"]);
    }
    // Offsets past the end, huge shapes, offsets near usize::MAX.
    let headers = [
        r#"{"theta":{"dtype":"F64","shape":[2],"data_offsets":[0,18446744073709551615]}}"#,
        r#"{"theta":{"dtype":"F64","shape":[4611686018427387904],"data_offsets":[0,16]}}"#,
        r#"{"a":{"dtype":"U8","shape":[9223372036854775807],"data_offsets":[0,9223372036854775807]},"b":{"dtype":"U8","shape":[9223372036854775807],"data_offsets":[9223372036854775807,18446744073709551614]}}"#,
        r#"{"theta":{"dtype":"F64","shape":[2],"data_offsets":[8,24]}}"#,
        r#"{"__metadata__":{"format":1}}"#,
        r#"[1,2,3]"#,
        r#"{"theta":{"dtype":"F99","shape":[2],"data_offsets":[0,16]}}"#,
        "{\"\u{0}\":",
    ];
    // Eight tensors of 2^61 − 1 bytes: their offsets end at 2^64 − 8, where adding the
    // header length overflows.
    let size = (1u64 << 61) - 1;
    let overflow = (0..8u64)
        .map(|i| {
            format!(
                r#""t{i}":{{"dtype":"U8","shape":[{size}],"data_offsets":[{},{}]}}"#,
                i * size,
                (i + 1) * size
            )
        })
        .collect::<Vec<_>>()
        .join(",");
    let overflow = format!("{{{overflow}}}");
    for h in headers.iter().copied().chain([overflow.as_str()]) {
        let mut b = (h.len() as u64).to_le_bytes().to_vec();
        b.extend_from_slice(h.as_bytes());
        b.extend_from_slice(&[0u8; 16]);
        refuse_bytes(&b, &[]);
    }
    refuse_bytes(&[], &["too short"]);
    refuse_bytes(&[1, 2, 3], &["too short"]);
}

/// Every truncation of a valid file is refused.
#[test]
fn every_truncation_is_refused() {
    let good = base().to_bytes();
    for len in 0..good.len() {
        assert!(
            SurrogateModel::from_bytes(&good[..len]).is_err(),
            "accepted {len} of {} bytes",
            good.len()
        );
    }
    // Trailing garbage too.
    let mut long = good.clone();
    long.push(0);
    assert!(SurrogateModel::from_bytes(&long).is_err());
}

/// Random byte corruption anywhere (header and data): an error or a model that steps,
/// never a panic. A corrupted header must mostly be refused.
#[test]
fn random_corruption_never_panics() {
    let mut rng = ChaCha8Rng::seed_from_u64(24);
    let files = [
        base().to_bytes(),
        clustered(&WIDTHS, 9, &mut rng).0.to_bytes(),
    ];
    let (mut refused, mut trials) = (0, 0);
    for good in &files {
        let header_len =
            usize::try_from(u64::from_le_bytes(good[..8].try_into().unwrap())).unwrap() + 8;
        for _ in 0..3000 {
            let mut b = good.clone();
            let flips = rng.random_range(1..=4);
            for _ in 0..flips {
                let at = if rng.random_bool(0.5) {
                    rng.random_range(0..header_len)
                } else {
                    rng.random_range(0..b.len())
                };
                b[at] = rng.random();
            }
            trials += 1;
            match SurrogateModel::from_bytes(&b) {
                Ok(mut m) => exercise(&mut m),
                Err(e) => {
                    refused += 1;
                    assert!(!e.to_string().is_empty());
                }
            }
        }
    }
    // Half the flips land in the header, where nearly any change breaks the JSON or a
    // name; so at least a third of the files must be refused.
    assert!(
        refused * 3 >= trials,
        "only {refused} of {trials} corrupted files refused"
    );
}

#[test]
fn a_model_whose_network_overflows_is_refused_by_running_it() {
    // Finite everywhere, so every other check passes; the forward pass overflows.
    for (name, value) in [("theta", 1e308_f64), ("out_std", 1e308), ("base", 1e308)] {
        let mut s = base();
        let t = s.tensor_mut(name);
        let n = t.data.len() / 8;
        t.data = (0..n).flat_map(|_| value.to_le_bytes()).collect();
        let e = refuse(&s, &["finite outputs", "in_mean"]);
        assert!(matches!(e, ModelError::DoesNotRun { .. }), "{name}: {e:?}");
    }
}
