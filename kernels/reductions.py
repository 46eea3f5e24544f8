"""In-kernel reductions over time: memory independent of the number of steps.

mu_s (SPEC section 7) is the maximum over time of mu(t) = sign(v_max) * int tau_f dx / int sigma_n dx.
Sampling mu only at accepted steps would miss the peak by O(h^2 * mu''); each time the middle of
the last three accepted points is a local maximum, the parabola through the three points is
maximised instead (docs/model.md, "Outputs").
"""


import warp as wp

from .params import IntegratorState


@wp.func
def record_friction_point(st: IntegratorState, t: wp.float64, mu: wp.float64):
    """Fold the accepted point (t, mu) into the running maximum of ``st`` and return ``st``."""
    if mu > st.mu_s:  # mu_s starts at -inf (set by the host)
        st.mu_s = mu
        st.mu_s_time = t
    if st.npts >= 2 and st.mu1 >= st.mu2 and st.mu1 >= mu and t > st.t1 and st.t1 > st.t2:
        d1 = (st.mu1 - st.mu2) / (st.t1 - st.t2)
        d2 = (mu - st.mu1) / (t - st.t1)
        curv = (d2 - d1) / (t - st.t2)
        if curv < wp.float64(0.0):
            t_peak = wp.float64(0.5) * (st.t1 + st.t2) - d1 / (wp.float64(2.0) * curv)
            if t_peak >= st.t2 and t_peak <= t:
                mu_peak = st.mu2 + d1 * (t_peak - st.t2) + curv * (t_peak - st.t2) * (t_peak - st.t1)
                if mu_peak > st.mu_s:
                    st.mu_s = mu_peak
                    st.mu_s_time = t_peak
    st.t2 = st.t1
    st.mu2 = st.mu1
    st.t1 = t
    st.mu1 = mu
    st.mu_final = mu
    st.npts = st.npts + 1
    return st
