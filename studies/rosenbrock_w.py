"""Does a Rosenbrock-W method pay under the stress gate? A float64 NumPy prototype (issue 21, part 3).

    python studies/rosenbrock_w.py [--nodes 40] [--eccentricities 0 -0.2] [--end-time 20.3]
                                   [--rtols 1e-4 1e-5 1e-6 1e-7] [--ref-rtol 1e-9]
                                   [--methods trbdf2 ros34pw2 ros23] [--predict] [--no-engine]
                                   [--out studies/results/rosenbrock_w_cpu.json]
    python studies/rosenbrock_w.py --check     # the tableau checks only (a few seconds)

One member of the default scene (F = 1000 N, e = 0 and -0.2), default law (stress gate), N nodes,
t = 0..end_time (20.3 s: just past the mu_s peak at ~20.232 s, in place of the engine's automatic
end), integrated by three methods that share everything except the step itself:

- trbdf2:   the engine's TR-BDF2 with full Newton (esdirk_order.py `attempt`: exact Jacobian and a
            fresh LU every iteration, newton_tol 0.03, <= 8 iterations), its error estimate filtered
            in the velocity rows by (I - gamma h J)^-1, as in esdirk_order.py;
- ros34pw2: the Rosenbrock-W method ROS34PW2 of Rang & Angermann (BIT 45, 2005; the coefficients as
            PETSc TSROSWRA34PW2): 4 stages, order 3, embedded order 2, L-stable, stiffly accurate;
            one Jacobian and one LU per step, 4 substitutions, 3 stage evaluations of f; written
            in the transformed variables u_i = sum_j gamma_ij k_j (Hairer-Wanner IV.7), so that a
            stage needs no J-vector product: (I/(gamma h) - J) u_i = f(t + alpha_i h, y + sum a_ij
            u_j) + sum (c_ij/h) u_j + gamma_i h f_t;
- ros23:    the Rosenbrock-W pair of Shampine & Reichelt (ode23s, OrdinaryDiffEq Rosenbrock23):
            order 2 with a third-stage error estimate; one Jacobian and one LU per step, 3
            substitutions, 2 evaluations of f (the second, at y_new, also gives the switch test).

Common to all (modelled on the kernels): the controller h_next = h*clamp(0.9*err^(-1/3), 0.2, 5)
(every estimate here is O(h^3): TR-BDF2's, ROS34PW2's 3(2) pair and Rosenbrock23's), a rejected
step shrinks by >= 0.9, a failed solve by 0.25; breakpoints hit with the engine's rule (esdirk_order
`next_breakpoint`); within a step the protocol is the smooth continuation of its piece; error norm
max |e|/(rtol*(scale + max(|y|, |y_new|))). The Rosenbrock estimates are not filtered (standard
practice for L-stable pairs; both embedded solutions are A-stable, see the tableau check). f_t (the
ramps of F and v_d) enters the Rosenbrock stages exactly as the method prescribes; here it is a
central difference of f in t (not counted as work: in a kernel it is one more analytic column of
the Jacobian, inside L).

Stress gate (docs/model.md "Gate switches", kernels/gates.py), the same for every method:
- held per step: node i's gate g_i in {0, 1} is fixed over an attempt; r = g_i |s| in tau_el' and
  phi'; the Jacobian has g_i * d|s|/ds and no derivative of the Heaviside;
- tested at the step end: the yield margin z1 = |tau_f| - tau_c A at y_new against the gate held;
  a node whose sign disagrees switched at theta = z0/(z0 - z1) (z0: the margin at the step start),
  switch error (1 - theta) h rate, rate = max(|tau_el| |s|/D / (srtol (tau_scale + |tau_el|)),
  phi |s|/D / (srtol (phi_scale + phi))), srtol = switch_tol*rtol (kernels/gates.py `test_switch`,
  the same formula); a step with error test <= 1 and switch error > 1 is retried to end at
  t + h*min_i(theta_i + 0.5 (1 - theta_i)/e_i) (`locate_switch`: at most 8 retries, then accepted
  as an unlocated switch); the error-controlled h is kept, and the retried step is clipped there
  (kernels/controller.py `propose_step`); after an accepted step each node takes the Heaviside
  theta(z1), and the first derivative of the next step is re-evaluated with the new gates;
- --predict adds the engine's predicted switches (`after_accept`: the margin's secant over the step
  extended to 0 plus 0.5/rate, two misses in a row stop predictions until the next switch).
  Default off: located switches only (predict_switches=False in the engine).
- simplification: no Filippov sliding regime (kernels/gates.py `switch_gates`); the driver counts
  the accepted steps where the engine's sliding condition would hold (sliding_candidates) so that
  this is checked, not assumed.

Kinks in the Jacobian (the same code for every method: FastPad.f): |s| in r = g|s| and in the
viscous term, and lift-off max(sigma, 0), are differentiated on the side where the state lies
(sign(s); contact = sigma >= 0), i.e. one-sided derivatives at the kink; at exactly s = 0 sign(0) =
0. A W-method's order does not depend on J, so a one-sided J costs stability margin only.

Work units (../shared/perf/kernel-study.md 2.2; estimates of an optimised kernel, instructions per
node): L ~ 250 (friction law with derivatives + stencil + Jacobian row + Thomas row: one bordered
tridiagonal solve with a fresh factorization), F ~ 150 (f evaluation), S ~ 20 (a substitution with
a stored factorization), C ~ 20 (a vector pass: stage combination, update, norm). Counted per
attempt (accepted or rejected):
- trbdf2: L = Newton iterations; S = 1 (the velocity filter of the estimate); F = 1 (the end-of-step
  evaluation of the margin, mu and the next first stage: the engine's stage_derivatives, which does
  two); C = Newton iterations (update + norm) + 4 (two stage starts, estimate, error norm);
- ros34pw2: L = 1; F = 3 (stages 2-4) + 1 (end of step, as TR-BDF2); S = 4; C = 4 (stage arguments)
  + 3 (y_new, estimate, error norm);
- ros23: L = 1; F = 2 (its f at y_new serves the end of step); S = 3; C = 3 + 2.
work = 250 L + 150 F + 20 S + 20 C per node.

mu_s (esdirk_order.py `mu_readings`, the same for every method): mu at every accepted point;
'parabola' (the engine's reading, primary): the largest of the accepted points refined by the
parabola through three consecutive accepted points; 'dense': the maximum of mu along the cubic
Hermite of y around the largest point; 'stepped': one step of the method itself from the accepted
point before the dense maximum to its time. Errors relative to the reference (TR-BDF2 at
--ref-rtol, same N, same gate treatment, parabola reading); mu_s_time errors absolute (s).

A fourth accuracy measure, free of how a reading refines the peak: 'mu(t)', the largest error of mu
at the run's accepted points after the disc starts (against the reference's Hermite). Steps by
phase: start-up (t < 1 ms), force ramp, rest, disc sliding before the gates open (to 20.12 s), the
switching window (20.12-20.14 s: the 40 gates open there at N = 40), after it.

Prints one JSON line per run, then per scene the table of runs and the work-precision table: the
weighted work (and L, attempts) at mu_s error 1e-5, 1e-6, 1e-7 (log-log interpolation along each
method's rtol sweep, esdirk_order `at_error`) and its ratio to TR-BDF2. Writes --out.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy.linalg import lu_factor, lu_solve  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from baseline_scipy import PadODE  # noqa: E402
from esdirk_order import (  # noqa: E402
    FAILURE_FACTOR, INITIAL_STEP, MAX_FACTOR, MAX_STEP, MIN_FACTOR, MIN_STEP, SAFETY, FastPad, at_error, attempt,
    hermite, mu_readings, next_breakpoint, tableau_trbdf2,
)

import warpfric as wf  # noqa: E402

WORK = dict(L=250.0, F=150.0, S=20.0, C=20.0)  # kernel-study.md 2.2, instructions per node
MAX_SWITCH_RETRIES = 8  # kernels/gates.py
MAX_PREDICTION_MISSES = 2
ERROR_EXPONENT = -1.0 / 3.0

# ------------------------------------------------------------------------------------------------
# Rosenbrock tableaus and their checks
# ------------------------------------------------------------------------------------------------


def tableau_ros34pw2():
    """ROS34PW2 (Rang & Angermann 2005), as PETSc TSROSWRA34PW2: alpha (strictly lower), Gamma (lower,
    gamma on the diagonal), b (order 3), bhat (order 2)."""
    g = 4.3586652150845900e-01
    alpha = np.zeros((4, 4))
    alpha[1, 0] = 8.7173304301691801e-01
    alpha[2, 0] = 8.4457060015369423e-01
    alpha[2, 1] = -1.1299064236484185e-01
    alpha[3, 2] = 1.0
    Gam = np.diag([g] * 4)
    Gam[1, 0] = -8.7173304301691801e-01
    Gam[2, 0] = -9.0338057013044082e-01
    Gam[2, 1] = 5.4180672388095326e-02
    Gam[3, 0] = 2.4212380706095346e-01
    Gam[3, 1] = -1.2232505839045147e+00
    Gam[3, 2] = 5.4526025533510214e-01
    b = np.array([2.4212380706095346e-01, -1.2232505839045147e+00, 1.5452602553351020e+00, 4.3586652150845900e-01])
    bhat = np.array([3.7810903145819369e-01, -9.6042292212423178e-02, 5.0000000000000000e-01, 2.1793326075422950e-01])
    return make_rosenbrock("ros34pw2", alpha, Gam, b, bhat, order=3, embedded_order=2)


def tableau_ros23():
    """Rosenbrock23 (Shampine & Reichelt 1997) as a dict for the checks: its order-2 solution is a
    2-stage Rosenbrock-W method (alpha21 = 1/2, gamma = 1/(2 + sqrt 2), gamma21 = -gamma, b = (0, 1));
    the third stage (error estimate) is written out in ros23_attempt."""
    d = 1 / (2 + math.sqrt(2))
    alpha = np.array([[0, 0], [0.5, 0]])
    Gam = np.array([[d, 0], [-d, d]])
    b = np.array([0.0, 1.0])
    return make_rosenbrock("ros23", alpha, Gam, b, None, order=2, embedded_order=None)


def make_rosenbrock(name, alpha, Gam, b, bhat, order, embedded_order):
    Gi = np.linalg.inv(Gam)
    g = Gam[0, 0]
    a = alpha @ Gi
    C = np.tril(np.diag(1 / np.diag(Gam)) - Gi, -1)
    tb = dict(name=name, alpha=alpha, Gamma=Gam, b=b, bhat=bhat, gamma=g, a=a, C=C, m=b @ Gi,
              ci=alpha.sum(1), gi=Gam.sum(1), order=order, embedded_order=embedded_order, stages=len(b))
    tb["mhat"] = None if bhat is None else bhat @ Gi
    return tb


def order_conditions(tb, w, p):
    """Residuals of the Rosenbrock (exact J) and W-method (any matrix W) order conditions up to order
    p for weights w (Hairer-Wanner II, IV.7: trees with f-vertices (alpha) and W-vertices (Gamma,
    diagonal included); with W = J the two merge into the Rosenbrock conditions, beta = alpha + Gamma)."""
    al, G, g = tb["alpha"], tb["Gamma"], tb["gamma"]
    e = np.ones(len(w))
    ae, Ge = al @ e, G @ e
    bp = (al + G - g * np.eye(len(w))) @ e  # beta'_i = sum_{j<i} beta_ij
    Bs = np.tril(al + G, -1)
    ros = {"b.e = 1": w @ e - 1}
    wm = {"b.e = 1": w @ e - 1}
    if p >= 2:
        ros["b.beta' = 1/2 - g"] = w @ bp - (0.5 - g)
        wm.update({"b.alpha e = 1/2": w @ ae - 0.5, "b.Gamma e = 0": w @ Ge})
    if p >= 3:
        ros.update({"b.(alpha e)^2 = 1/3": w @ ae**2 - 1 / 3, "b.beta beta' = 1/6 - g + g^2": w @ (Bs @ bp) - (1 / 6 - g + g * g)})
        wm.update({"b.(alpha e)^2 = 1/3": w @ ae**2 - 1 / 3, "b.alpha alpha e = 1/6": w @ (al @ ae) - 1 / 6,
                   "b.alpha Gamma e = 0": w @ (al @ Ge), "b.Gamma alpha e = 0": w @ (G @ ae), "b.Gamma Gamma e = 0": w @ (G @ Ge)})
    return {k: float(v) for k, v in ros.items()}, {k: float(v) for k, v in wm.items()}


def stability(tb, w):
    B = tb["alpha"] + tb["Gamma"]
    e = np.ones(len(w))

    def R(z):
        return 1 + z * w @ np.linalg.solve(np.eye(len(w)) - z * B, e)

    return R


def ros_step_small(tb, fun, jac, ft, t, y, h):
    """One constant step of a Rosenbrock tableau (transformed form) on a small dense system; jac(t, y)
    may be any matrix (W-method). Returns (y_new, y_embedded or None)."""
    g = tb["gamma"]
    f0 = fun(t, y)
    W = np.eye(y.size) / (g * h) - jac(t, y)
    fT = ft(t, y)
    U = []
    for i in range(tb["stages"]):
        Yi = y + sum(tb["a"][i, j] * U[j] for j in range(i))
        fi = f0 if i == 0 else fun(t + tb["ci"][i] * h, Yi)
        rhs = fi + sum(tb["C"][i, j] / h * U[j] for j in range(i)) + tb["gi"][i] * h * fT
        U.append(np.linalg.solve(W, rhs))
    ynew = y + sum(tb["m"][i] * U[i] for i in range(len(U)))
    yhat = None if tb["mhat"] is None else y + sum(tb["mhat"][i] * U[i] for i in range(len(U)))
    return ynew, yhat


def ros23_step_small(fun, jac, ft, t, y, h):
    d = 1 / (2 + math.sqrt(2))
    e32 = 6 + math.sqrt(2)
    f0 = fun(t, y)
    W = np.eye(y.size) - h * d * jac(t, y)
    T = ft(t, y)
    k1 = np.linalg.solve(W, f0 + h * d * T)
    f1 = fun(t + 0.5 * h, y + 0.5 * h * k1)
    k2 = np.linalg.solve(W, f1 - k1) + k1
    ynew = y + h * k2
    f2 = fun(t + h, ynew)
    k3 = np.linalg.solve(W, f2 - e32 * (k2 - f1) - 2 * (k1 - f0) + h * d * T)
    return ynew, ynew - h / 6 * (k1 - 2 * k2 + k3)


def observed_orders(name, steps=(10, 20, 40, 80)):
    """Observed orders on (a) y' = -y, (b) y' = -2 t y^2, y(0) = 1 (y = 1/(1 + t^2), non-autonomous,
    nonlinear) over t = 0..1 with the exact Jacobian, and (c) the same with W = 0.5 J + 1 (a wrong
    matrix: the W-method property), of the solution and of the embedded one (or ros23's estimate)."""
    probs = {
        "linear": (lambda t, y: -y, lambda t, y: np.array([[-1.0]]), lambda t, y: np.zeros(1), lambda t: math.exp(-t)),
        "nonlinear": (lambda t, y: -2 * t * y**2, lambda t, y: np.array([[-4 * t * y[0]]]), lambda t, y: -2 * y**2,
                      lambda t: 1 / (1 + t * t)),
        "nonlinear_W": (lambda t, y: -2 * t * y**2, lambda t, y: np.array([[-2 * t * y[0] + 1.0]]), lambda t, y: -2 * y**2,
                        lambda t: 1 / (1 + t * t)),
    }
    out = {}
    for pname, (fun, jac, ft, exact) in probs.items():
        errs, errs_h = [], []
        for n in steps:
            h = 1.0 / n
            y = np.array([1.0])
            yh_err = 0.0
            for k in range(n):
                if name == "ros23":
                    ynew, yh = ros23_step_small(fun, jac, ft, k * h, y, h)
                else:
                    ynew, yh = ros_step_small(TABLEAUS[name](), fun, jac, ft, k * h, y, h)
                y = ynew
            errs.append(abs(y[0] - exact(1.0)))
            # the embedded solution's global order: integrate with it
            y = np.array([1.0])
            for k in range(n):
                if name == "ros23":
                    _, y = ros23_step_small(fun, jac, ft, k * h, y, h)
                else:
                    _, y = ros_step_small(TABLEAUS[name](), fun, jac, ft, k * h, y, h)
            errs_h.append(abs(y[0] - exact(1.0)))
        out[pname] = dict(order=[math.log2(errs[i] / errs[i + 1]) for i in range(len(errs) - 1)], errors=errs)
        if name != "ros23":  # Rosenbrock23's third stage is an error estimate, not a solution
            out[pname]["embedded_order"] = [math.log2(errs_h[i] / errs_h[i + 1]) for i in range(len(errs_h) - 1)]
    return out


def check_rosenbrock(name):
    tb = TABLEAUS[name]()
    ros_b, w_b = order_conditions(tb, tb["b"], tb["order"])
    res = dict(method=name, rosenbrock_conditions=ros_b, w_conditions=w_b,
               max_rosenbrock_residual=max(abs(v) for v in ros_b.values()),
               max_w_residual=max(abs(v) for v in w_b.values()))
    R = stability(tb, tb["b"])
    res["R_at_minus_1e8"] = float(abs(R(-1e8)))
    res["max_abs_R_on_imag_axis"] = float(max(abs(R(1j * y)) for y in np.logspace(-3, 6, 400)))
    if tb["bhat"] is not None:
        ros_h, w_h = order_conditions(tb, tb["bhat"], tb["embedded_order"])
        Rh = stability(tb, tb["bhat"])
        res.update(max_rosenbrock_residual_embedded=max(abs(v) for v in ros_h.values()),
                   max_w_residual_embedded=max(abs(v) for v in w_h.values()),
                   Rhat_at_minus_1e8=float(abs(Rh(-1e8))),
                   max_abs_Rhat_on_imag_axis=float(max(abs(Rh(1j * y)) for y in np.logspace(-3, 6, 400))))
        res["stiffly_accurate"] = bool(np.allclose((tb["alpha"] + tb["Gamma"])[-1], tb["b"], atol=1e-15))
    res["observed"] = observed_orders(name)
    return res


TABLEAUS = dict(ros34pw2=tableau_ros34pw2, ros23=tableau_ros23)

# ------------------------------------------------------------------------------------------------
# the model with the stress gate held per step
# ------------------------------------------------------------------------------------------------


class GatedPad(FastPad):
    """FastPad with the stress gate: r = g_i |s|, g_i in {0, 1} held per step (self.g)."""

    GATES = ("none", "stress")

    def __init__(self, ode: PadODE):
        super().__init__(ode)
        self.stress = ode.model.relaxation_gate == "stress"
        self.g = np.zeros(self.n) if self.stress else np.ones(self.n)
        self.tau_c = self.p.shear_strength
        self.tau_scale = self.scales[2 * self.n]
        self.phi_scale = self.p.aging_time

    def relaxation(self, s):
        return self.g * np.abs(s), self.g * np.sign(s)

    def f(self, t, y, jac=False):
        out = super().f(t, y, jac=jac)
        if jac:
            self.last_J = out[1]  # the error filter reads the diagonal blocks of the last Jacobian
        return out

    def velocity_filter(self, g):
        """The kernels' filter of the velocity's error estimate (kernels/esdirk.py fold_error):
        min(1, |rho H/(g*diag)|), diag the node's velocity pivot of the Newton matrix with u, tau_el
        and phi eliminated node-locally, i.e. per node min(1, |((I - g J)_node^-1)_vv|) of its 4 x 4
        block (u, v, tau_el, phi) of the last Jacobian (the plate's rank-2 response included)."""
        n = self.n
        idx = np.arange(n)[:, None] + n * np.arange(4)[None, :]  # (n, 4) indices of node i's components
        B = np.eye(4)[None] - g * self.last_J[idx[:, :, None], idx[:, None, :]]
        return np.minimum(1.0, np.abs(np.linalg.inv(B)[:, 1, 1]))

    def end_terms(self, t, y):
        """What the end of a step needs besides f: margin z = |tau_f| - tau_c A, |s|, tau_el, phi and
        d(dz/dt)/dg (kernels/gates.py test_switch), at (t, y)."""
        p, n = self.p, self.n
        u, v, tau, phi = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
        d = self.solve_plate(u, v, tau, phi, t)
        sigma, c, ag, alpha, area, s, L, tau_f = self._terms(u, v, tau, phi, t, d)
        z = np.abs(tau_f) - self.tau_c * area
        relax = np.abs(s) / p.memory_length
        darea_dgate = c * sigma / p.hardness * p.aging_coefficient / (p.aging_time + phi) * (-phi * relax)
        dtau_dgate = -tau * relax + self.eta_vr * L * darea_dgate
        dz_dgate = np.sign(tau_f) * dtau_dgate - self.tau_c * darea_dgate
        return z, relax, tau, phi, dz_dgate

    def f_t(self, t, y):
        """df/dt at fixed y (the ramps of F and v_d) by a central difference inside the step's piece;
        0 outside the ramps."""
        p = self.p
        tm = t if self.piece is None else self.piece
        ramp = (p.force_ramp_time > 0 and tm < p.force_ramp_time) or (p.rest_until < tm < p.rest_until + p.velocity_ramp_time)
        if not ramp:
            return np.zeros(4 * self.n)
        dt = min(1e-6, 0.5 * t) if t > 0 else 1e-6
        plate = self.plate.copy()
        fp = self.f(t + dt, y)
        self.plate = plate.copy()
        fm = self.f(max(t - dt, 0.0), y)
        self.plate = plate
        return (fp - fm) / (t + dt - max(t - dt, 0.0))


# ------------------------------------------------------------------------------------------------
# the steppers: one attempt each, with their work counts
# ------------------------------------------------------------------------------------------------


FILTER = dict(mode="engine")  # the velocity error filter of every method: engine (diagonal), full, none


def filtered(gp, e, g, lu=None):
    """The error estimate e with its velocity rows filtered (FILTER['mode']): 'engine': the kernels'
    per-node diagonal (GatedPad.velocity_filter; a vector pass, C); 'full': the v rows of (I - gJ)^-1 e
    with the step's LU (one substitution, S; esdirk_order.py's choice); 'none'. Returns (e, S, C)."""
    n = gp.n
    mode = FILTER["mode"]
    if mode == "engine":
        e = e.copy()
        e[n:2 * n] *= gp.velocity_filter(g)
        return e, 0, 1
    if mode == "full":
        ef = lu_solve(lu, e, check_finite=False)
        e = e.copy()
        e[n:2 * n] = ef[n:2 * n]
        return e, 1, 0
    return e, 0, 0


def err_norm(e, y, y_new, scales, rtol):
    err = float(np.max(np.abs(e) / (rtol * (scales + np.maximum(np.abs(y), np.abs(y_new))))))
    return err if math.isfinite(err) else 1e30


def trbdf2_attempt(gp, t, y, K1, hs, t_new, rtol, eye, tb=tableau_trbdf2()):
    ok, Y, K, lu, st, it = attempt(tb, gp, t, y, K1, hs, t_new, rtol, eye)
    counts = dict(L=it, F=0, S=0, C=it, newton=it, stages=st)
    if not ok:
        return False, None, 1e30, counts
    e, s_f, c_f = filtered(gp, hs * ((tb["b"] - tb["bhat"]) @ K), tb["gamma"] * hs, lu)
    counts.update(F=1, S=s_f, C=it + 4 + c_f)
    return True, Y, err_norm(e, y, Y, gp.scales, rtol), counts


def ros34pw2_attempt(gp, t, y, K1, hs, t_new, rtol, eye, tb=tableau_ros34pw2()):
    gp.set_step(t, t_new)
    g = tb["gamma"]
    counts = dict(L=1, F=0, S=0, C=0, newton=0, stages=0)
    try:
        with np.errstate(invalid="raise", divide="raise", over="raise"):
            f0, J = gp.f(t, y, jac=True)
            fT = gp.f_t(t, y)
            lu = lu_factor(eye - (g * hs) * J, check_finite=False)
            U = []
            for i in range(tb["stages"]):
                if i == 0:
                    fi = f0
                else:
                    Yi = y + sum(tb["a"][i, j] * U[j] for j in range(i))
                    fi = gp.f(t + tb["ci"][i] * hs, Yi)
                    counts["F"] += 1
                rhs = fi + sum(tb["C"][i, j] / hs * U[j] for j in range(i)) + (tb["gi"][i] * hs) * fT
                U.append((g * hs) * lu_solve(lu, rhs, check_finite=False))  # (I/(g h) - J)^-1 rhs
                counts["S"] += 1
                counts["C"] += 1
            y_new = y + sum(tb["m"][i] * U[i] for i in range(4))
            e = sum((tb["m"][i] - tb["mhat"][i]) * U[i] for i in range(4))
    except (np.linalg.LinAlgError, FloatingPointError, RuntimeError, ValueError):
        return False, None, 1e30, counts
    if not np.all(np.isfinite(y_new)):
        return False, None, 1e30, counts
    e, s_f, c_f = filtered(gp, e, g * hs, lu)
    counts["F"] += 1  # the end-of-step evaluation (margin, mu, next first stage)
    counts["S"] += s_f
    counts["C"] += 3 + c_f
    return True, y_new, err_norm(e, y, y_new, gp.scales, rtol), counts


def ros23_attempt(gp, t, y, K1, hs, t_new, rtol, eye):
    gp.set_step(t, t_new)
    d = 1 / (2 + math.sqrt(2))
    e32 = 6 + math.sqrt(2)
    counts = dict(L=1, F=0, S=0, C=0, newton=0, stages=0)
    try:
        with np.errstate(invalid="raise", divide="raise", over="raise"):
            f0, J = gp.f(t, y, jac=True)
            T = gp.f_t(t, y)
            lu = lu_factor(eye - (hs * d) * J, check_finite=False)
            k1 = lu_solve(lu, f0 + hs * d * T, check_finite=False)
            f1 = gp.f(t + 0.5 * hs, y + 0.5 * hs * k1)
            k2 = lu_solve(lu, f1 - k1, check_finite=False) + k1
            y_new = y + hs * k2
            f2 = gp.f(t_new, y_new)
            k3 = lu_solve(lu, f2 - e32 * (k2 - f1) - 2 * (k1 - f0) + hs * d * T, check_finite=False)
            e = hs / 6 * (k1 - 2 * k2 + k3)
    except (np.linalg.LinAlgError, FloatingPointError, RuntimeError, ValueError):
        return False, None, 1e30, counts
    if not np.all(np.isfinite(y_new)):
        return False, None, 1e30, counts
    e, s_f, c_f = filtered(gp, e, d * hs, lu)
    counts.update(F=2, S=3 + s_f, C=5 + c_f)
    return True, y_new, err_norm(e, y, y_new, gp.scales, rtol), counts


ATTEMPTS = dict(trbdf2=trbdf2_attempt, ros34pw2=ros34pw2_attempt, ros23=ros23_attempt)


def weighted_work(c):
    return sum(WORK[k] * c[k] for k in WORK)


# ------------------------------------------------------------------------------------------------
# the driver: controller, breakpoints, gate switches
# ------------------------------------------------------------------------------------------------


def integrate(method, gp: GatedPad, rtol, switch_tol=1.0, predict=False, max_steps=400000):
    p, n = gp.p, gp.n
    step_fn = ATTEMPTS[method]
    srtol = switch_tol * rtol
    y = np.zeros(4 * n)
    y[3 * n:] = p.initial_age
    t = 0.0
    gp.plate = np.zeros(2)
    gp.g = np.zeros(n) if gp.stress else np.ones(n)
    gp.set_step(0.0, INITIAL_STEP)
    z0 = gp.end_terms(0.0, y)[0] if gp.stress else np.zeros(n)
    K1 = gp.f(0.0, y)
    h = INITIAL_STEP
    ts, ys, fs, plates, gates = [t], [y.copy()], [K1.copy()], [gp.plate.copy()], [gp.g.copy()]
    cnt = dict(L=0, F=0, S=0, C=0, newton=0)
    acc = rej_err = rej_fail = rej_switch = 0
    switches = unlocated = sliding_candidates = missed_predictions = 0
    switch_limit, retries, predicted, misses = math.inf, 0, False, 0
    eye = np.eye(4 * n)
    wall0 = time.perf_counter()
    while t < p.end_time:
        if acc + rej_err + rej_fail + rej_switch >= max_steps:
            raise RuntimeError(f"{method} rtol {rtol}: max_steps at t = {t}")
        # ---- propose (kernels/controller.py propose_step) ----
        bp = next_breakpoint(p, t)
        hs = min(h, MAX_STEP)
        clipped = 0
        if hs >= bp - t:
            hs, clipped = bp - t, 1
        elif hs > 0.5 * (bp - t):
            hs = 0.5 * (bp - t)
        t_new = bp if clipped == 1 else t + hs
        if t < switch_limit < t + hs:
            hs, t_new, clipped = switch_limit - t, switch_limit, 2
        plate0 = gp.plate.copy()
        ok, y_new, err, c = step_fn(gp, t, y, K1, hs, t_new, rtol, eye)
        for k in cnt:
            cnt[k] += c[k]
        if not ok:
            rej_fail += 1
            gp.plate = plate0
            h = hs * FAILURE_FACTOR
            if h < MIN_STEP:
                raise RuntimeError(f"{method} rtol {rtol}: step underflow at t = {t}")
            continue
        factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, max(MIN_FACTOR, SAFETY * err**ERROR_EXPONENT))
        sw_err, frac, next_switch = 0.0, 1.0, math.inf
        if gp.stress:
            gp.set_step(t, t_new)
            z1, relax, tau, phi, dz_dg = gp.end_terms(t_new, y_new)
            open_now = (z1 > 0).astype(float)
            rate = np.maximum(np.abs(tau) * relax / (srtol * (gp.tau_scale + np.abs(tau))),
                              phi * relax / (srtol * (gp.phi_scale + np.abs(phi))))
            flip = open_now != gp.g
            if np.any(flip):
                dz = z0 - z1
                theta = np.where(dz != 0, np.clip(np.divide(z0, dz, out=np.zeros(n), where=dz != 0), 0, 1), 0.0)
                e_sw = np.where(flip, (1 - theta) * hs * rate, 0.0)
                sw_err = float(e_sw.max())
                big = e_sw > 1
                if np.any(big):
                    frac = float(np.min(theta[big] + 0.5 * (1 - theta[big]) / e_sw[big]))
            if predict:
                slope = (z1 - z0) / hs
                towards = (~flip) & (rate > 0) & (z0 != z1) & (((z1 < 0) & (slope > 0)) | ((z1 > 0) & (slope < 0)))
                if np.any(towards):
                    next_switch = float(np.min(-z1[towards] / slope[towards] + 0.5 / rate[towards]))
            if err <= 1.0 and sw_err > 1.0:
                if frac * hs > MIN_STEP and retries < MAX_SWITCH_RETRIES:
                    rej_switch += 1
                    retries += 1
                    switch_limit = t + frac * hs
                    predicted = False
                    gp.plate = plate0
                    continue
                unlocated += 1
        if err > 1.0:
            rej_err += 1
            gp.plate = plate0
            h = hs * min(factor, SAFETY)
            if h < MIN_STEP:
                raise RuntimeError(f"{method} rtol {rtol}: step underflow at t = {t}")
            continue
        # ---- accepted ----
        acc += 1
        switched = False
        if gp.stress:
            new_g = open_now
            changed = new_g != gp.g
            # the engine's sliding condition (not implemented here: counted)
            r_obs = (z1 - z0) / hs
            rate_far = r_obs + (1 - 2 * gp.g) * dz_dg
            slide = changed & (dz_dg < 0) & (((gp.g == 0) & (rate_far < 0)) | ((gp.g == 1) & (rate_far > 0)))
            sliding_candidates += int(np.count_nonzero(slide))
            nsw = int(np.count_nonzero(changed))
            switches += nsw
            switched = nsw > 0
            gp.g = new_g
            z0 = z1
            if switched or sw_err > 1.0:
                retries = 0
            if switched:
                misses = 0
            elif clipped == 2 and predicted:
                misses += 1
                missed_predictions += 1
            if t_new >= switch_limit:
                switch_limit, predicted = math.inf, False
            if predict and misses < MAX_PREDICTION_MISSES and not (switch_limit < math.inf and not predicted):
                if next_switch < math.inf and t_new + next_switch < switch_limit:
                    switch_limit, predicted = t_new + next_switch, True
        h_next = hs * factor
        if clipped:
            h_next = max(h_next, h)
        h = h_next
        t, y = t_new, y_new
        K1 = gp.f(t, y)  # with the new gates (the engine corrects its FSAL in closed form)
        ts.append(t)
        ys.append(y.copy())
        fs.append(K1.copy())
        plates.append(gp.plate.copy())
        gates.append(gp.g.copy())
    wall = time.perf_counter() - wall0
    attempts = acc + rej_err + rej_fail + rej_switch
    return dict(t=np.array(ts), y=np.array(ys), f=np.array(fs), plates=np.array(plates), gates=np.array(gates),
                method=method, rtol=rtol, steps_accepted=acc, rejected_error=rej_err, rejected_solve=rej_fail,
                rejected_switch=rej_switch, attempts=attempts, gate_switches=switches, unlocated_switches=unlocated,
                sliding_candidates=sliding_candidates, missed_predictions=missed_predictions,
                linear_solves_fresh=cnt["L"], substitutions=cnt["S"], f_evaluations=cnt["F"], vector_passes=cnt["C"],
                newton_iterations=cnt["newton"], factorizations=cnt["L"], work=weighted_work(cnt), wall_s=wall)


