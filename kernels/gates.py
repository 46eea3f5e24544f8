"""The stress gate's state between steps (docs/model.md, "Gate switches"): each node's yield gate is
held over a step; a switch inside a step is located by rejecting the step and retrying up to just
past it; after an accepted step each node's regime (closed, open, sliding on the yield surface) is
chosen for the next one and the FSAL derivatives are corrected in closed form.

``make_gates(ft, model, terms, team)`` builds the functions for one working precision and model; with
another law than the stress gate they compile to constants (gate 1, not sliding). It composes one
factory per part: ``make_node_gates`` (the gate a node holds over a step), ``make_switch_test`` (the
end-of-step test), ``make_switch_location`` (retries and predicted step ends) and
``make_gate_update`` (the regimes after an accepted step, with ``make_contact_arrival``).
"""

import warp as wp

from .controller import STEP_AT_SWITCH
from .model_terms import disc_velocity_at
from .reductions import crossing_time_quadratic
from .types import (
    C_PHI, C_TAU, C_V, EV_CONTACT, G_DMARGIN, G_GATE, G_GATE_END, G_MARGIN, G_MARGIN_END, G_MARGIN_OLD, G_SLIDE, IntegratorState,
    MemberParams, OutputSettings, SolverSettings,
)

# a gate switch that MAX_SWITCH_RETRIES retries could not place within its tolerance (a strongly
# curved margin makes the linear crossing estimate creep towards it, like regula falsi) is accepted
# at the end of the step and counted in unlocated_switches: the cost of one is bounded
MAX_SWITCH_RETRIES = 8
# predicted switches (Solver.predict_switches): consecutive predictions that did not happen before
# predictions stop until the next switch; the "no prediction" value of SwitchTest.next_switch (s)
MAX_PREDICTION_MISSES = 2
NO_PREDICTION = 1.0e30


def make_node_gates(ft, model):
    """Each node's yield gate and sliding flag over the current step, read from the gates array
    (constants 1 and 0 for the gate-less and velocity laws)."""
    stress_gate = model.relaxation_gate == "stress"
    array3 = wp.array3d(dtype=ft)

    @wp.func
    def node_gate(gates: array3, i: int, m: int):
        """The yield gate of node i over the current step (1 for the gate-less and velocity laws)."""
        if wp.static(stress_gate):
            return gates[G_GATE, i, m]
        return ft(1.0)

    @wp.func
    def node_sliding(gates: array3, i: int, m: int):
        """1 where node i slides on the yield surface (stress gate), else 0."""
        if wp.static(stress_gate):
            return gates[G_SLIDE, i, m]
        return ft(0.0)

    return dict(node_gate=node_gate, node_sliding=node_sliding)


