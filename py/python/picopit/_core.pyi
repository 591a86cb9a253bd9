"""Type stubs for picopit._core, the pyo3 extension (thin bindings to the Rust core).

Array arguments accept anything numpy can convert to float64 of the stated shape; they are
copied, and a wrong shape or a non-finite value raises ValueError naming the argument.
Returned arrays are fresh float64 copies.
"""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

_ArrayLike = Union[npt.ArrayLike, Sequence[float]]
_F64 = npt.NDArray[np.float64]

GRAVITY: float

class ParamError(ValueError):
    """A parameter set or parameter file that cannot be used; the message names the field."""

class MpcError(ValueError):
    """Bad MPC settings, construction input or control-step input; the message names the
    field."""

class ModelError(ValueError):
    """A surrogate model file that cannot be used; the message names the metadata key or
    tensor (docs/model-format.md)."""

def load_params(name_or_path: str) -> str:
    """Load and validate a parameter set (built-in name or TOML path); returns it as TOML."""

def builtin_param_sets() -> list[str]:
    """Names of the built-in parameter sets (``full_size``, ``half_scale``)."""

def footprint(pose: _ArrayLike, length: float, width: float, cg_to_front: float) -> _F64:
    """Corners (4, 2) of a vehicle footprint with its c.g. at ``pose = [X, Y, yaw]``,
    counter-clockwise from front-left."""

def footprint_contact(pose_a: _ArrayLike, size_a: _ArrayLike, pose_b: _ArrayLike,
                      size_b: _ArrayLike) -> Optional[Dict[str, Any]]:
    """Where two vehicle footprints overlap (the plant's separating-axis test):
    ``{"gamma": world heading of the normal from a into b, "point": [X, Y], "depth": m}``,
    or None apart. ``pose = [X, Y, yaw]`` of the c.g., ``size = [length, width, cg_to_front]``."""

def wrap_angle(a: float) -> float:
    """Wrap an angle to (-pi, pi]."""

class ContactDict(TypedDict):
    fc: _F64
    """[F_n, F_t] on the target in the contact frame (N); the bullet receives -fc."""
    gamma: float
    """World heading of the contact normal (bullet into target), rad."""
    point_in_world: _F64
    point_in_target: _F64
    point_in_bullet: _F64
    depth: float
    """Penetration depth (m)."""

class Plant:
    """The high-fidelity two-vehicle simulator (the truth), fixed step ``dt``."""

    def __init__(
        self,
        params: str = "full_size",
        mu: float = 0.9,
        dt: float = 1e-3,
        *,
        tyre_forces: bool = True,
        target_gear: str = "forward",
    ) -> None:
        """``params``: built-in set name or TOML path; ``mu``: road adhesion in (0, 1.5];
        ``dt``: step in (0, 1e-3] s; ``tyre_forces=False`` leaves only contact forces
        (diagnostics); ``target_gear``: "forward" (the target's powertrain engaged: engine
        braking, a stall that holds the driven axle) or "neutral" (it rolls freely). Bad
        values raise ParamError naming ``plant.mu`` / ``plant.dt``, ValueError for a gear."""
    def reset(self, bullet: _ArrayLike, target: _ArrayLike) -> None:
        """Place both vehicles, each ``[X, Y, yaw, vx, vy, r]`` (c.g. position, body-frame
        velocities); time restarts at 0."""
    def set_commands(
        self,
        bullet_steer: float,
        bullet_torque: float,
        target_steer: float = 0.0,
        target_brake: float = 0.0,
        bullet_brake: float = 0.0,
    ) -> None:
        """Driver commands held until changed: bullet front steer (rad), rear drive torque
        T_r (N m, negative brakes through the drivetrain); target front steer (rad), the
        target driver's longitudinal torque at the wheels (N m: >= 0 service brakes, < 0 the
        throttle, drive torque at its driven axle); bullet service brake (N m, >= 0). The plant applies actuator
        limits, rate limits and lags."""
    def set_bullet_command_blended(self, steer: float, torque: float) -> None:
        """The bullet command as the controllers plan it, ``[δ_f, T_r]``: a positive T_r
        drives the rear axle, a negative one is blended into the service brakes of all four
        wheels with the same total force."""
    def advance(self, duration: float) -> None:
        """Simulate ``duration`` seconds (rounded to whole steps, at most 1e5 s); the GIL is
        released meanwhile."""
    def step(self) -> None:
        """One integration step of ``dt``."""
    @property
    def time(self) -> float: ...
    @property
    def dt(self) -> float: ...
    @property
    def mu(self) -> float: ...
    @property
    def params(self) -> str: ...
    def bullet_state(self) -> _F64:
        """``[X, Y, yaw, vx, vy, r]``, shape (6,)."""
    def target_state(self) -> _F64:
        """``[vx, vy, yaw, r, p, phi, X, Y]`` (the paper's order), shape (8,)."""
    def body(self, which: str) -> Dict[str, Any]:
        """Full state of ``which`` ("bullet" or "target"): ``steer``, ``torque``, ``brake``
        (actual actuator values), ``omega`` (wheel spin FL FR RL RR, rad/s), ``fz`` (wheel
        loads, N), ``roll``, ``pitch`` (rad), ``acc_body`` (c.g. acceleration, body frame),
        ``stalled`` (the engine of a vehicle in gear has stalled)."""
    def set_drive(self, which: str, torque: float) -> None:
        """Drive-torque command T_r (N m, motor side) of ``which`` ("bullet" or "target");
        actuator limits and lag apply. ValueError for another name or a non-finite torque."""
    def contact(self) -> Optional[ContactDict]:
        """The bullet-target contact of the last step, or None."""
    def take_contact_average(self) -> Optional[ContactDict]:
        """The contact averaged since the previous call (impulse over elapsed time; normal and
        points weighted by the normal impulse; ``depth`` the maximum), then averaging
        restarts. None if the vehicles did not touch in that interval."""
    def footprints(self) -> _F64:
        """Corners, shape (2, 4, 2): [bullet, target] x 4 corners x [X, Y]."""

