//! Service names and the iceoryx2 ports of each process.
//!
//! Every service lives under a configurable prefix (`picopit` by default), so several runs
//! (tests, a soak beside a trial) share one host without meeting:
//!
//! | service                         | pattern        | payload            | publisher  |
//! |---------------------------------|----------------|--------------------|------------|
//! | `<prefix>/state`                | publish-subscribe | [`StateEstimate`]  | vehicle    |
//! | `<prefix>/command`              | publish-subscribe | [`ActuatorCommand`]| controller |
//! | `<prefix>/status`               | publish-subscribe | [`ControllerStatus`]| controller |
//! | `<prefix>/heartbeat/controller` | publish-subscribe | [`Heartbeat`]      | controller |
//! | `<prefix>/heartbeat/vehicle`    | publish-subscribe | [`Heartbeat`]      | vehicle    |
//! | `<prefix>/state/ready`          | event          | —                  | vehicle    |
//! | `<prefix>/command/ready`        | event          | —                  | controller |
//!
//! Publishing is loan → write → send; the events wake the other side at once (no polling).
//! All services are opened with the same quality-of-service settings by [`open_pubsub`], so
//! either side (and a recorder) may start first.

use crate::msg::{ActuatorCommand, ControllerStatus, Heartbeat, StateEstimate};
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use std::fmt::Debug;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Once;
use std::time::Duration;

/// The iceoryx2 service flavour: inter-process, shared memory.
pub type Svc = ipc::Service;

/// Samples a subscriber buffers before the oldest is overwritten (safe overflow): the
/// controller only wants the newest state; the recorder drains every few milliseconds.
pub const SUBSCRIBER_BUFFER: usize = 64;
/// Subscribers per service: the peer, the two recorders and room for tools and tests.
pub const MAX_SUBSCRIBERS: usize = 8;

/// A failure to set up a port (at start-up only; never on the hot path).
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    #[error("service prefix {prefix:?}: {reason}")]
    Prefix { prefix: String, reason: String },
    #[error("iceoryx2 node: {0}")]
    Node(String),
    #[error("iceoryx2 service `{service}`: {reason}")]
    Service { service: String, reason: String },
}

/// A publish or receive failure on the hot path (small and `Copy`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum IoFault {
    #[error("loaning a sample failed")]
    Loan,
    #[error("sending a sample failed")]
    Send,
    #[error("receiving a sample failed")]
    Receive,
    #[error("notifying the peer failed")]
    Notify,
    #[error("waiting for an event failed")]
    Wait,
}

/// The names of all services under one prefix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceNames {
    pub state: String,
    pub command: String,
    pub status: String,
    pub heartbeat_controller: String,
    pub heartbeat_vehicle: String,
    pub state_ready: String,
    pub command_ready: String,
}

impl ServiceNames {
    /// The names under `prefix` (1–64 characters of `[A-Za-z0-9_-]`, `/` separating parts).
    ///
    /// # Errors
    /// [`PortError::Prefix`] for an empty, long or oddly spelled prefix.
    pub fn new(prefix: &str) -> Result<Self, PortError> {
        let ok = !prefix.is_empty()
            && prefix.len() <= 64
            && !prefix.starts_with('/')
            && !prefix.ends_with('/')
            && !prefix.contains("//")
            && prefix
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '/'));
        if !ok {
            return Err(PortError::Prefix {
                prefix: prefix.to_owned(),
                reason:
                    "must be 1–64 characters of A–Z, a–z, 0–9, `_`, `-`, with `/` between parts"
                        .to_owned(),
            });
        }
        let n = |s: &str| format!("{prefix}/{s}");
        Ok(Self {
            state: n("state"),
            command: n("command"),
            status: n("status"),
            heartbeat_controller: n("heartbeat/controller"),
            heartbeat_vehicle: n("heartbeat/vehicle"),
            state_ready: n("state/ready"),
            command_ready: n("command/ready"),
        })
    }
}

fn service_err(service: &str, e: impl Debug) -> PortError {
    PortError::Service {
        service: service.to_owned(),
        reason: format!("{e:?}"),
    }
}

/// A node for this process (signals: SIGINT/SIGTERM are caught, see
/// [`termination_requested`]).
///
/// # Errors
/// [`PortError::Node`] when iceoryx2 cannot create it.
pub fn node(name: &str) -> Result<Node<Svc>, PortError> {
    // iceoryx2 logs at "warn" by default (e.g. that no config file was found and its
    // defaults apply); `IOX2_LOG_LEVEL` still overrides.
    set_log_level_from_env_or(LogLevel::Error);
    let name: NodeName = name
        .try_into()
        .map_err(|e| PortError::Node(format!("node name {name:?}: {e:?}")))?;
    let node = NodeBuilder::new()
        .name(&name)
        .create::<Svc>()
        .map_err(|e| PortError::Node(format!("{e:?}")))?;
    catch_termination(&node);
    Ok(node)
}