def make_switch_test(ft, model, terms, team, node_sliding):
    """The gate-switch test at the end of a step: each node's yield margin against the gate it held
    (test_switch), combined over the team (team_switch_test), as a SwitchTest."""
    viscous = bool(model.viscous_friction)
    Coeffs = terms["Coeffs"]
    Friction = terms["Friction"]
    yield_margin = terms["yield_margin"]
    team_max = team["team_max"]
    team_min = team["team_min"]
    array3 = wp.array3d(dtype=ft)

    @wp.struct
    class SwitchTest:
        """A step's gate-switch test: its error (1 = the tolerance), the fraction of the step to
        retry with (1: no retry), and the predicted end of the next step (s after this step's end;
        NO_PREDICTION: none): just past the earliest gate switch that the nodes' margins predict."""

        error: ft
        retry_fraction: ft
        next_switch: ft

    @wp.func
    def no_switch():
        test = SwitchTest()
        test.error = ft(0.0)
        test.retry_fraction = ft(1.0)
        test.next_switch = ft(NO_PREDICTION)
        return test

    @wp.func
    def test_switch(
        c: Coeffs, settings: SolverSettings, gates: array3, i: int, m: int, fr: Friction, sigma: ft,
        velocity: ft, v_disc: ft, h: ft, test: SwitchTest,
    ):
        """At the end of a step of size h, node i: store the yield margin z1 (gates[G_MARGIN_END]) and,
        where the node switched (the only place switch_gates reads it), the slope of its rate with
        respect to the gate (gates[G_DMARGIN]), and fold the node into the step's switch test.

        Where z1 has the other sign than the gate held, the switch happened inside the step, at the
        fraction theta = z0/(z0 - z1) (linear in time); the relaxation then ran with the wrong gate
        over (1 - theta)*h, a local error of (1 - theta)*h*(|tau_el|, phi)*|s|/D. Its error-weighted
        size (like the step's error norm) is the switch error; > 1 rejects the step, and the retry
        ends where that error is 0.5."""
        rtol = ft(wp.min(settings.switch_rtol, wp.float64(1.0e30)))
        z1 = yield_margin(c, fr.stress, fr.area, sigma)
        gates[G_MARGIN_END, i, m] = z1
        slip = v_disc - c.kif * velocity
        relax = wp.abs(slip) * c.inv_D
        open_now = ft(0.0)
        if z1 > ft(0.0):
            open_now = ft(1.0)
        if node_sliding(gates, i, m) == ft(0.0):
            z0 = gates[G_MARGIN, i, m]
            # the switch error per second of wrong gate
            rate = wp.max(
                wp.abs(fr.elastic_stress) * relax / (rtol * (c.tau_scale + wp.abs(fr.elastic_stress))),
                fr.contact_age * relax / (rtol * (c.phi_scale + wp.abs(fr.contact_age))),
            )
            if open_now != fr.gate:
                # d(dz/dt)/d(gate) at the end of the step: the gate enters the rates of tau_el and phi
                # (and A through phi); the pad's rates do not depend on it. switch_gates reads it where
                # the gate changes, which for a node not sliding is here (its new gate is open_now)
                darea_dgate = fr.contact * sigma * c.inv_hardness * c.b / (c.phi0 + fr.contact_age) * (-fr.contact_age * relax)
                dtau_dgate = -fr.elastic_stress * relax
                if wp.static(viscous):
                    dtau_dgate += c.eta_vstar * wp.sign(slip) * wp.log(ft(1.0) + wp.abs(slip) / c.vstar) * darea_dgate
                gates[G_DMARGIN, i, m] = wp.sign(fr.stress) * dtau_dgate - c.tau_c * darea_dgate
                theta = ft(0.0)
                if z0 != z1:
                    theta = wp.clamp(z0 / (z0 - z1), ft(0.0), ft(1.0))
                e = (ft(1.0) - theta) * h * rate
                test.error = wp.max(test.error, e)
                if e > ft(1.0):
                    test.retry_fraction = wp.min(test.retry_fraction, theta + ft(0.5) * (ft(1.0) - theta) / e)
            elif rate > ft(0.0) and h > ft(0.0) and z0 != z1:
                # no switch in this step: where the margin's secant over the step reaches 0, the node
                # will switch; a step that ends 0.5/rate after that (a switch error of 0.5, where a
                # located retry would end) takes the switch without a rejected step
                slope = (z1 - z0) / h
                if (z1 < ft(0.0) and slope > ft(0.0)) or (z1 > ft(0.0) and slope < ft(0.0)):
                    test.next_switch = wp.min(test.next_switch, -z1 / slope + ft(0.5) / rate)
        return test

    @wp.func
    def team_switch_test(test: SwitchTest):
        """The step's switch test over the team: the largest error, the smallest retry fraction."""
        out = SwitchTest()
        out.error = team_max(test.error)
        out.retry_fraction = team_min(test.retry_fraction)
        out.next_switch = team_min(test.next_switch)
        return out

    return dict(SwitchTest=SwitchTest, no_switch=no_switch, test_switch=test_switch,
                team_switch_test=team_switch_test)