def readings(gp: GatedPad, run):
    """esdirk_order.mu_readings with the method's own step (gate of the step start) for 'stepped'."""
    step_fn = ATTEMPTS[run["method"]]
    eye = np.eye(4 * gp.n)

    def step(j, tq):
        g_save = gp.g.copy()
        gp.g = run["gates"][j].copy()
        ok, y_t, _, _ = step_fn(gp, run["t"][j], run["y"][j], run["f"][j], tq - run["t"][j], tq, run["rtol"], eye)
        gp.g = g_save
        return y_t if ok else None

    return mu_readings(gp, run, step=step)


def mu_path_error(gp: GatedPad, run, ref_run, ref_value):
    """max over the run's accepted points after the disc starts of |mu(t_k) - mu_ref(t_k)| / mu_s_ref,
    mu_ref from the cubic Hermite of the reference's state (its steps are short): the accuracy of
    mu(t) where the readings take it from, free of how a reading refines the peak."""
    p = gp.p
    tr, yr, fr = ref_run["t"], ref_run["y"], ref_run["f"]
    ts, ys = run["t"], run["y"]
    worst = 0.0
    for k in range(int(np.searchsorted(ts, p.rest_until)), len(ts)):
        tk = ts[k]
        j = min(max(int(np.searchsorted(tr, tk, side="right")) - 1, 0), len(tr) - 2)
        gp.set_step(tr[j], tr[j + 1])
        mu_ref = gp.mu(tk, hermite(tr[j], tr[j + 1], yr[j], yr[j + 1], fr[j], fr[j + 1], tk))
        gp.set_step(ts[max(k - 1, 0)], tk)
        worst = max(worst, abs(gp.mu(tk, ys[k]) - mu_ref))
    gp.piece = None
    return worst / ref_value


