//! Vehicle I/O: the PIT controller and the vehicle side as two processes over iceoryx2
//! zero-copy IPC, with MCAP recordings, a watchdog on both sides and safe fallbacks.
//!
//! - [`msg`]: the `#[repr(C)]`, `Copy`, zero-copy payloads (states, commands, status,
//!   heartbeats);
//! - [`ports`]: the service names under a prefix and each process's ports (loan → write →
//!   send; event-driven wake-up);
//! - [`config`]: both processes' TOML settings, validated;
//! - [`control`]: the controller's cycle (watchdog, delay compensation, the hierarchical
//!   controller, the fallback), allocation-free;
//! - [`vehicle`]: the [`vehicle::VehicleBridge`] where a real car plugs in, the simulator
//!   bridge and the vehicle's own command watchdog;
//! - [`run`]: the two processes' loops;
//! - [`record`], [`recording`]: MCAP recording of every topic on a thread of its own;
//! - [`cli`]: what the binaries share.
//!
//! See docs/vehicle_io.md.

pub mod cli;
pub mod config;
pub mod control;
pub mod msg;
pub mod ports;
pub mod record;
pub mod recording;
pub mod run;
pub mod vehicle;