def make_switch_location(ft, SwitchTest):
    """The step-size side of the gate switches: retry a step up to a located switch (locate_switch),
    and after an accepted step count missed predictions and set the next predicted step end
    (after_accept, drop_stale_limit)."""

    @wp.func
    def locate_switch(st: IntegratorState, settings: SolverSettings, t: wp.float64, h: wp.float64, test: SwitchTest):
        """A step that passed the error test but not the switch test: return (st, 1) to retry it up to
        just past the switch (st.switch_limit; the error-controlled st.h is kept), or (st, 0) to
        accept it, counting an unlocated switch when the retries are spent."""
        if test.error > ft(1.0):
            if wp.float64(test.retry_fraction) * h > settings.min_step and st.switch_retries < MAX_SWITCH_RETRIES:
                st.steps_rejected = st.steps_rejected + 1
                st.switch_retries = st.switch_retries + 1
                st.rejected_switch = st.rejected_switch + 1
                st.switch_limit = t + wp.float64(test.retry_fraction) * h
                st.switch_predicted = 0
                return st, 1
            st.unlocated_switches = st.unlocated_switches + 1
        return st, 0

    @wp.func
    def drop_stale_limit(st: IntegratorState, t_new: wp.float64):
        """After every accepted step and its observers: a step limit that the step reached (a
        backward-Euler (re)start has no after_accept) or any limit when the step ended on the sudden
        stop (st.restart set: the load jumps, so a prediction made before it says nothing after it)
        is dropped."""
        if t_new >= st.switch_limit or st.restart != 0:
            st.switch_limit = wp.float64(1.0e300)
            st.switch_predicted = 0
        return st

    @wp.func
    def after_accept(st: IntegratorState, settings: SolverSettings, switches_before: int, test: SwitchTest,
                     t_new: wp.float64, clipped: int):
        """Bookkeeping of the switch location after an accepted step with a switch test (not a
        backward-Euler (re)start; ``clipped``: the step's clipping code, kernels/controller.py), and
        the end of the next step at a predicted switch.

        A prediction that did not happen (the step clipped at it switched nothing) counts a miss;
        after MAX_PREDICTION_MISSES in a row predictions stop until the next switch, so that a margin
        that only approaches 0 (e.g. a steady state just below the yield stress) cannot hold the
        step size down. A predicted limit never replaces a located one (a rejected step's)."""
        switched = st.gate_switches != switches_before
        if switched or test.error > ft(1.0):
            st.switch_retries = 0  # the located switch happened (or was given up)
        if switched:
            st.prediction_misses = 0
        elif clipped == STEP_AT_SWITCH and st.switch_predicted == 1:
            st.prediction_misses = st.prediction_misses + 1
            st.missed_predictions = st.missed_predictions + 1
        st = drop_stale_limit(st, t_new)  # st.restart is 0 here: the limit this step reached
        located_pending = st.switch_limit < wp.float64(1.0e300) and st.switch_predicted == 0
        predict = settings.predict_switches == 1 and st.prediction_misses < MAX_PREDICTION_MISSES
        # a located retry that ended before the switch (regula falsi creeping towards a curved crossing):
        # the margin's secant over this step, on the near side, is the next step's end, with or
        # without predictions
        creeping = st.switch_retries > 0 and not switched
        if (predict or creeping) and not located_pending:
            if test.next_switch < ft(NO_PREDICTION):
                limit = t_new + wp.float64(test.next_switch)
                if limit < st.switch_limit:
                    st.switch_limit = limit
                    # a prediction where predictions are on (a miss counts); located-only, the
                    # continuation of the located switch
                    st.switch_predicted = settings.predict_switches
        return st

    return dict(locate_switch=locate_switch, drop_stale_limit=drop_stale_limit, after_accept=after_accept)


@wp.func
def margin_crossing(t_old: wp.float64, t_new: wp.float64, z0: wp.float64, z1: wp.float64):
    """The yield margin's linear crossing of 0 in the step (t_old, t_new], s, from its values z0 at
    the step's start and z1 at its end (Pa); the step's start where the margin is not above 0 at
    the end (switch_gates records openings only where it is). A node's yield_time, and the linear
    crossing against which the contact arrival measures its error (contact_arrival)."""
    theta = wp.float64(0.0)
    if z0 != z1 and z1 > wp.float64(0.0):
        theta = wp.clamp(z0 / (z0 - z1), wp.float64(0.0), wp.float64(1.0))
    return t_old + theta * (t_new - t_old)


def make_contact_arrival(ft):
    """The contact front's arrival time at a node whose gate opened in a step (contact_arrival)."""

    @wp.func
    def contact_arrival(p: MemberParams, st: IntegratorState, t_old: wp.float64, t_new: wp.float64, z_prev: ft,
                        z0: ft, z1: ft, backward_euler: int):
        """The contact front's arrival at a node whose gate first opened in the step (t_old, t_new]
        after the disc started: (time, error estimate) in s. The yield margin's crossing of 0 on the
        quadratic through the margins at the last three accepted points (t_prev = st.t2, t_old, t_new),
        and its distance to the linear crossing (the yield_time rule) as the error; the linear
        crossing with the whole step as the error after a (re)start, where no earlier point belongs
        to the same smooth piece (or where the margin is not above 0 at the step's end, which
        switch_gates does not pass).
        (nan, nan) outside the window from the disc start to the stop."""
        if t_new <= p.rest_until or t_old >= p.stop_time:
            return wp.float64(wp.nan), wp.float64(wp.nan)
        zp = wp.float64(z_prev)
        za = wp.float64(z0)
        zb = wp.float64(z1)
        t_lin = margin_crossing(t_old, t_new, za, zb)
        t_prev = st.t2
        if backward_euler == 0 and st.npts >= 2 and t_prev < t_old and za < wp.float64(0.0) and zb > wp.float64(0.0):
            # crossing_time_quadratic takes the middle point at a fraction c_mid of its interval:
            # the interval (t_prev, t_new) with t_old inside
            c_mid = (t_old - t_prev) / (t_new - t_prev)
            t_quad, _unused = crossing_time_quadratic(wp.float64(0.0), t_prev, zp, c_mid, za, t_new, zb)
            if t_quad >= t_old and t_quad <= t_new:
                return t_quad, wp.abs(t_quad - t_lin)
        return t_lin, t_new - t_old

    return dict(contact_arrival=contact_arrival)