def steps_by_phase(p, t):
    edges = [0.0, 1e-3, p.force_ramp_time, p.rest_until, 20.12, 20.14, np.inf]
    return {f"{a:g}-{b:g} s": int(np.sum((t[1:] > a) & (t[1:] <= b))) for a, b in zip(edges[:-1], edges[1:])}


def cheapest_within(rows, err, key, cost="work"):
    """The cost of the cheapest run whose ``key`` error is <= err (no interpolation; None if none)."""
    c = [r[cost] for r in rows if r[key] <= err]
    return min(c) if c else None


def engine_run(p, n, rtol, predict):
    solver = wf.Solver(nodes=n, rtol=rtol, max_steps=10**6, predict_switches=predict)
    ds = wf.simulate(scene=p, solver=solver, fronts=None, device="cpu")
    return dict(rtol=rtol, mu_s=float(ds.mu_s[0]), mu_s_time=float(ds.mu_s_time[0]), steps_accepted=int(ds.steps_accepted[0]),
                steps_rejected=int(ds.steps_rejected[0]), newton_iterations=int(ds.newton_iterations[0]),
                gate_switches=int(ds.gate_switches[0]), unlocated_switches=int(ds.unlocated_switches[0]))


ROW_KEYS = ("steps_accepted", "rejected_error", "rejected_solve", "rejected_switch", "attempts", "gate_switches",
            "unlocated_switches", "sliding_candidates", "missed_predictions", "newton_iterations", "factorizations",
            "linear_solves_fresh", "substitutions", "f_evaluations", "vector_passes", "work", "wall_s")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=40)
    ap.add_argument("--eccentricities", type=float, nargs="+", default=[0.0, -0.2])
    ap.add_argument("--end-time", type=float, default=20.3)
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-4, 1e-5, 1e-6, 1e-7])
    ap.add_argument("--ref-rtol", type=float, default=1e-9)
    ap.add_argument("--methods", nargs="+", default=["trbdf2", "ros34pw2", "ros23"], choices=list(ATTEMPTS))
    ap.add_argument("--predict", action="store_true", help="predicted switches too (the engine's default)")
    ap.add_argument("--filter", choices=["engine", "full", "none"], default="engine",
                    help="the velocity error filter, the same for every method (default: the kernels')")
    ap.add_argument("--targets", type=float, nargs="+", default=[1e-5, 1e-6, 1e-7])
    ap.add_argument("--time-targets", type=float, nargs="+", default=[1e-5, 3e-6, 1e-6])
    ap.add_argument("--path-targets", type=float, nargs="+", default=[1e-4, 1e-5, 1e-6])
    ap.add_argument("--no-engine", action="store_true", help="skip the warpfric check of the reference")
    ap.add_argument("--check", action="store_true", help="the tableau checks only")
    ap.add_argument("--out", default="studies/results/rosenbrock_w_cpu.json")
    args = ap.parse_args(argv)
    command = "python studies/rosenbrock_w.py " + " ".join(sys.argv[1:] if argv is None else argv)
    t_script = time.perf_counter()

    checks = {name: check_rosenbrock(name) for name in TABLEAUS}
    for name, chk in checks.items():
        print(json.dumps(dict(tableau=name, **{k: v for k, v in chk.items() if k not in ("rosenbrock_conditions", "w_conditions")})),
              flush=True)
    if args.check:
        return checks
    FILTER["mode"] = args.filter

    scenes = []
    for ecc in args.eccentricities:
        p = wf.Parameters(end_time=args.end_time, eccentricity=ecc)
        gp = GatedPad(PadODE(p, args.nodes, wf.Model()))
        ref_run = integrate("trbdf2", gp, args.ref_rtol, predict=args.predict)
        ref = dict(method="trbdf2", rtol=args.ref_rtol, **readings(gp, ref_run), **{k: ref_run[k] for k in ROW_KEYS})
        ref_value, ref_time = ref["mu_s_parabola"], ref["mu_s_time_parabola"]
        ref["reading_spread"] = dict(stepped=ref["mu_s"] / ref_value - 1, dense=ref["mu_s_dense"] / ref_value - 1)
        print(json.dumps(dict(eccentricity=ecc, reference=ref)), flush=True)
        engine = None
        if not args.no_engine:
            engine = engine_run(wf.Parameters(end_time=args.end_time, eccentricity=ecc), args.nodes, args.ref_rtol, args.predict)
            engine["relative_difference_to_reference"] = engine["mu_s"] / ref_value - 1
            engine["time_difference_to_reference"] = engine["mu_s_time"] - ref_time
            print(json.dumps(dict(eccentricity=ecc, engine=engine)), flush=True)
        rows = []
        for method in args.methods:
            for rtol in args.rtols:
                try:
                    r = integrate(method, gp, rtol, predict=args.predict)
                except RuntimeError as exc:
                    row = dict(method=method, rtol=rtol, eccentricity=ecc, nodes=args.nodes, failed=str(exc))
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    continue
                rd = readings(gp, r)
                row = dict(method=method, rtol=rtol, eccentricity=ecc, nodes=args.nodes, **{k: r[k] for k in ROW_KEYS},
                           mu_s_parabola=rd["mu_s_parabola"], mu_s_time_parabola=rd["mu_s_time_parabola"],
                           mu_s_stepped=rd["mu_s"], mu_s_dense=rd["mu_s_dense"], mu_s_time_dense=rd["mu_s_time"])
                row["mu_s_error"] = abs(row["mu_s_parabola"] / ref_value - 1)  # primary: the engine's reading
                row["mu_s_time_error"] = abs(row["mu_s_time_parabola"] - ref_time)
                row["mu_s_error_stepped"] = abs(row["mu_s_stepped"] / ref_value - 1)
                row["mu_s_error_dense"] = abs(row["mu_s_dense"] / ref_value - 1)
                row["mu_s_time_error_dense"] = abs(row["mu_s_time_dense"] - ref_time)
                row["mu_path_error"] = mu_path_error(gp, r, ref_run, ref_value)
                row["steps_by_phase"] = steps_by_phase(p, r["t"])
                rows.append(row)
                print(json.dumps(row), flush=True)
        del ref_run
        ok_rows = [r for r in rows if "failed" not in r]
        wp = {}
        measures = {"parabola": ("mu_s_error", args.targets), "stepped": ("mu_s_error_stepped", args.targets),
                    "mu(t) at accepted points": ("mu_path_error", args.path_targets),
                    "mu_s_time (s)": ("mu_s_time_error", args.time_targets)}
        for reading, (key, targets) in measures.items():
            wp[reading] = {}
            for method in args.methods:
                sr = [dict(r, mu_s_error=r[key]) for r in ok_rows if r["method"] == method]
                wp[reading][method] = {f"{tgt:g}": dict(**{k: at_error(sr, tgt, k) for k in ("work", "linear_solves_fresh", "attempts")},
                                                        cheapest_within=cheapest_within(sr, tgt, "mu_s_error"))
                                       for tgt in targets}
            base = wp[reading].get("trbdf2")
            for method in args.methods:
                for tgt in wp[reading][method]:
                    v, b0 = wp[reading][method][tgt], (base or {}).get(tgt, {})
                    v["work_ratio_to_trbdf2"] = (v["work"] / b0["work"]) if (v["work"] and b0.get("work")) else None
                    v["cheapest_ratio_to_trbdf2"] = ((v["cheapest_within"] / b0["cheapest_within"])
                                                     if (v["cheapest_within"] and b0.get("cheapest_within")) else None)
        scenes.append(dict(eccentricity=ecc, reference=ref, engine=engine, rows=rows, work_precision=wp))

    wall_script = time.perf_counter() - t_script
    out = dict(command=command, nodes=args.nodes, end_time=args.end_time, rtols=args.rtols, ref_rtol=args.ref_rtol,
               switches="predicted and located" if args.predict else "located only", work_units=WORK,
               velocity_error_filter=args.filter,
               tableau_checks=checks, scenes=scenes, script_wall_s=wall_script,
               notes=("mu_s_error: parabola reading (the engine's) against the reference's parabola reading; "
                      "work = 250 L + 150 F + 20 S + 20 C per node (kernel-study 2.2); costs at a target error by "
                      "log-log interpolation along the rtol sweep (None outside the measured range)"))
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    print_tables(out)
    print(f"\nscript wall time {wall_script:.0f} s; written {args.out}")
    return out