class BulletModel:
    """The bullet's single-track control model: state ``[X, Y, yaw, vx, vy, r]``, input
    ``[delta_f, T_r]``, one RK4 step of ``dt`` per call."""

    def __init__(
        self,
        params: str = "full_size",
        mu: float = 0.9,
        dt: float = 0.05,
        vehicle: str = "bullet",
        *,
        substeps: int | None = None,
    ) -> None:
        """``vehicle`` picks ``bullet`` or ``target`` out of the parameter set; ``substeps``
        splits each step into equal RK4 sub-steps (Jacobians stay exact). ``None`` keeps the
        model's default, the fewest sub-steps that are stable down to 1 m/s."""
    @property
    def dt(self) -> float: ...
    @property
    def substeps(self) -> int: ...
    @property
    def understeer_gradient(self) -> float:
        """Understeer gradient from the axle curves (rad s^2/m)."""
    def step(
        self,
        x: _ArrayLike,
        u: _ArrayLike,
        fc: Optional[_ArrayLike] = None,
        gamma: float = 0.0,
        point: Optional[_ArrayLike] = None,
    ) -> _F64:
        """The next state (6,). ``fc = [F_n, F_t]`` is the force on the target (the bullet
        receives ``-fc``), ``gamma`` the world heading of the contact normal, ``point`` the
        point of action in the bullet's body frame relative to its c.g.; None means zero."""
    def step_jac(
        self,
        x: _ArrayLike,
        u: _ArrayLike,
        fc: Optional[_ArrayLike] = None,
        gamma: float = 0.0,
        point: Optional[_ArrayLike] = None,
    ) -> Tuple[_F64, _F64, _F64, _F64]:
        """``(x_next (6,), A = dx+/dx (6, 6), B = dx+/du (6, 2), F = dx+/dfc (6, 2))``."""

