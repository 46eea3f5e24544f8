"""Outputs a user can trust: stragglers are stopped and flagged, inputs that cannot run are refused."""

import numpy as np
from conftest import run


def test_a_straggler_is_stopped_within_a_bounded_factor_of_its_peers():
    """One member with eta = 0 under the stress gate (a dynamic rupture: ~6e5 steps at N = 40) among
    healthy ones: it is stopped with status 'stalled' and NaN mu_s once it needs more than
    stall_factor times the median of its finished peers; the others are untouched."""
    eta = np.full(12, 2.7e13)
    eta[5] = 0.0
    ds = run({"viscous_coefficient": eta, "eccentricity": np.linspace(-0.15, 0.15, 12)}, nodes=20, rtol=1e-5,
             stall_factor=5.0, stall_min_steps=500, steps_per_launch=100)
    meanings = ds.status.attrs["flag_meanings"].split()
    attempts = ds.steps_accepted.values + ds.steps_rejected.values
    healthy = np.delete(np.arange(12), 5)
    assert meanings[ds.status.values[5]] == "stalled" and np.isnan(ds.mu_s.values[5])
    assert (ds.status.values[healthy] == 0).all() and np.isfinite(ds.mu_s.values[healthy]).all()
    limit = max(500, 5.0 * np.median(attempts[healthy]))
    assert limit < attempts[5] <= limit + 100  # stopped at the first launch boundary past the limit
    alone = run({"viscous_coefficient": eta[healthy], "eccentricity": np.linspace(-0.15, 0.15, 12)[healthy]},
                nodes=20, rtol=1e-5, stall_factor=5.0, stall_min_steps=500, steps_per_launch=100)
    np.testing.assert_array_equal(alone.mu_s.values, ds.mu_s.values[healthy])  # peers unaffected