def make_gate_update(ft, terms, team):
    """After an accepted step: each node's gate regime for the next step, the FSAL correction, the
    stick-to-slip time (yield_time) and the contact front's arrival (switch_gates)."""
    Coeffs = terms["Coeffs"]
    team_count = team["team_count"]
    contact_arrival = make_contact_arrival(ft)["contact_arrival"]
    array3 = wp.array3d(dtype=ft)
    array4 = wp.array4d(dtype=ft)

    @wp.func
    def gate_regime(gate: ft, sliding: ft):
        """0: closed, 1: sliding on the yield surface, 2: open."""
        if sliding > ft(0.0):
            return 1
        if gate >= ft(1.0):
            return 2
        return 0

    @wp.func
    def switch_gates(
        c: Coeffs, p: MemberParams, st: IntegratorState, outputs: OutputSettings, m: int, n: int, state: array3,
        K: array4, slot: int, gates: array3, t_old: wp.float64, t_new: wp.float64,
        backward_euler: int, yield_time: wp.array2d(dtype=wp.float64), arrival: wp.array3d(dtype=wp.float64),
        arrival_error: wp.array3d(dtype=wp.float64),
    ):
        """After an accepted step (state advanced): choose each node's gate regime for the next step
        from its end-of-step yield margin z1, store the margin, correct the FSAL derivatives K[slot] of
        the nodes whose gate changed (the gate enters only the relaxation rates of tau_el and phi,
        closed-form in the state) and record the stick-to-slip transition's time (yield_time: the
        first opening after the disc started, linear in the margin: the margin's first crossing of 0
        from below, for a node in the sliding regime too; openings in the loading phase, where the
        margin of a node at a contact edge can graze 0, are not recorded).

        A closed or open node takes the Heaviside theta(z1), unless it crossed the yield surface
        z = 0 into a side whose field points back (Filippov sliding): the margin's rate is affine in
        the gate, dz/dt(g) = r_obs + (g - g_old)*dr, r_obs seen over the step and dr = d(dz/dt)/dg
        at its end (gates[G_DMARGIN]); with dr < 0 and the far side's rate of opposite sign the node
        slides. A sliding node's gate is solved in every stage from |tau_f| = tau_c*A
        (interface_friction), pinned at 1 or 0 where that cannot hold; the node keeps that implicit
        regime for the rest of the run. With the contact front (outputs.contact_front), a node whose
        gate opens after the disc started, for the first time in that window, records its arrival
        (contact_arrival; its window ends at the disc's stop): the event of yield_time, so that the
        two agree to the arrival's error. st.stuck_nodes counts the nodes in contact (margin below 0)
        that have not opened since the disc started, closed or in the sliding regime (the automatic end
        waits for them: observers.py detachment_over).
        The lane's nodes; the switches are counted over the team (which is also a barrier: no lane
        reads another lane's gates)."""
        v_disc = ft(disc_velocity_at(p, t_new, t_old))
        h = ft(t_new - t_old)
        switches = int(0)
        stuck = int(0)
        for i in range(c.first_node, c.end_node):
            z1 = gates[G_MARGIN_END, i, m]
            z0 = gates[G_MARGIN, i, m]
            sliding = gates[G_SLIDE, i, m]
            gate_start = gates[G_GATE, i, m]
            gate = gate_start
            new_sliding = ft(0.0)
            new_gate = ft(0.0)
            if sliding > ft(0.0):
                # a sliding node stays in the implicit regime: where |tau_f| = tau_c*A cannot hold, its
                # solved gate is pinned at 1 (open) or 0 (closed), which is the Heaviside value; leaving
                # the regime would only trade the implicit gate for repeated located switches
                gate = gates[G_GATE_END, i, m]  # the last stage's solved gate: K[slot] is consistent with it
                new_gate = gate
                new_sliding = ft(1.0)
            else:
                if z1 > ft(0.0):
                    new_gate = ft(1.0)
                if new_gate != gate:  # the node switched: test_switch stored the slope dr for it
                    dr = gates[G_DMARGIN, i, m]
                    if dr < ft(0.0) and h > ft(0.0):
                        r_obs = (z1 - z0) / h
                        rate_far = r_obs + (ft(1.0) - ft(2.0) * gate) * dr  # the rate with the other gate value
                        if (gate == ft(0.0) and rate_far < ft(0.0)) or (gate == ft(1.0) and rate_far > ft(0.0)):
                            new_sliding = ft(1.0)
                            new_gate = wp.clamp(gate + (-z1 / h - r_obs) / dr, ft(0.0), ft(1.0))  # start value
            if new_gate != gate:
                relax = (new_gate - gate) * wp.abs(v_disc - c.kif * state[C_V, i, m]) * c.inv_D
                K[slot, C_TAU, i, m] = K[slot, C_TAU, i, m] - state[C_TAU, i, m] * relax
                K[slot, C_PHI, i, m] = K[slot, C_PHI, i, m] - state[C_PHI, i, m] * relax
            if gate_regime(new_gate, new_sliding) != gate_regime(gate, sliding):
                switches += 1
            # an opening, the stick-to-slip transition, is the yield margin crossing 0 at a node that
            # sticks: a closed node in contact (z0 < 0; a node out of contact without friction stress
            # has z = 0) has gate 0 at the step's start and above 0 at its end (it opens or enters
            # the sliding regime, z1 > 0); a node in the sliding regime crosses where its margin does
            # (its regularised gate theta_w's midpoint, 1/2), not where its gate leaves 0: theta_w's
            # tail ~exp(2x) leaves 0 far below the yield surface (1e-12 at a margin of -15 kPa, where
            # the node still sticks). yield_time and the contact front read the gates only there
            opened = False
            if sliding > ft(0.0):
                opened = z0 <= ft(0.0) and z1 > ft(0.0)
            else:
                opened = gate_start == ft(0.0) and new_gate > ft(0.0) and z0 < ft(0.0)
            if opened and t_new > p.rest_until:
                if not wp.isfinite(yield_time[i, m]):
                    yield_time[i, m] = margin_crossing(t_old, t_new, wp.float64(z0), wp.float64(z1))
            if outputs.contact_front == 1 and opened:
                if not wp.isfinite(arrival[EV_CONTACT, i, m]):
                    t_cross, t_err = contact_arrival(p, st, t_old, t_new, gates[G_MARGIN_OLD, i, m], z0, z1,
                                                     backward_euler)
                    arrival[EV_CONTACT, i, m] = t_cross
                    arrival_error[EV_CONTACT, i, m] = t_err
            gates[G_GATE, i, m] = new_gate
            gates[G_SLIDE, i, m] = new_sliding
            gates[G_MARGIN_OLD, i, m] = z0
            gates[G_MARGIN, i, m] = z1
            # still stuck: in contact below the yield threshold (z1 < 0: a node without contact area
            # has z = 0 or carries a stress, z > 0) and not opened since the disc started. Below it a
            # closed node's gate is 0; a node in the sliding regime sticks there too, whatever the
            # tail of its regularised gate (~exp(2x), not exactly 0)
            if z1 < ft(0.0) and not wp.isfinite(yield_time[i, m]):
                stuck += 1
        st.gate_switches = st.gate_switches + team_count(switches)
        st.stuck_nodes = team_count(stuck)
        return st

    return dict(switch_gates=switch_gates)


def make_gates(ft, model, terms, team):
    """The stress gate's functions for one working precision and model, by part: the node gates,
    the switch test, the switch location and the gate update."""
    node_gates = make_node_gates(ft, model)
    test = make_switch_test(ft, model, terms, team, node_gates["node_sliding"])
    location = make_switch_location(ft, test["SwitchTest"])
    update = make_gate_update(ft, terms, team)
    return dict(SwitchTest=test["SwitchTest"], drop_stale_limit=location["drop_stale_limit"],
                no_switch=test["no_switch"], team_switch_test=test["team_switch_test"],
                node_gate=node_gates["node_gate"], node_sliding=node_gates["node_sliding"],
                test_switch=test["test_switch"], locate_switch=location["locate_switch"],
                switch_gates=update["switch_gates"], after_accept=location["after_accept"])
