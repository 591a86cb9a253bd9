//! MLP inference for picopit's learned target surrogates, the teacher PINN and PicoPINN.
//!
//! A model file (`docs/model-format.md`, format `picopit-mlp` version 3) is a safetensors
//! file holding the free parameters θ, the relation R as a gather (`ŵ = sign · θ[idx]` per
//! weight), the feature and output normalisation, the fixed linear base `B` of the
//! increments, and the architecture in its metadata.
//! [`SurrogateModel`] loads and validates it ([`ModelError`] names the key or tensor at
//! fault; bad input never panics), expands ŵ once, and implements
//! [`dynamics::TargetModel`]: the discrete step over the file's `dt` and its exact
//! Jacobians, allocation-free after load.
//!
//! ```no_run
//! use dynamics::{ContactInput, TargetInput, TargetJacobians, TargetModel, TargetState};
//! // On a road of adhesion 0.6 (default: the file's `mu_default`, 0.9 for the shipped files).
//! let mut m = pico_nn::SurrogateModel::from_path("models/full_size/picopinn.safetensors")?
//!     .with_mu(0.6)?;
//! let mut jac = TargetJacobians::default();
//! let x = TargetState::from([15.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
//! let next = m.step_jac(&x, &TargetInput::zeros(), &ContactInput::none(), &mut jac);
//! # Ok::<(), pico_nn::ModelError>(())
//! ```

mod error;
pub mod format;
mod mlp;
mod surrogate;
mod tanh;

pub use error::ModelError;
pub use format::{FEATURES, FORMAT, N_FEATURES, N_IN, N_OUT, OUTPUTS, VERSION};
pub use mlp::{JacobianMode, Kernel, Mlp};
pub use surrogate::{SurrogateModel, MAX_FILE_BYTES};
