"""The Rosenbrock-W prototype of studies/rosenbrock_w.py (issue 21, part 3): the ROS34PW2 tableau
(as PETSc TSROSWRA34PW2) satisfies its order conditions, with the exact and with any Jacobian
(W-method), and shows its orders on smooth problems; the gated model's Jacobian is exact for the
held gate. A few seconds on the CPU."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
import rosenbrock_w as rw  # noqa: E402
from baseline_scipy import PadODE  # noqa: E402
from esdirk_order import fd_jacobian  # noqa: E402

import warpfric as wf  # noqa: E402


def test_ros34pw2_order_conditions_and_stability():
    tb = rw.tableau_ros34pw2()
    ros, w = rw.order_conditions(tb, tb["b"], 3)
    assert max(abs(v) for v in ros.values()) < 1e-14, ros
    assert max(abs(v) for v in w.values()) < 1e-14, w  # a W-method of order 3
    ros_h, w_h = rw.order_conditions(tb, tb["bhat"], 2)
    assert max(abs(v) for v in ros_h.values()) < 1e-14 and max(abs(v) for v in w_h.values()) < 1e-14
    # order 3 fails for the embedded weights: they are a genuine order-2 estimate
    assert max(abs(v) for v in rw.order_conditions(tb, tb["bhat"], 3)[0].values()) > 1e-3
    R = rw.stability(tb, tb["b"])
    assert abs(R(-1e8)) < 1e-6  # L-stable
    assert max(abs(R(1j * y)) for y in np.logspace(-3, 6, 200)) <= 1 + 1e-12  # A-stable on the axis
    assert np.allclose((tb["alpha"] + tb["Gamma"])[-1], tb["b"], atol=1e-15)  # stiffly accurate


def test_observed_orders_on_smooth_problems():
    o = rw.observed_orders("ros34pw2", steps=(20, 40, 80, 160))
    for prob in ("linear", "nonlinear", "nonlinear_W"):  # nonlinear_W: a wrong matrix W = 0.5 J + 1
        assert abs(o[prob]["order"][-1] - 3) < 0.3, (prob, o[prob])
        assert abs(o[prob]["embedded_order"][-1] - 2) < 0.3, (prob, o[prob])
    o23 = rw.observed_orders("ros23", steps=(20, 40, 80, 160))
    for prob in ("linear", "nonlinear", "nonlinear_W"):
        assert abs(o23[prob]["order"][-1] - 2) < 0.3, (prob, o23[prob])


def test_gated_jacobian_is_exact_for_the_held_gate():
    p = wf.Parameters(end_time=20.3)
    gp = rw.GatedPad(PadODE(p, 8, wf.Model()))
    n = gp.n
    rng = np.random.default_rng(1)
    y = np.concatenate([1e-7 * rng.standard_normal(n), 1e-6 * rng.standard_normal(n),
                        1e5 * (1 + rng.random(n)), 3e-4 * (1 + rng.random(n))])
    gp.g = (rng.random(n) > 0.5).astype(float)
    assert 0 < gp.g.sum() < n
    t = 20.13
    gp.set_step(t, t + 1e-3)
    gp.plate = np.zeros(2)
    f0, J = gp.f(t, y, jac=True)
    d = gp.plate.copy()
    sc = gp.scales + np.abs(y)
    Jfd = fd_jacobian(lambda yy: gp.f(t, yy), y, sc, lambda: setattr(gp, "plate", d.copy()))
    for k in range(4):  # each component block, relative to its largest scaled entry
        rows = slice(k * n, (k + 1) * n)
        a, b = J[rows] * sc, Jfd[rows] * sc
        assert np.max(np.abs(a - b)) <= 1e-5 * np.max(np.abs(b)), k
    # the gate enters tau_el' and phi' only: the closed nodes neither relax nor rejuvenate
    closed = gp.g == 0
    assert np.allclose(f0[3 * n:][closed], 1.0)