/// Set once SIGINT or SIGTERM has arrived, by [`on_termination`] (or by
/// [`catch_termination`], for one that iceoryx2 caught before it).
static TERMINATION: AtomicBool = AtomicBool::new(false);
/// The SIGINT and SIGTERM handlers [`on_termination`] replaced and calls on (iceoryx2's, as
/// addresses; 0: none).
static PREVIOUS_HANDLER: [AtomicUsize; 2] = [AtomicUsize::new(0), AtomicUsize::new(0)];

/// This process's SIGINT/SIGTERM handler: it sets [`TERMINATION`], then calls the handler it
/// replaced. iceoryx2 keeps only the last signal that arrived, in one slot, so a SIGCONT that
/// follows a SIGTERM (as `systemctl stop` sends them, or a pause's end just before a stop)
/// erased the request there; the flag keeps it. Async-signal-safe: atomics only.
extern "C" fn on_termination(signal: libc::c_int) {
    TERMINATION.store(true, Ordering::SeqCst);
    let previous = PREVIOUS_HANDLER[usize::from(signal == libc::SIGTERM)].load(Ordering::SeqCst);
    if previous != 0 {
        // SAFETY: a one-argument handler taken from `sigaction` (not SA_SIGINFO, not
        // SIG_DFL or SIG_IGN) by `catch_termination`.
        let handler: extern "C" fn(libc::c_int) = unsafe { std::mem::transmute(previous) };
        handler(signal);
    }
}

/// Install [`on_termination`] for SIGINT and SIGTERM, once per process, on top of
/// iceoryx2's handlers (which it installs on first use: `node.wait` makes sure of that
/// first). No `SA_RESTART`: the signal still interrupts a wait.
fn catch_termination(node: &Node<Svc>) {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if node.wait(Duration::ZERO).is_err() {
            TERMINATION.store(true, Ordering::SeqCst);
        }
        for (slot, signal) in PREVIOUS_HANDLER.iter().zip([libc::SIGINT, libc::SIGTERM]) {
            // SAFETY: plain `sigaction` calls with zero-initialised (valid) structs.
            unsafe {
                let mut new: libc::sigaction = std::mem::zeroed();
                new.sa_sigaction = on_termination as extern "C" fn(libc::c_int) as usize;
                libc::sigemptyset(&raw mut new.sa_mask);
                let mut old: libc::sigaction = std::mem::zeroed();
                if libc::sigaction(signal, &raw const new, &raw mut old) == 0
                    && old.sa_sigaction != libc::SIG_DFL
                    && old.sa_sigaction != libc::SIG_IGN
                    && old.sa_flags & libc::SA_SIGINFO == 0
                {
                    slot.store(old.sa_sigaction, Ordering::SeqCst);
                }
            }
        }
    });
}

/// Whether SIGINT or SIGTERM has arrived (checked without blocking: one atomic load, no
/// system call). Once true, it stays true for the life of the process, whatever signal came
/// after it. The node is the proof that [`node`] installed the handler.
#[must_use]
pub fn termination_requested(_node: &Node<Svc>) -> bool {
    TERMINATION.load(Ordering::SeqCst)
}

/// Open (or create) a publish-subscribe service with the shared quality of service.
///
/// # Errors
/// [`PortError::Service`] naming the service.
pub fn open_pubsub<T: Debug + Copy + ZeroCopySend + 'static>(
    node: &Node<Svc>,
    name: &str,
) -> Result<PortFactory<Svc, T, ()>, PortError> {
    let sname: ServiceName = name.try_into().map_err(|e| service_err(name, e))?;
    node.service_builder(&sname)
        .publish_subscribe::<T>()
        .max_publishers(1)
        .max_subscribers(MAX_SUBSCRIBERS)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
        .history_size(1)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| service_err(name, e))
}

/// A publisher on `name`.
///
/// # Errors
/// [`PortError::Service`] naming the service (e.g. a second publisher).
pub fn publisher<T: Debug + Copy + ZeroCopySend + 'static>(
    node: &Node<Svc>,
    name: &str,
) -> Result<Publisher<Svc, T, ()>, PortError> {
    open_pubsub::<T>(node, name)?
        .publisher_builder()
        .create()
        .map_err(|e| service_err(name, e))
}

/// A subscriber on `name`.
///
/// # Errors
/// [`PortError::Service`] naming the service.
pub fn subscriber<T: Debug + Copy + ZeroCopySend + 'static>(
    node: &Node<Svc>,
    name: &str,
) -> Result<Subscriber<Svc, T, ()>, PortError> {
    open_pubsub::<T>(node, name)?
        .subscriber_builder()
        .buffer_size(SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| service_err(name, e))
}

fn event(
    node: &Node<Svc>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, PortError> {
    let sname: ServiceName = name.try_into().map_err(|e| service_err(name, e))?;
    node.service_builder(&sname)
        .event()
        .open_or_create()
        .map_err(|e| service_err(name, e))
}

/// Loan a sample, write `value` into it and send it (no copy through the heap).
///
/// # Errors
/// [`IoFault::Loan`] or [`IoFault::Send`].
pub fn publish<T: Debug + Copy + ZeroCopySend + 'static>(
    p: &Publisher<Svc, T, ()>,
    value: T,
) -> Result<(), IoFault> {
    let sample = p.loan_uninit().map_err(|_| IoFault::Loan)?;
    let sample = sample.write_payload(value);
    sample.send().map(|_| ()).map_err(|_| IoFault::Send)
}