def print_tables(out):
    def fmt(v, spec=".0f"):
        return format(v, spec) if v is not None else "n/a"

    for sc in out["scenes"]:
        ref = sc["reference"]
        print(f"\n=== e = {sc['eccentricity']:g}, N = {out['nodes']}, {out['switches']} switches, velocity error filter "
              f"{out['velocity_error_filter']}; reference TR-BDF2 rtol "
              f"{out['ref_rtol']:g}: mu_s = {ref['mu_s_parabola']:.12f} at {ref['mu_s_time_parabola']:.9f} s "
              f"({ref['attempts']} attempts; stepped/dense readings differ by {ref['reading_spread']['stepped']:.1e} / "
              f"{ref['reading_spread']['dense']:.1e})")
        if sc["engine"]:
            e = sc["engine"]
            print(f"    engine (warpfric CPU, same rtol): mu_s = {e['mu_s']:.12f} ({e['relative_difference_to_reference']:+.1e}), "
                  f"time {e['time_difference_to_reference']:+.1e} s, {e['steps_accepted']} + {e['steps_rejected']} steps, "
                  f"{e['newton_iterations']} Newton")
        print(f"{'method':>9} {'rtol':>6} {'acc':>6} {'rej e/s/sw':>13} {'L':>6} {'S':>6} {'F':>6} {'work/1e3':>9} "
              f"{'mu_s err':>8} {'t err s':>8} {'stepped':>8} {'dense':>8} {'mu(t)':>8} {'wall':>6}  steps by phase")
        for r in sc["rows"]:
            if "failed" in r:
                print(f"{r['method']:>9} {r['rtol']:6.0e} FAILED: {r['failed']}")
                continue
            rej = f"{r['rejected_error']}/{r['rejected_solve']}/{r['rejected_switch']}"
            print(f"{r['method']:>9} {r['rtol']:6.0e} {r['steps_accepted']:6d} {rej:>13} {r['linear_solves_fresh']:6d} "
                  f"{r['substitutions']:6d} {r['f_evaluations']:6d} {r['work'] / 1e3:9.1f} {r['mu_s_error']:8.1e} "
                  f"{r['mu_s_time_error']:8.1e} {r['mu_s_error_stepped']:8.1e} {r['mu_s_error_dense']:8.1e} "
                  f"{r['mu_path_error']:8.1e} {r['wall_s']:6.1f}  {'/'.join(str(v) for v in r['steps_by_phase'].values())}")
        for reading, tab in sc["work_precision"].items():
            print(f"  work at equal error ({reading}): work/1e3 (L, attempts), work ratio to TR-BDF2 interpolated "
                  f"[cheapest run within the error]")
            for method, v in tab.items():
                cells = []
                for tgt, c in v.items():
                    cells.append(f"{tgt}: {fmt(c['work'] and c['work'] / 1e3, '.1f'):>7} ({fmt(c['linear_solves_fresh'])}, "
                                 f"{fmt(c['attempts'])}) x{fmt(c['work_ratio_to_trbdf2'], '.2f')} [x{fmt(c['cheapest_ratio_to_trbdf2'], '.2f')}]")
                print(f"    {method:>9}  " + "  ".join(cells))


if __name__ == "__main__":
    main()
