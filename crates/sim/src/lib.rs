//! Scenarios, the closed-loop episode runner, the success test and the failure causes.
//!
//! * [`scenario`]: the scenario schema (JSON lines), its loader with typed errors naming
//!   line and field, and the helpers that build the road, obstacles, the plant's initial
//!   conditions and the target driver from a scenario.
//! * [`driver`]: the target driver's definition and law (lane keeping, the throttle, the
//!   reaction to the contact).
//! * [`outcome`]: the success test and the single first failure cause of an episode.
//! * [`config`]: an episode's configuration (surrogate, controller settings, uncertainty,
//!   clock; the benchmark's presets) and its errors.
//! * [`episode`]: the closed-loop episode runner (plant + controller + success test).
//! * [`screen`]: rule and short-simulation screening used by the dataset generator.
//! * [`oracle`]: the ideal-PIT bound (could any single rear-quarter shove, at any time
//!   the bullet could be there, save the scenario?), a controller-independent ceiling.
//! * [`vehicle`]: the simulated vehicle pair (plant, target driver, sensors, actuators,
//!   judge) one control period at a time, shared by the episode runner and `pit-vehicle`.

pub mod config;
pub mod driver;
pub mod episode;
pub mod oracle;
pub mod outcome;
pub mod scenario;
pub mod screen;
mod unique_keys;
pub mod vehicle;

pub use config::{ClockKind, EpisodeConfig, EpisodeError, ModelKind, Uncertainty};
pub use episode::{run_episode, EpisodeResult, PlanRecord};
pub use oracle::{
    ideal_pit, oracle_tiers, shove_grid, DriverView, GridChoice, OracleReport, OracleSettings,
    ShoveGrid, TierReport,
};
pub use outcome::{FailureCause, JudgeSettings, Metrics, Monitor, Observation, Outcome, Status};
pub use scenario::{load_jsonl, parse_jsonl, Scenario, ScenarioError, TargetDriver};
pub use screen::{screen, ScreenReport, ScreenSettings, Verdict};
