"""Warp structs shared by the kernels: per-member parameters, solver settings and integrator state.

Parameters and times are float64 whatever the working precision: a float32 time has only ~2 us
resolution at t = 20 s, coarser than the steps the detachment needs.
"""


import warp as wp

# status codes of a member (netCDF flag_values / flag_meanings)
STATUS_OK = 0
STATUS_MAX_STEPS = 1
STATUS_NON_FINITE = 2
STATUS_STEP_UNDERFLOW = 3
STATUS_NO_PEAK = 4  # set on the host: the friction coefficient was still rising at the end of the run
STATUS_STALLED = 5  # set on the host: far more steps than its peers (Solver.stall_factor)
STATUS_MEANINGS = ("ok", "max_steps_reached", "non_finite_state", "step_size_underflow", "no_peak", "stalled")


@wp.struct
class MemberParams:
    """One member's physical parameters (SI), as resolved by warpfric.parameters."""

    shear_modulus: wp.float64
    poisson_ratio: wp.float64
    density: wp.float64
    memory_length: wp.float64
    shear_strength: wp.float64
    hardness: wp.float64
    viscous_coefficient: wp.float64
    reference_velocity: wp.float64
    aging_coefficient: wp.float64
    aging_time: wp.float64
    interface_stiffness: wp.float64
    gate_velocity: wp.float64
    height: wp.float64
    length: wp.float64
    depth: wp.float64
    damping: wp.float64
    normal_force: wp.float64
    eccentricity: wp.float64
    disc_velocity: wp.float64
    force_ramp_time: wp.float64
    rest_until: wp.float64
    velocity_ramp_time: wp.float64
    stop_time: wp.float64
    end_time: wp.float64  # s, min(end_time, max_end_time)
    auto_end: wp.float64  # 1: end_time was None, the run ends when the detachment is over
    interface_velocity_factor: wp.float64
    torque_arm: wp.float64
    initial_age: wp.float64


MEMBER_PARAM_NAMES = tuple(MemberParams.vars.keys())


@wp.struct
class SolverSettings:
    rtol: wp.float64
    initial_step: wp.float64
    min_step: wp.float64
    max_step: wp.float64
    newton_tol: wp.float64
    switch_rtol: wp.float64  # relative tolerance of the gate-switch location (rtol * switch_tol)
    sliding_width: wp.float64  # relative width of the regularised gate of nodes sliding on the yield surface
    max_steps: wp.int32
    newton_max_iter: wp.int32


# how the detachment velocity w is read from the pad velocity u_t (docs/model.md, "Fronts")
FRONT_AGAINST_DISC = 0  # w = -sign(v_max) * u_t: the pad springing back as the interface lets go
FRONT_WITH_DISC = 1  # w = sign(v_max) * u_t
FRONT_ABSOLUTE = 2  # w = |u_t|
FRONT_DIRECTIONS = ("against_disc", "with_disc", "absolute")

# fields that Record can sample (first index of the record array)
RECORD_FIELDS = ("velocity", "slip_rate", "normal_stress", "friction_stress")


@wp.struct
class OutputSettings:
    """What the integrator records besides mu_s."""

    front_direction: wp.int32  # FRONT_* code
    fronts: wp.int32  # 1: track the detachment velocity (event maximum and arrival times)
    n_record_times: wp.int32  # length of the field-recording time grid (0: no recording)
    front_threshold: wp.float64  # arrival level as a fraction of the event maximum


@wp.struct
class IntegratorState:
    """Per-member integrator state that persists between launches, and the in-kernel reductions."""

    t: wp.float64  # s, time of the state
    h: wp.float64  # s, next step size
    delta0: wp.float64  # m, mean compression of the pad
    tilt: wp.float64  # rad, tilt a of the backing plate
    mu_s: wp.float64  # static friction coefficient (running maximum, refined)
    mu_s_time: wp.float64  # s
    t1: wp.float64  # last two accepted (t, mu) points, for the parabolic refinement
    mu1: wp.float64
    t2: wp.float64
    mu2: wp.float64
    mu_final: wp.float64  # friction coefficient at the last accepted step
    npts: wp.int32
    steps_accepted: wp.int32
    steps_rejected: wp.int32
    newton_iterations: wp.int32
    newton_failures: wp.int32
    status: wp.int32
    lift_off: wp.int32
    fsal: wp.int32  # slot of K holding f(y_n)
    restart: wp.int32  # 1: next step is a backward-Euler (re)start
    last_failure_non_finite: wp.int32
    done: wp.int32
    front_max: wp.float64  # m/s, running maximum of the detachment velocity w over nodes and the window
    front_level: wp.float64  # m/s, arrival level (threshold * event maximum of a first pass); inf: none
    front_last: wp.float64  # s, last accepted time with max_x w >= threshold * running maximum (pass 1)
    front_now: wp.float64  # m/s, max over nodes of w at the last accepted step (pass 1)
    front_until: wp.float64  # s, the arrival pass stops here (front_last of pass 1); inf in pass 1
    switch_limit: wp.float64  # s, steps end at or before this time (a gate switch located in a rejected step)
    gate_switches: wp.int32  # accepted gate switches (stress gate)
    switch_retries: wp.int32  # consecutive steps rejected to locate a gate switch
    unlocated_switches: wp.int32  # steps accepted with a switch error > 1 after MAX_SWITCH_RETRIES
    record_slot: wp.int32  # index among the recorded members, -1: not recorded
    record_next: wp.int32  # next index of the recording time grid