class FourDofTarget:
    """The 4-DOF analytic target model: state ``[vx, vy, yaw, r, p, phi, X, Y]``, input
    ``[delta, T_b]``, one step of ``dt`` per call."""

    def __init__(
        self,
        params: str = "full_size",
        mu: float = 0.9,
        dt: float = 0.05,
        vehicle: str = "target",
        *,
        substeps: int | None = None,
    ) -> None: ...
    @property
    def dt(self) -> float: ...
    @property
    def substeps(self) -> int: ...
    @property
    def param_count(self) -> int:
        """Trainable parameters (0: analytic)."""
    @property
    def name(self) -> str:
        """``4dof``."""
    def step(
        self,
        x: _ArrayLike,
        u: _ArrayLike,
        fc: Optional[_ArrayLike] = None,
        gamma: float = 0.0,
        point: Optional[_ArrayLike] = None,
    ) -> _F64:
        """The next state (8,). ``fc = [F_n, F_t]`` acts on the target at ``point`` (body
        frame, relative to the c.g.); ``gamma`` is the world heading of the normal."""
    def step_jac(
        self,
        x: _ArrayLike,
        u: _ArrayLike,
        fc: Optional[_ArrayLike] = None,
        gamma: float = 0.0,
        point: Optional[_ArrayLike] = None,
    ) -> Tuple[_F64, _F64, _F64, _F64]:
        """``(x_next (8,), A (8, 8), B (8, 2), F (8, 2))``."""

class SurrogateModel:
    """A learned target surrogate (teacher PINN or PicoPINN) loaded from a ``picopit-mlp``
    v2 safetensors file (docs/model-format.md): state ``[vx, vy, yaw, r, p, phi, X, Y]``,
    input ``[delta, T_b]``, one step of the file's ``dt`` per call, on a road of adhesion
    ``mu`` (a property of the instance, as for :class:`FourDofTarget`)."""

    def __init__(self, path: Union[str, os.PathLike[str]], mu: Optional[float] = None) -> None:
        """Load and validate the file (the GIL is released meanwhile). A file that cannot
        be used raises ModelError naming the metadata key or tensor at fault. ``mu``
        defaults to the file's ``mu_default``; outside the file's ``mu_range`` it raises
        ModelError naming ``mu``."""
    @property
    def mu(self) -> float:
        """Road adhesion μ, the network's last input. Setting it outside ``mu_range``
        raises ModelError (the previous μ stays)."""
    @mu.setter
    def mu(self, value: float) -> None: ...
    @property
    def mu_range(self) -> Tuple[float, float]:
        """``(lo, hi)``: the road adhesion the model was trained on (the file's ``mu_range``)."""
    @property
    def name(self) -> str:
        """``pinn`` or ``picopinn`` (the file's ``kind``)."""
    @property
    def dt(self) -> float:
        """Step length (s), from the file's metadata."""
    @property
    def param_count(self) -> int:
        """Free parameters, ``len(theta)``."""
    @property
    def layers(self) -> List[int]:
        """Layer widths, input first (``[11, ..., 8]``)."""
    @property
    def metadata(self) -> Dict[str, str]:
        """Every key of the file's header metadata."""
    def step(
        self,
        x: _ArrayLike,
        u: _ArrayLike,
        fc: Optional[_ArrayLike] = None,
        gamma: float = 0.0,
        point: Optional[_ArrayLike] = None,
    ) -> _F64:
        """The next state (8,); the arguments as for :meth:`FourDofTarget.step`."""
    def step_jac(
        self,
        x: _ArrayLike,
        u: _ArrayLike,
        fc: Optional[_ArrayLike] = None,
        gamma: float = 0.0,
        point: Optional[_ArrayLike] = None,
    ) -> Tuple[_F64, _F64, _F64, _F64]:
        """``(x_next (8,), A (8, 8), B (8, 2), F (8, 2))``, F with ``gamma`` and ``point``
        held fixed."""
    def forward(self, features: _ArrayLike) -> _F64:
        """The increments ``o = [dvx, dvy, dr, dp, dphi, dpsi, dx_b, dy_b]`` (8,), kinematic
        base included, for ``features = [vx, vy, r, p, phi, delta, T_b, f_bx, f_by, M_z, mu]``
        (11,); μ comes from the features (not range-checked) and ``self.mu`` is unchanged."""

class MpcTimes(TypedDict):
    linearise: float
    assemble: float
    qp: float
    total: float

class MpcResult(TypedDict):
    status: str
    """``RtiStep``, ``Converged``, ``IterationCap``, ``TimeBudget`` or ``QpFailure``."""
    command: _F64
    """``[delta_f, T_r]`` to apply now; always finite."""
    fallback: Optional[str]
    """None, ``shifted_plan`` or ``brake`` (with ``QpFailure``)."""
    coupled: bool
    """Whether the QP carried the target and the contact force."""
    scp_iterations: int
    qp_iterations: int
    merit: float
    max_violation: float
    times: MpcTimes

