"""The baseline a user would write without warpfric: the same semi-discrete equations as a plain
NumPy right-hand side, integrated by scipy.integrate.solve_ivp (BDF, with the Jacobian's sparsity
pattern). Also the independent float64 reference of tests/test_reference.py.

    python studies/baseline_scipy.py [--nodes 40] [--rtols 1e-4 1e-5 1e-6] [--end-time 20.6]
                                     [--gpu-json studies/results/work_precision_h100.json]
                                     [--out studies/results/baseline_scipy.json]

It runs, on this machine's CPU and in one process: warpfric (M = 1, float64, fronts off) over
--warpfric-rtols and scipy BDF over --rtols on the default scene (F = 1000 N, e = 0,
t = 0..end_time), measures each run's mu_s error against a tight warpfric run (rtol 1e-10, same
N: the spatial error is common to both; tests/test_reference.py checks that warpfric and this
scipy code converge to the same solution) and, for every scipy run, the ratio of its wall time
to warpfric's at the same mu_s error (log-log interpolation along warpfric's rtol sweep, whose
error falls monotonically; scipy's does not). With --gpu-json the same against warpfric's
per-realisation cost in a 10,000-member H100 ensemble (studies/work_precision.py, same N).

Equations (docs/model.md): per node u, v = du/dt, tau_el, phi; the plate's compression delta0
and tilt a are algebraic and are solved at every right-hand-side evaluation from the force and
moment balance (a 2x2 semi-smooth Newton solve, exact in one step without lift-off).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

import warpfric as wf


class PadODE:
    """Right-hand side dy/dt of the semi-discrete pad model, y = [u, v, tau_el, phi] (4N,)."""

    def __init__(self, p: wf.Parameters, n: int, model: wf.Model = wf.Model(), gate_width: float = 1e-3):
        """gate_width: the stress gate is smoothed here, theta_w(z) = (1 + tanh(z/(w*tau_c*A)))/2 with
        z = |tau_f| - tau_c*A and w = gate_width (relative to tau_c*A): an independent, smooth
        reading of the Heaviside gate that the kernels treat by locating the switches."""
        if not (model.inertia and model.tilt):
            raise ValueError("the baseline implements the default model (inertia and tilt on)")
        self.p, self.n, self.model, self.gate_width = p, n, model, gate_width
        nu, G, H, L = p.poisson_ratio, p.shear_modulus, p.height, p.length
        self.M = 2 * G * (1 - nu) / (1 - 2 * nu)
        self.lam = 2 * G * nu / (1 - 2 * nu)
        self.dx = L / (n - 1)
        self.x = -L / 2 + np.arange(n) * self.dx
        self.w = np.full(n, self.dx)  # control-volume widths (trapezoid weights)
        self.w[[0, -1]] = self.dx / 2
        self.w1 = self.x * self.dx  # exact moment weights of a piecewise-linear function
        self.w1[0] = self.dx * (self.x[0] / 2 + self.dx / 6)
        self.w1[-1] = self.dx * (self.x[-1] / 2 - self.dx / 6)
        self.h_arm = H if p.torque_arm is None else p.torque_arm
        self.stop = np.inf if p.stop_time is None else p.stop_time
        self.plate = np.zeros(2)  # last (delta0, a): Newton start
        self.evaluations = 0

    # protocol -------------------------------------------------------------------------------
    def force(self, t):
        p = self.p
        return p.normal_force * min(max(t / p.force_ramp_time, 0.0), 1.0) if p.force_ramp_time > 0 else p.normal_force

    def disc_velocity(self, t):
        p = self.p
        if t >= self.stop or t <= p.rest_until:
            return 0.0
        return p.disc_velocity * min((t - p.rest_until) / p.velocity_ramp_time, 1.0)

    # model terms ----------------------------------------------------------------------------
    def sigma_parts(self, u):
        """sigma_n = s_u + A0*delta0 + Aa*a at every node (Pa): the u part and the two columns."""
        p, n = self.p, self.n
        kif = p.interface_velocity_factor
        A0 = np.full(n, self.M / p.height)
        Aa = -self.M / p.height * self.x
        s_u = np.zeros(n)
        if self.model.poisson_coupling:
            f = 0.5 * kif * self.lam
            e_face = np.diff(u) / self.dx  # strains on the interior faces
            s_u[:-1] -= f * e_face  # right face of nodes 0..n-2
            s_u[1:] -= f * e_face  # left face of nodes 1..n-1
            c = f * self.lam / (self.M * p.height)  # free-edge face strain lambda*delta/(M*H)
            for i, x_edge in ((0, -p.length / 2), (n - 1, p.length / 2)):
                A0[i] -= c
                Aa[i] += c * x_edge
        return s_u, A0, Aa

    def friction(self, sigma, v, tau, phi, t):
        p = self.p
        s = self.disc_velocity(t) - p.interface_velocity_factor * v
        contact = sigma >= 0
        aging = 1 + p.aging_coefficient * np.log1p(phi / p.aging_time)
        area = np.where(contact, sigma, 0.0) / p.hardness * aging
        tau_f = tau.copy()
        if self.model.viscous_friction:
            tau_f += p.viscous_coefficient * p.reference_velocity * area * np.sign(s) * np.log1p(np.abs(s) / p.reference_velocity)
        return tau_f, area, s, contact

    def solve_plate(self, u, v, tau, phi, t):
        """(delta0, a) from the force and moment balance per unit depth (semi-smooth Newton)."""
        p = self.p
        F = self.force(t)
        rhs = np.array([F / p.depth, F * p.eccentricity * p.length / 2 / p.depth])
        s_u, A0, Aa = self.sigma_parts(u)
        d0, a = self.plate
        for _ in range(20):
            sigma = s_u + A0 * d0 + Aa * a
            tau_f, area, s, contact = self.friction(sigma, v, tau, phi, t)
            c = contact.astype(float)
            # d tau_f / d sigma (viscous part, linear in the contact pressure)
            dtf = np.zeros(self.n)
            if self.model.viscous_friction:
                aging = 1 + p.aging_coefficient * np.log1p(phi / p.aging_time)
                dtf = c * p.viscous_coefficient * p.reference_velocity / p.hardness * aging * np.sign(s) * np.log1p(np.abs(s) / p.reference_velocity)
            res = np.array([self.w @ (c * sigma), self.w1 @ (c * sigma) + self.h_arm * (self.w @ tau_f)]) - rhs
            J = np.array([[self.w @ (c * A0), self.w @ (c * Aa)],
                          [self.w1 @ (c * A0) + self.h_arm * (self.w @ (dtf * A0)),
                           self.w1 @ (c * Aa) + self.h_arm * (self.w @ (dtf * Aa))]])
            if F == 0:
                d0, a = 0.0, 0.0
                break
            step = np.linalg.solve(J, -res)
            d0, a = d0 + step[0], a + step[1]
            if abs(step[0]) <= 1e-14 * (abs(d0) + 1e-30) and abs(step[1]) <= 1e-14 * (abs(a) + 1e-30) + 1e-300:
                break
        self.plate = np.array([d0, a])
        sigma = s_u + A0 * d0 + Aa * a
        return d0, a, sigma

    def elastic_force(self, u, d0, a):
        p, n, dx = self.p, self.n, self.dx
        MH = self.M * p.height
        flux = np.zeros(n + 1)  # axial force N on the faces, zero at the free edges
        flux[1:-1] = MH * np.diff(u) / dx - self.lam * (d0 - a * 0.5 * (self.x[:-1] + self.x[1:]))
        div = np.diff(flux) / self.w
        return div - 2 * p.shear_modulus / p.height * u + p.shear_modulus * a

    def __call__(self, t, y):
        self.evaluations += 1
        p, n = self.p, self.n
        u, v, tau, phi = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
        d0, a, sigma = self.solve_plate(u, v, tau, phi, t)
        tau_f, area, s, contact = self.friction(sigma, v, tau, phi, t)
        rhoH = p.density * p.height
        dv = (self.elastic_force(u, d0, a) + tau_f - p.damping * v) / rhoH
        relax = self.relaxation_speed(s, tau_f, area)
        dtau = p.interface_stiffness * area * s - tau * relax / p.memory_length
        dphi = 1 - phi * relax / p.memory_length
        return np.concatenate([v, dv, dtau, dphi])

    def relaxation_speed(self, s, tau_f, area):
        """|s| times the gate (m/s), SPEC v2 section 5."""
        gate = self.model.relaxation_gate
        if gate == "none":
            return np.abs(s)
        if gate == "velocity":
            return np.sqrt(s**2 + self.p.gate_velocity**2)
        strength = self.p.shear_strength * area
        z = np.abs(tau_f) - strength
        with np.errstate(divide="ignore", invalid="ignore"):
            theta = np.where(strength > 0, 0.5 * (1 + np.tanh(z / (self.gate_width * strength))), (z > 0) * 1.0)
        return theta * np.abs(s)

    def mu(self, t, y):
        n = self.n
        u, v, tau, phi = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
        d0, a, sigma = self.solve_plate(u, v, tau, phi, t)
        tau_f, area, s, contact = self.friction(sigma, v, tau, phi, t)
        load = self.w @ np.where(contact, sigma, 0.0)
        return np.sign(self.p.disc_velocity) * (self.w @ tau_f) / load if load > 0 else 0.0

    def sparsity(self):
        """Jacobian pattern: u_i' = v_i; v_i' on u_{i-1..i+1}, v_i, tau_i, phi_i and, through the
        plate, on every u, v, tau, phi; tau_i' likewise (area depends on sigma); phi_i' on v_i."""
        n = self.n
        S = np.zeros((4 * n, 4 * n), dtype=bool)
        idx = np.arange(n)
        S[idx, n + idx] = True
        S[n:3 * n, :] = True
        S[3 * n + idx, n + idx] = True
        S[3 * n + idx, 3 * n + idx] = True
        return S

    def scales(self):
        """Absolute-tolerance scales of u, v, tau, phi (the same natural scales as the kernels)."""
        p = self.p
        sigma0 = p.normal_force / (p.depth * p.length)
        u_s = sigma0 * p.height / (2 * p.shear_modulus)
        v_s = u_s * max(abs(p.disc_velocity), p.reference_velocity) / p.memory_length
        return np.concatenate([np.full(self.n, u_s), np.full(self.n, v_s), np.full(self.n, sigma0),
                               np.full(self.n, p.aging_time)])


def breakpoints(p: wf.Parameters):
    pts = [0.0, p.force_ramp_time, p.rest_until, p.rest_until + p.velocity_ramp_time]
    if p.stop_time is not None:
        pts.append(p.stop_time)
    return sorted({t for t in pts if 0 <= t < p.end_time} | {p.end_time})


def run_scipy(p: wf.Parameters, n: int, rtol: float, model: wf.Model = wf.Model(), gate_width: float = 1e-3):
    """Integrate with solve_ivp BDF piece by piece between the protocol's breakpoints; return
    (mu_s, mu_s_time, wall s, steps, rhs evaluations)."""
    from scipy.integrate import solve_ivp

    ode = PadODE(p, n, model, gate_width)
    y = np.zeros(4 * n)
    y[3 * n:] = p.initial_age
    atol = rtol * ode.scales()
    t_all, mu_all = [], []
    steps = 0
    t0 = time.perf_counter()
    pts = breakpoints(p)
    for a, b in zip(pts[:-1], pts[1:]):
        sol = solve_ivp(ode, (a, b), y, method="BDF", rtol=rtol, atol=atol, jac_sparsity=ode.sparsity(),
                        first_step=min(1e-6, b - a))
        if sol.status != 0:
            raise RuntimeError(f"solve_ivp failed on [{a}, {b}]: {sol.message}")
        steps += sol.t.size - 1
        for k in range(1, sol.t.size):
            t_all.append(sol.t[k])
            mu_all.append(ode.mu(sol.t[k], sol.y[:, k]))
        y = sol.y[:, -1]
    wall = time.perf_counter() - t0
    t_all, mu_all = np.array(t_all), np.array(mu_all)
    k = int(np.argmax(mu_all))
    mu_s, t_s = mu_all[k], t_all[k]
    if 0 < k < len(mu_all) - 1:  # the same parabolic refinement as the kernels
        tt, mm = t_all[k - 1:k + 2], mu_all[k - 1:k + 2]
        c = np.polyfit(tt - tt[1], mm, 2)
        if c[0] < 0:
            tp = -c[1] / (2 * c[0])
            if tt[0] - tt[1] <= tp <= tt[2] - tt[1]:
                mu_s, t_s = np.polyval(c, tp), tp + tt[1]
    return dict(mu_s=float(mu_s), mu_s_time=float(t_s), wall_s=wall, steps=steps, rhs_evaluations=ode.evaluations,
                final_state=y)


def run_warpfric(p: wf.Parameters, n: int, rtol: float, repeat: int = 3):
    solver = wf.Solver(nodes=n, rtol=rtol, max_steps=10**6)
    wf.simulate(scene=p, solver=solver, fronts=None, device="cpu")  # compile
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        ds = wf.simulate(scene=p, solver=solver, fronts=None, device="cpu")
        best = min(best, time.perf_counter() - t0)
    return dict(mu_s=float(ds.mu_s[0]), mu_s_time=float(ds.mu_s_time[0]), wall_s=best,
                steps=int(ds.steps_accepted[0] + ds.steps_rejected[0]))


def time_at_error(rows, err):
    """Wall time at mu_s error ``err`` by log-log interpolation over rows whose error falls
    monotonically with their cost (warpfric's rtol sweep). Above the largest measured error: the
    time of that (more accurate) run, an upper bound, so a ratio with it is a lower bound. Below
    the smallest: None."""
    e = np.log([r["mu_s_error"] for r in rows])
    w = np.log([r["wall_s"] for r in rows])
    order = np.argsort(e)
    if np.log(err) < e.min():
        return None
    if np.log(err) > e.max():
        return float(np.exp(w[order][-1]))
    return float(np.exp(np.interp(np.log(err), e[order], w[order])))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=40)
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-4, 1e-5, 1e-6], help="scipy tolerances")
    ap.add_argument("--warpfric-rtols", type=float, nargs="+", default=[1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8])
    ap.add_argument("--end-time", type=float, default=20.6)
    ap.add_argument("--gpu-json", default=None, help="work_precision.py H100 results (per-realisation cost)")
    ap.add_argument("--out", default="baseline_scipy.json")
    ap.add_argument("--from-json", default=None, help="recompute the ratios and the table of a saved run")
    args = ap.parse_args(argv)
    if args.from_json:
        return resummarise(args.from_json, args.gpu_json, args.nodes)
    p = wf.Parameters(end_time=args.end_time)
    ref = run_warpfric(p, args.nodes, 1e-10, repeat=1)
    print(json.dumps(dict(reference=ref)), flush=True)
    rows = []
    for solver, fn, rtols in (("warpfric", run_warpfric, args.warpfric_rtols), ("scipy_bdf", run_scipy, args.rtols)):
        for rtol in rtols:
            r = fn(p, args.nodes, rtol)
            r.pop("final_state", None)
            r.update(solver=solver, rtol=rtol, nodes=args.nodes, mu_s_error=abs(r["mu_s"] / ref["mu_s"] - 1),
                     mu_s_time_error=abs(r["mu_s_time"] - ref["mu_s_time"]))
            rows.append(r)
            print(json.dumps(r), flush=True)
    report(rows, ref, args.gpu_json, args.nodes, args.out, "python studies/baseline_scipy.py " + " ".join(argv or sys.argv[1:]))


def report(rows, ref, gpu_json, nodes, out, command):
    """Ratios at equal mu_s error, the JSON file and the table."""
    wf_rows = [r for r in rows if r["solver"] == "warpfric"]
    gpu_rows = []
    if gpu_json:
        with open(gpu_json) as f:
            gpu_rows = [dict(mu_s_error=r["mu_s_error"], wall_s=r["wall_s_per_realisation"])
                        for r in json.load(f)["rows"] if r["nodes"] == nodes and r["dtype"] == "float64"]
    # scipy's error does not fall monotonically with its tolerance: compare each scipy run with
    # warpfric at that run's error
    for r in rows:
        if r["solver"] != "scipy_bdf":
            continue
        cpu = time_at_error(wf_rows, r["mu_s_error"])
        r["warpfric_cpu_s_at_same_error"] = cpu
        r["ratio_cpu"] = r["wall_s"] / cpu if cpu else None
        if gpu_rows:
            gpu = time_at_error(gpu_rows, r["mu_s_error"])
            r["warpfric_h100_s_per_realisation_at_same_error"] = gpu
            r["ratio_h100"] = r["wall_s"] / gpu if gpu else None
    with open(out, "w") as f:
        json.dump(dict(reference=ref, rows=rows, command=command, gpu_json=gpu_json), f, indent=1)
    print(f"\n{'solver':>10} {'rtol':>7} {'wall s':>9} {'steps':>7} {'mu_s':>12} {'mu_s err':>9} {'t_s err s':>9} "
          f"{'wf CPU s':>9} {'x CPU':>7} {'wf H100 s':>10} {'x H100':>8}")
    for r in rows:
        extra = ""
        if r["solver"] == "scipy_bdf":
            def f(v, spec):
                return format(v, spec) if v else "n/a"
            extra = (f" {f(r['warpfric_cpu_s_at_same_error'], '9.4f'):>9} {f(r['ratio_cpu'], '7.0f'):>7} "
                     f"{f(r.get('warpfric_h100_s_per_realisation_at_same_error'), '10.2e'):>10} {f(r.get('ratio_h100'), '8.0f'):>8}")
        print(f"{r['solver']:>10} {r['rtol']:7.0e} {r['wall_s']:9.3f} {r['steps']:7d} {r['mu_s']:12.8f} "
              f"{r['mu_s_error']:9.2e} {r['mu_s_time_error']:9.1e}" + extra)


def resummarise(path, gpu_json, nodes):
    with open(path) as f:
        saved = json.load(f)
    report(saved["rows"], saved["reference"], gpu_json, nodes, path, saved["command"])


if __name__ == "__main__":
    main()