/// Receive every pending sample and keep the newest (`None` when there was none).
///
/// # Errors
/// [`IoFault::Receive`].
pub fn newest<T: Debug + Copy + ZeroCopySend + 'static>(
    s: &Subscriber<Svc, T, ()>,
) -> Result<Option<T>, IoFault> {
    let mut last = None;
    while let Some(sample) = s.receive().map_err(|_| IoFault::Receive)? {
        last = Some(*sample.payload());
    }
    Ok(last)
}

/// Wait until `listener` fires or `timeout` passes; returns whether it fired.
///
/// Two cases never block for good and never fail:
///
/// - a timeout under 1 µs: the listener's socket timeout has microsecond resolution and a
///   zero socket timeout means "wait forever", so a remaining wait of a few hundred
///   nanoseconds used to hang the loop. It is rounded up to whole microseconds, and a zero
///   timeout only looks (no wait);
/// - a signal that interrupts the wait (`EINTR`: SIGCONT after SIGSTOP, a scheduler's pause,
///   SIGINT, SIGTERM) ends the wait early with `Ok(false)`. The caller checks
///   [`termination_requested`] and carries on.
///
/// # Errors
/// [`IoFault::Wait`] when the listener itself fails.
pub fn wait_event(listener: &Listener<Svc>, timeout: Duration) -> Result<bool, IoFault> {
    let mut fired = false;
    let micros = timeout.as_nanos().div_ceil(1_000);
    let result = if micros == 0 {
        listener.try_wait(|_| fired = true)
    } else {
        let micros = u64::try_from(micros).unwrap_or(u64::MAX);
        listener.timed_wait(|_| fired = true, Duration::from_micros(micros))
    };
    match result {
        Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(fired),
        Err(_) => Err(IoFault::Wait),
    }
}

/// The controller's ports.
pub struct ControllerPorts {
    pub node: Node<Svc>,
    pub state: Subscriber<Svc, StateEstimate, ()>,
    pub state_ready: Listener<Svc>,
    pub command: Publisher<Svc, ActuatorCommand, ()>,
    pub command_ready: Notifier<Svc>,
    pub status: Publisher<Svc, ControllerStatus, ()>,
    pub heartbeat: Publisher<Svc, Heartbeat, ()>,
    pub vehicle_heartbeat: Subscriber<Svc, Heartbeat, ()>,
}

impl ControllerPorts {
    /// Open every port of the controller under `names`.
    ///
    /// # Errors
    /// [`PortError`] naming the service at fault.
    pub fn open(names: &ServiceNames) -> Result<Self, PortError> {
        let node = node("pit-controller")?;
        Ok(Self {
            state: subscriber(&node, &names.state)?,
            state_ready: event(&node, &names.state_ready)?
                .listener_builder()
                .create()
                .map_err(|e| service_err(&names.state_ready, e))?,
            command: publisher(&node, &names.command)?,
            command_ready: event(&node, &names.command_ready)?
                .notifier_builder()
                .create()
                .map_err(|e| service_err(&names.command_ready, e))?,
            status: publisher(&node, &names.status)?,
            heartbeat: publisher(&node, &names.heartbeat_controller)?,
            vehicle_heartbeat: subscriber(&node, &names.heartbeat_vehicle)?,
            node,
        })
    }
}

/// The vehicle side's ports.
pub struct VehiclePorts {
    pub node: Node<Svc>,
    pub state: Publisher<Svc, StateEstimate, ()>,
    pub state_ready: Notifier<Svc>,
    pub command: Subscriber<Svc, ActuatorCommand, ()>,
    pub command_ready: Listener<Svc>,
    pub status: Subscriber<Svc, ControllerStatus, ()>,
    pub heartbeat: Publisher<Svc, Heartbeat, ()>,
    pub controller_heartbeat: Subscriber<Svc, Heartbeat, ()>,
}

impl VehiclePorts {
    /// Open every port of the vehicle side under `names`.
    ///
    /// # Errors
    /// [`PortError`] naming the service at fault.
    pub fn open(names: &ServiceNames) -> Result<Self, PortError> {
        let node = node("pit-vehicle")?;
        Ok(Self {
            state: publisher(&node, &names.state)?,
            state_ready: event(&node, &names.state_ready)?
                .notifier_builder()
                .create()
                .map_err(|e| service_err(&names.state_ready, e))?,
            command: subscriber(&node, &names.command)?,
            command_ready: event(&node, &names.command_ready)?
                .listener_builder()
                .create()
                .map_err(|e| service_err(&names.command_ready, e))?,
            status: subscriber(&node, &names.status)?,
            heartbeat: publisher(&node, &names.heartbeat_vehicle)?,
            controller_heartbeat: subscriber(&node, &names.heartbeat_controller)?,
            node,
        })
    }
}

/// `CLOCK_MONOTONIC` in nanoseconds: the same clock in every process of the host.
#[must_use]
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC is always available on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0, "clock_gettime(CLOCK_MONOTONIC) cannot fail");
    (ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64
}