class MpcPlan(TypedDict):
    u: _F64
    f: _F64
    target: _F64
    bullet: _F64
    gap: _F64

class CoupledMpc:
    """The coupled collision MPC (crates/mpc): SCP over Clarabel QPs, N = 20, dt = 0.05 s.
    ``target_model`` is ``4dof`` or the path of a surrogate file (``SurrogateModel``);
    ``settings`` is TOML (``mpc::MpcSettings``, missing fields default); ``side`` the side the
    default reference works on. Bad values raise MpcError naming the field."""

    def __init__(
        self,
        params: str = "full_size",
        mu: float = 0.9,
        target_model: str = "4dof",
        settings: Optional[str] = None,
        side: str = "left",
    ) -> None: ...
    @property
    def settings(self) -> str: ...
    @property
    def horizon(self) -> int: ...
    @property
    def target_model(self) -> str: ...
    @property
    def param_count(self) -> int: ...
    @property
    def qp_sizes(self) -> Tuple[Tuple[int, int], Tuple[int, int]]:
        """(columns, rows) of the coupled QP and of the bullet-only QP."""
    @property
    def linearisation_error(self) -> float: ...
    def set_road(self, road_toml: Optional[str]) -> None: ...
    def set_straight_road(
        self, length: float = 2000.0, lanes: int = 3, lane_width: float = 3.5, shoulder: float = 1.0
    ) -> None: ...
    def set_obstacles(self, obstacles: _ArrayLike) -> None:
        """(n, 7): ``[x, y, heading, vx, vy, length, width]`` at time 0."""
    def default_reference(self, target: _ArrayLike, bullet: _ArrayLike, lane_heading: float = 0.0) -> None: ...
    def set_reference(self, stages: _ArrayLike, target_heading: float, target_weight: float) -> None:
        """(N, 8): ``[rel_x, rel_y, rel_heading, rel_speed, track, fn_lo, fn_hi, envelope_lat]``."""
    def reference(self) -> _F64: ...
    @property
    def reference_target(self) -> Tuple[float, float]:
        """``(target_heading, target_weight)`` of the current reference."""
    def solve(
        self,
        target: _ArrayLike,
        bullet: _ArrayLike,
        target_input: Optional[_ArrayLike] = None,
        last_command: Optional[_ArrayLike] = None,
        time: float = 0.0,
    ) -> MpcResult:
        """One control step; the GIL is released meanwhile."""
    def plan(self) -> MpcPlan: ...
    def linearisation(self) -> Dict[str, Any]:
        """The last QP's per-stage linearisation (contact frame, gap and its gradients, the
        soft rows as ``[gX, gY, gpsi, rhs]``)."""
    def evaluate(
        self,
        target: _ArrayLike,
        bullet: _ArrayLike,
        u: _ArrayLike,
        f: _ArrayLike,
        target_input: Optional[_ArrayLike] = None,
        last_command: Optional[_ArrayLike] = None,
        time: float = 0.0,
    ) -> Tuple[float, float]:
        """(merit, largest violation) of the plan that ``u`` (N, 2) and ``f`` (N, 2) produce."""
    def reset(self) -> None: ...

# --- scenarios (crates/sim) -------------------------------------------------------------

class ScenarioError(ValueError):
    """A scenario file or line that cannot be used; the message names the line and the field."""

class ScreenResult(TypedDict):
    verdict: str
    """``keep``, ``trivial``, ``impossible`` or ``rejected``."""
    reason: str
    t_fail: Optional[float]
    t_stop: Optional[float]
    t_reach: float
    simulated: float
    min_margin: float

class InitialStates(TypedDict):
    bullet: _F64
    """``[X, Y, yaw, vx, vy, r]``."""
    target: _F64
    """``[vx, vy, yaw, r, p, phi, X, Y]``."""

def load_scenarios(path: str) -> List[Dict[str, Any]]:
    """Read and validate a JSON-lines scenario file; a bad line raises ScenarioError naming
    its line number and field."""
def validate_scenario_line(text: str, line: int = 1) -> Dict[str, Any]:
    """Validate one scenario (JSON text); returns it as a dict."""
def screen_scenario(text: str) -> ScreenResult:
    """Rule and short-simulation screening of one scenario (the GIL is released)."""
def scenario_initial_states(text: str) -> InitialStates: ...
def road_poses(road: str, s: _ArrayLike, d: Optional[_ArrayLike] = None) -> _F64:
    """(n, 3) ``[x, y, heading]`` of a scenario road (JSON of its ``road`` object) at
    stations ``s``, offset laterally by ``d``."""
def road_project(road: str, x: Sequence[float], y: Sequence[float]) -> _F64:
    """(n, 3) Frenet ``[s, d, heading]`` of world points on a scenario road (JSON of its
    ``road`` object): station and lateral offset (left positive) of the nearest reference-line
    point, and the road's heading there (NaN rows for non-finite points)."""

# --- the ideal-PIT bound (crates/sim oracle) -----------------------------------------------

def oracle_settings(settings_json: Optional[str] = None) -> Dict[str, Any]:
    """The oracle's settings (JSON over the defaults) resolved and validated; ScenarioError
    names a bad field."""
def ideal_pit(scenario: str, settings_json: Optional[str] = None) -> Dict[str, Any]:
    """The ideal-PIT bound on one scenario (JSON): ``feasible``, ``shove`` (``time``, ``side``,
    ``dv``, ``decided_at``, ``at_rest``; None), ``t_reach``, ``tried``, ``successes``,
    ``alone_fails_at`` (the GIL is released)."""
def oracle_tier_names() -> List[str]: ...
def oracle_tiers(scenario: str, settings_json: Optional[str] = None) -> Dict[str, Any]:
    """The tiers on one scenario (JSON): ``tiers`` (name -> chance of success), ``true_share``,
    ``held_share``, ``t_reach``, ``shoves`` (the GIL is released)."""
def shove_grid(scenario: str, settings_json: Optional[str] = None, held: bool = False) -> Dict[str, Any]:
    """Every single shove of the grid on one scenario (JSON), simulated to the verdict with the
    driver's true law (``held``: its command held): ``times`` (s, from the bullet's earliest
    arrival), ``sides``, ``shoves`` (m/s), ``success`` (``[time][side][shove]`` bools),
    ``t_reach`` (the GIL is released)."""

# --- planner (crates/planner): decision layer and whole-maneuver controller --------------

class PlannerError(ValueError):
    """Bad planner or controller settings (the message names the field), a bad array shape,
    a non-finite input, an unknown target model or a missing road."""

class PlanTerminal(TypedDict):
    heading: float
    """psi_T,rev: the reversed heading (rad, unwrapped)."""
    heading_tol: float
    yaw_decay: float
    """tau of the projected heading ``psi_N + tau r_N`` (s)."""

class PlanPackage(TypedDict):
    """The decision package Pi (``planner::DecisionPackage``); N = horizon / dt steps."""

    mode: str
    """``chase``, ``pit``, ``stabilise`` or ``abort``."""
    infeasible: Optional[str]
    """Why no feasible PIT exists: ``terminal_set_unreachable``, ``road_boundary``,
    ``obstacle_clearance`` or ``numerical``; None when a feasible candidate was found."""
    time: float
    side: str
    """``left`` or ``right``."""
    contact_point: _F64
    """(2,) contact point on the target's rear quarter, target body frame (m)."""
    contact_rel_pos: _F64
    """(2,) the bullet's contact position relative to the target, target frame (m)."""
    contact_rel_heading: float
    push_speed: float
    envelope_lat: float
    window: Optional[Tuple[float, float]]
    """Contact window ``(t0, t1)`` (absolute s), or None when none is planned."""
    terminal: PlanTerminal
    road_margin: float
    obstacle_clearance: float
    obstacles: _F64
    """(m, 7) the obstacles planned against, as given to ``set_obstacles``."""
    predicted_heading_error: float
    predicted_road_margin: float
    predicted_clearance: float
    """Least predicted obstacle clearance (m; a sentinel near 1e3 without obstacles)."""
    predicted_stop_margin: float
    objective: float
    """Objective of the chosen candidate (inf when none was evaluated)."""
    candidates: int
    feasible_candidates: int
    times: _F64
    """(N+1,) step start times (absolute s)."""
    forces: _F64
    """(N+1, 2) the virtual interaction ``[F_n, F_t]`` (N); zero outside the window and at
    the last entry."""
    corridor: _F64
    """(N+1, 2) the normal-force corridor ``[lo, hi]`` (N); zero outside the window."""
    targets: _F64
    """(N+1, 8) the predicted target ``[vx, vy, yaw, r, p, phi, X, Y]``."""

class ControllerStep(TypedDict):
    command: _F64
    """``[delta_f, T_r]`` to apply now (negative T_r brakes); always finite."""
    phase: str
    """``chasing``, ``pit``, ``stabilising``, ``done`` or ``aborted``."""
    mode: Optional[str]
    """The upper layer's current mode (as ``PlanPackage.mode``); None without it."""
    abort: Optional[str]
    """``chase_timeout``, ``bullet_unstable``, ``bullet_clearance`` or
    ``decision_infeasible:<reason>`` (reason as ``PlanPackage.infeasible``); None."""
    mpc_status: Optional[str]
    """As ``MpcResult.status`` when the MPC ran this step (active phases), else None."""
    replanned: bool
    plan_time: float
    """Wall time of this step's planning (s; 0 when it did not replan)."""
    ctrl_time: float
    """Wall time of the rest of the step (s)."""

class Planner:
    """The upper virtual-PIT decision layer (crates/planner). ``target_model`` is ``4dof`` or
    the path of a surrogate file; ``settings`` is TOML of ``planner::PlannerSettings``
    (missing fields default). Bad values raise PlannerError naming the field; a road must be
    set before planning."""

    def __init__(
        self,
        params: str = "full_size",
        mu: float = 0.9,
        target_model: str = "4dof",
        settings: Optional[str] = None,
    ) -> None: ...
    def settings_toml(self) -> str: ...
    @property
    def target_model(self) -> str: ...
    def set_road(self, road_toml: str) -> None: ...
    def set_straight_road(
        self, length: float = 2000.0, lanes: int = 3, lane_width: float = 3.5, shoulder: float = 1.0
    ) -> None: ...
    def set_obstacles(self, obstacles: _ArrayLike) -> None:
        """(n, 7): ``[x, y, heading, vx, vy, length, width]`` at time 0; n <= 32."""
    def plan(
        self,
        time: float,
        target: _ArrayLike,
        bullet: _ArrayLike,
        target_input: Optional[_ArrayLike] = None,
        side: Optional[str] = None,
        best_effort: bool = False,
    ) -> PlanPackage:
        """One decision; ``target`` (8,), ``bullet`` (6,), ``target_input`` (2,) or None for
        zeros; ``side`` None, ``left`` or ``right``. The GIL is released meanwhile."""
    def predict(
        self,
        mode: str,
        time: float,
        target: _ArrayLike,
        bullet: _ArrayLike,
        target_input: Optional[_ArrayLike] = None,
    ) -> PlanPackage:
        """The free (no-force) prediction as a package of ``mode``."""

class PitController:
    """Planner + coupled MPC + phase machine (``planner::PitController``). ``settings`` is
    TOML of ``planner::ControllerSettings`` (tables ``planner``, ``phases``, ``mpc``);
    ``upper_layer=False`` is the ablation without the decision layer (a settings text that
    says otherwise is a PlannerError)."""

    def __init__(
        self,
        params: str = "full_size",
        mu: float = 0.9,
        target_model: str = "4dof",
        settings: Optional[str] = None,
        upper_layer: bool = True,
    ) -> None: ...
    def settings_toml(self) -> str: ...
    @property
    def target_model(self) -> str: ...
    @property
    def upper_layer(self) -> bool: ...
    @property
    def phase(self) -> str:
        """As ``ControllerStep.phase``."""
    @property
    def abort_reason(self) -> Optional[str]:
        """As ``ControllerStep.abort``."""
    def set_road(self, road_toml: str) -> None: ...
    def set_straight_road(
        self, length: float = 2000.0, lanes: int = 3, lane_width: float = 3.5, shoulder: float = 1.0
    ) -> None: ...
    def set_obstacles(self, obstacles: _ArrayLike) -> None: ...
    def step(
        self,
        time: float,
        target: _ArrayLike,
        bullet: _ArrayLike,
        target_input: Optional[_ArrayLike] = None,
    ) -> ControllerStep:
        """One control step; the GIL is released meanwhile."""
    def package(self) -> Optional[PlanPackage]:
        """The last decision package, or None without the upper layer."""
    def reset(self) -> None:
        """Start a new maneuver at the next step (the phase is reset then)."""

# --- closed-loop episodes (crates/sim::episode) -------------------------------------------

class EpisodeError(ValueError):
    """An episode that cannot be run: a bad configuration (the message names the field), a
    model file that cannot be loaded, or settings the controller refuses."""

class EpisodeResult(TypedDict):
    scenario: str
    config: str
    seed: int
    model: str
    """``4dof``, ``pinn`` or ``picopinn``."""
    param_count: int
    upper_layer: bool
    success: bool
    at_rest: bool
    """The success was the target at rest reversed (not only settled, still rolling, at T_max)."""
    cause: Optional[str]
    """First failure cause: ``decision_infeasible``, ``no_termination``,
    ``boundary_violation``, ``secondary_collision``, ``unsafe_rebound``; None on success."""
    decided_at: Optional[float]
    terminal_heading_error: float
    """rad, at the last observation."""
    min_margin: float
    """m, smallest footprint distance to a road edge or obstacle (negative: crossed)."""
    boundary_violation: bool
    secondary_collision: bool
    contacts: int
    contact_at: Optional[float]
    """s, time of the first bullet-target contact; None without contact."""
    impact_speed: Optional[float]
    """m/s, |v_B - v_T| of the two c.g. at the first contact; None without contact."""
    impact_angle: Optional[float]
    """rad, |wrap(psi_B - psi_T)| at the first contact; None without contact."""
    impact_x: Optional[float]
    impact_y: Optional[float]
    """m, the first contact's point in the target's body frame (x forward, y left)."""
    reversed_at: Optional[float]
    reversed_speed: Optional[float]
    """s and m/s: time and target speed at its first observation within eps_psi of the
    reversed heading; None if it never reversed."""
    failed_vehicle: Optional[str]
    """``bullet``, ``target`` or ``both``: who crossed the edge or hit the obstacle that
    decided a boundary violation or secondary collision; None otherwise."""
    sim_time: float
    control_steps: int
    plan_count: int
    plan_ms_median: float
    plan_ms_p99: float
    plan_ms_max: float
    ctrl_count: int
    ctrl_ms_median: float
    ctrl_ms_p99: float
    ctrl_ms_max: float
    final_phase: str
    abort: Optional[str]
    mpc_failures: int
    mpc_time_budget: int
    held_back_until: Optional[float]
    """The time (s) of the last plan that held the bullet back behind the target for an
    obstacle in the way of its stand-off pose; None if no plan did."""
    wall_time: float
    plan_times_ms: _F64
    """Every planning time (ms) of the episode (steps that planned)."""
    ctrl_times_ms: _F64
    """Every control time (ms) of the episode (steps the MPC ran)."""
    #: with ``record``, the upper layer's plans: ``time``, ``mode``, ``reason`` (why an
    #: abort: ``"race lost"`` or the infeasibility; else None), ``side`` (``"left"`` or
    #: ``"right"``), ``hold_back`` (the bullet held back behind the target for an obstacle),
    #: ``push_from``, ``push_to``, ``push_peak``, ``push_impulse`` (the planned
    #: ∫F_n dt, N s), ``predicted_heading_error``, ``predicted_time`` ((N+1,) step start
    #: times, s) and ``predicted_target`` ((N+1, 8) the predicted target states) (empty without)
    plans: List[Dict[str, Any]]
    trajectory: Optional[_F64]
    """(steps, 29) per control step when recorded; columns: ``trajectory_columns()`` (the
    last three, ``contact_gamma``, ``contact_px``, ``contact_py``, with ``contact_fn`` and
    ``contact_ft`` are the step's averaged contact as a target model takes it)."""

def episode_presets() -> List[str]:
    """``['4dof', 'pinn', 'picopinn', 'picopinn_no_upper']``."""
def episode_config(config: str) -> Dict[str, Any]:
    """The resolved configuration of a preset name or JSON text (``{"preset": ..., ...}``)."""
def trajectory_columns() -> List[str]: ...
def run_episode(
    scenario: str,
    config: str,
    seed: int = 0,
    record: bool = False,
    models_dir: Optional[str] = None,
) -> EpisodeResult:
    """One closed-loop episode (scenario as JSON text; config a preset name or JSON); the
    GIL is released while it runs."""
