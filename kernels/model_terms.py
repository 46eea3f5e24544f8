"""Model terms of SPEC sections 3-6 as Warp functions, with the exact partial derivatives the
implicit integrator needs.

Everything here is a pure function of its arguments. ``make_model_terms(ft, model)`` builds the
functions for one floating-point type ``ft`` (wp.float32 or wp.float64) and one set of model
switches; switched-off terms are removed at compile time (``wp.static``). It composes one factory
per part of the model: ``make_coefficients`` (the per-member Coeffs), ``make_grid`` (node positions
and weights), ``make_elastic_stencil`` (normal stress and elastic force, SPEC sections 3-4),
``make_friction_at_gate`` and ``make_friction_law`` (the friction law, SPEC section 5), joined at
the interface by ``contact_terms``.

Discretisation (docs/model.md, "Space"): nodes x_i = -L/2 + i*dx, i = 0..N-1, dx = L/(N-1), with
control volumes of width w_i = dx (interior) and dx/2 (the two edge nodes). The axial force per
unit depth N(x) = M*H*u_x - lambda*delta(x) is evaluated on the control-volume faces and is zero at
the free edges, so the elastic force sums to zero over the pad exactly.
"""


import functools
from typing import Any

import warp as wp

from .types import MemberParams

FLOAT32_VELOCITY_FLOOR = 1.0e-4  # m/s, smallest velocity reference of the error weights in float32
SLIDING_NEWTON_ITERATIONS = 12  # Newton iterations on the gate of a node sliding on the yield surface
SLIDING_GATE_TOL = 1.0e-10  # converged gate update

# ------------------------------------------------------------------------------------------------
# Arithmetic
# ------------------------------------------------------------------------------------------------


@wp.func
def quotient(num: Any, den: Any):
    """num / den, the same value (NaN as NaN), without CUDA's slow path for a zero numerator: the
    GPU's FP64 division checks its operands and calls a full-range subroutine
    (__cuda_sm20_div_rn_f64_full) for a zero or tiny numerator, a call that also moves the
    caller's registers. A zero numerator divides 1 instead. Its quotient is then num * den for a
    finite, non-zero den (the signed zero of num / den, subnormal den included) and (1/den) * num
    for den = 0, inf or NaN (NaN, the signed zero, NaN). That last case uses the quotient of 1, so
    the compiler cannot divide num itself in its place. For the quotients that are often 0/x in a
    node sweep (docs/performance.md, "Divisions of zero")."""
    zero = type(num)(0.0)
    zero_numerator = num == zero
    q = wp.where(zero_numerator, type(num)(1.0), num) / den
    finite_nonzero = den != zero and den - den == zero
    return wp.where(zero_numerator, wp.where(finite_nonzero, num * den, q * num), q)


@functools.cache  # one function per type, shared
def make_over_den(ft):
    """over_den(x, den, inv_den) for scalar type ``ft`` (one function per type, shared): x / den, in
    float64 as x * inv_den (inv_den = 1/den), so that quotients of one denominator cost one division
    (the friction law's stage solution, phi/phi0 and |s|/v* with the member's 1/phi0 and 1/v* in
    Coeffs, the Thomas rows, the stage derivatives' 1/g): the GPU's FP64 division is a long
    dependent sequence. float32 keeps the exact quotient (its round-off decides which hard float32
    members stall: tests/test_trust.py), and inv_den is then unused."""

    @wp.func
    def over_den(x: ft, den: ft, inv_den: ft):
        if wp.static(ft == wp.float64):
            return x * inv_den
        return x / den

    return over_den


# where ratio_max compares cross products: both within [RATIO_PRODUCT_MIN, RATIO_PRODUCT_MAX], far from
# float64's underflow and overflow, so that each product is exact to a rounding
RATIO_PRODUCT_MIN = 1.0e-290
RATIO_PRODUCT_MAX = 1.0e290


@functools.cache  # one function per type, shared
def make_ratio_max(ft):
    """ratio_max(top, bottom, num, den) -> (top, bottom) for scalar type ``ft`` (one function per
    type, shared): the running maximum of num/den over a sweep (num, den >= 0), kept as the fraction
    top/bottom (start 0/1) so that the sweep divides once at its end (``quotient(top, bottom)``)
    instead of once per term: the error-weighted norms of the Newton update and of the local error.

    float64 compares num/den > top/bottom as num*bottom > top*den where both products lie in
    [RATIO_PRODUCT_MIN, RATIO_PRODUCT_MAX]; elsewhere (a zero or NaN term, the sweep's first, a
    zero or infinite den, or values far from 1, as in a diverged step, where a product could
    overflow or underflow) it compares the quotients themselves. A NaN term is dropped, as wp.max
    drops it. The maximum is the same quotient as wp.max of the quotients unless two terms lie
    within a rounding of each other (then either one, to an ulp). float32 keeps one quotient per
    term (bottom stays 1), as over_den keeps its quotients."""

    @wp.func
    def ratio_max(top: ft, bottom: ft, num: ft, den: ft):
        if wp.static(ft == wp.float64):
            lhs = num * bottom
            rhs = top * den
            low = ft(RATIO_PRODUCT_MIN)
            high = ft(RATIO_PRODUCT_MAX)
            if lhs > low and lhs < high and rhs > low and rhs < high:
                if lhs > rhs:
                    return num, den
                return top, bottom
            if num > ft(0.0) and den == den:  # NaN fails both
                if top == ft(0.0):
                    return num, den
                if num / den > top / bottom:
                    return num, den
            return top, bottom
        return wp.max(top, num / den), bottom

    return ratio_max


# ------------------------------------------------------------------------------------------------
# Load protocol (float64: times of order 20 s need more than float32's 1e-6 s resolution).
# ------------------------------------------------------------------------------------------------


@wp.func
def normal_force_at(p: MemberParams, t: wp.float64):
    """Normal force F(t) in N: linear ramp 0 -> normal_force over force_ramp_time, then constant."""
    if t >= p.force_ramp_time:
        return p.normal_force
    if t <= wp.float64(0.0):
        return wp.float64(0.0)
    return p.normal_force * t / p.force_ramp_time


@wp.func
def disc_velocity_at(p: MemberParams, t: wp.float64, step_start: wp.float64):
    """Disc velocity v_d(t) in m/s. ``step_start`` is the start of the current step: the sudden stop
    applies to steps that start at or after stop_time, so a step that ends on stop_time sees the
    left limit (steps are clipped to land on stop_time exactly)."""
    if step_start >= p.stop_time:
        return wp.float64(0.0)
    if t <= p.rest_until:
        return wp.float64(0.0)
    if t >= p.rest_until + p.velocity_ramp_time:
        return p.disc_velocity
    return p.disc_velocity * (t - p.rest_until) / p.velocity_ramp_time


@wp.func
def disc_travel_at(p: MemberParams, t: wp.float64):
    """Distance the disc has slid by time t, m (integral of |v_d|; nothing after a sudden stop)."""
    te = wp.min(t, p.stop_time) - p.rest_until
    if te <= wp.float64(0.0):
        return wp.float64(0.0)
    v = wp.abs(p.disc_velocity)
    if te < p.velocity_ramp_time:
        return v * te * te / (wp.float64(2.0) * p.velocity_ramp_time)
    return v * (te - wp.float64(0.5) * p.velocity_ramp_time)


@wp.func
def next_breakpoint(p: MemberParams, t: wp.float64):
    """First protocol time after t where the load is not smooth (ramp ends, disc start, stop, end)."""
    bp = p.end_time
    if p.force_ramp_time > t and p.force_ramp_time < bp:
        bp = p.force_ramp_time
    if p.rest_until > t and p.rest_until < bp:
        bp = p.rest_until
    t_ramp_end = p.rest_until + p.velocity_ramp_time
    if t_ramp_end > t and t_ramp_end < bp:
        bp = t_ramp_end
    if p.stop_time > t and p.stop_time < bp:
        bp = p.stop_time
    return bp


@wp.func
def normal_force_in_step(p: MemberParams, t: wp.float64, step_start: wp.float64):
    """normal_force_at(p, t) for a stage time t inside the step from step_start."""
    return normal_force_at(p, t)


@wp.func
def disc_velocity_piece(p: MemberParams, t: wp.float64, step_start: wp.float64):
    """disc_velocity_at for a stage of the step from step_start, past the protocol breakpoint that
    ends the step too (ESDIRK4's stage at c = 26/25 > 1): the smooth continuation of the piece the
    step lies in, not the next piece."""
    bp = next_breakpoint(p, step_start)
    if t <= bp:
        return disc_velocity_at(p, t, step_start)
    if step_start >= p.stop_time:
        return wp.float64(0.0)
    tm = wp.float64(0.5) * (step_start + bp)
    if tm <= p.rest_until:
        return wp.float64(0.0)
    if tm < p.rest_until + p.velocity_ramp_time:
        return p.disc_velocity * (t - p.rest_until) / p.velocity_ramp_time
    return p.disc_velocity


@wp.func
def normal_force_piece(p: MemberParams, t: wp.float64, step_start: wp.float64):
    """normal_force_at continued smoothly past the breakpoint that ends the step (see
    disc_velocity_piece)."""
    bp = next_breakpoint(p, step_start)
    if t <= bp:
        return normal_force_at(p, t)
    tm = wp.float64(0.5) * (step_start + bp)
    if tm >= p.force_ramp_time:
        return p.normal_force
    return p.normal_force * t / p.force_ramp_time


def make_coefficients(ft):
    """The per-member coefficients (Coeffs, in the working precision ``ft``) and make_coeffs, which
    derives them from a member's MemberParams (float64, SI units) for a grid of n nodes."""

    @wp.struct
    class Coeffs:
        """Per-member coefficients in the working precision (SI units)."""

        MH: ft  # P-wave modulus times height, N/m
        M_over_H: ft  # Pa/m
        lam: ft  # Lame lambda, Pa
        G: ft  # Pa
        two_G_over_H: ft  # Pa/m
        rhoH: ft  # kg/m^2
        damping: ft  # Pa s/m
        kif: ft  # interface velocity factor
        Kh: ft  # interface stiffness mu0/h, Pa/m
        inv_hardness: ft  # 1/Pa
        eta_vstar: ft  # eta * v_star, Pa
        vstar: ft  # m/s
        inv_vstar: ft  # s/m
        b: ft
        phi0: ft  # s
        inv_phi0: ft  # 1/s
        inv_D: ft  # 1/m
        tau_c: ft  # shear strength, Pa (stress gate)
        v0: ft  # gate velocity, m/s (velocity gate)
        dx: ft  # m
        inv_dx: ft  # 1/m
        L: ft  # m
        h_arm: ft  # m
        # natural scales for error weights
        tau_scale: ft
        u_scale: ft
        v_scale: ft
        v_scale_contact: ft  # the velocity's scale at nodes in contact this step (contact_velocity_scale)
        phi_scale: ft
        delta_scale: ft
        tilt_scale: ft
        # the nodes this thread works on, [first_node, end_node), and its lane in the member's team
        # (kernels/team.py; all nodes and lane 0 for the thread-per-member kernel)
        first_node: wp.int32
        end_node: wp.int32
        lane: wp.int32

    @wp.func
    def make_coeffs(p: MemberParams, n: int):
        c = Coeffs()
        nu = p.poisson_ratio
        M = wp.float64(2.0) * p.shear_modulus * (wp.float64(1.0) - nu) / (wp.float64(1.0) - wp.float64(2.0) * nu)
        lam = wp.float64(2.0) * p.shear_modulus * nu / (wp.float64(1.0) - wp.float64(2.0) * nu)
        c.MH = ft(M * p.height)
        c.M_over_H = ft(M / p.height)
        c.lam = ft(lam)
        c.G = ft(p.shear_modulus)
        c.two_G_over_H = ft(wp.float64(2.0) * p.shear_modulus / p.height)
        c.rhoH = ft(p.density * p.height)
        c.damping = ft(p.damping)
        c.kif = ft(p.interface_velocity_factor)
        c.Kh = ft(p.interface_stiffness)
        c.inv_hardness = ft(wp.float64(1.0) / p.hardness)
        c.eta_vstar = ft(p.viscous_coefficient * p.reference_velocity)
        c.vstar = ft(p.reference_velocity)
        c.inv_vstar = ft(wp.float64(1.0) / p.reference_velocity)
        c.b = ft(p.aging_coefficient)
        c.phi0 = ft(p.aging_time)
        c.inv_phi0 = ft(wp.float64(1.0) / p.aging_time)
        c.inv_D = ft(wp.float64(1.0) / p.memory_length)
        c.tau_c = ft(p.shear_strength)
        c.v0 = ft(p.gate_velocity)
        dx = p.length / wp.float64(n - 1)
        c.dx = ft(dx)
        c.inv_dx = ft(wp.float64(1.0) / dx)
        c.L = ft(p.length)
        c.h_arm = ft(p.torque_arm)
        sigma0 = p.normal_force / (p.depth * p.length)
        u_scale = sigma0 * p.height / (wp.float64(2.0) * p.shear_modulus)
        c.tau_scale = ft(sigma0)
        c.u_scale = ft(u_scale)
        v_ref = wp.max(wp.abs(p.disc_velocity), p.reference_velocity)
        if wp.static(ft == wp.float32):
            # float32 round-off in the pad's force balance cannot hold the pad velocity tighter than
            # this scale: below it the error test never passes (docs/performance.md, stability map)
            v_ref = wp.max(v_ref, wp.float64(FLOAT32_VELOCITY_FLOOR))
        c.v_scale = ft(u_scale * v_ref / p.memory_length)
        c.v_scale_contact = c.v_scale
        c.phi_scale = ft(p.aging_time)
        c.delta_scale = ft(sigma0 / M * p.height)
        c.tilt_scale = ft(sigma0 / M * p.height / p.length)
        c.first_node = 0
        c.end_node = n
        c.lane = 0
        return c

    return dict(Coeffs=Coeffs, make_coeffs=make_coeffs)


def make_grid(ft, Coeffs):
    """Node positions and the quadrature weights of the grid (docs/model.md, "Space")."""

    @wp.func
    def node_x(c: Coeffs, i: int):
        """Position of node i, m."""
        return ft(-0.5) * c.L + ft(float(i)) * c.dx

    @wp.func
    def node_weight(c: Coeffs, i: int, n: int):
        """Control-volume width w_i (trapezoid weight for integrals over x), m."""
        if i == 0 or i == n - 1:
            return ft(0.5) * c.dx
        return c.dx

    @wp.func
    def node_moment_weight(c: Coeffs, i: int, n: int):
        """Weight W1_i with sum_i W1_i f_i = integral x f(x) dx exactly for piecewise-linear f, m^2."""
        x = node_x(c, i)
        if i == 0:
            return c.dx * (ft(0.5) * x + c.dx / ft(6.0))
        if i == n - 1:
            return c.dx * (ft(0.5) * x - c.dx / ft(6.0))
        return x * c.dx

    return dict(node_x=node_x, node_weight=node_weight, node_moment_weight=node_moment_weight)


def make_elastic_stencil(ft, model, Coeffs, node_x):
    """The 3-point displacement stencil of the pad (SPEC sections 3-4): the interface normal stress
    sigma_n and the elastic force density at a node, each as a StencilTerm (value and partial
    derivatives). ``model`` switches the Poisson coupling and the tilt."""
    poisson = bool(model.poisson_coupling)
    tilt_on = bool(model.tilt)

    @wp.struct
    class StencilTerm:
        """A node quantity of the 3-point stencil and its partial derivatives with respect to
        u_{i-1}, u_i, u_{i+1} (per m), the plate compression delta0 (per m) and tilt a (per rad)."""

        value: ft
        d_u_left: ft
        d_u_center: ft
        d_u_right: ft
        d_delta0: ft
        d_tilt: ft

    @wp.func
    def stencil_term(value: ft, d_u_left: ft, d_u_center: ft, d_u_right: ft, d_delta0: ft, d_tilt: ft):
        t = StencilTerm()
        t.value = value
        t.d_u_left = d_u_left
        t.d_u_center = d_u_center
        t.d_u_right = d_u_right
        t.d_delta0 = d_delta0
        t.d_tilt = d_tilt
        return t

    @wp.func
    def normal_stress(c: Coeffs, i: int, n: int, u_l: ft, u_c: ft, u_r: ft, delta0: ft, tilt: ft):
        """Interface normal stress sigma_n at node i (Pa, compressive > 0) and its derivatives
        with respect to u_{i-1}, u_i, u_{i+1}, delta0 and the tilt a.

        sigma_n = M*delta(x_i)/H - lambda*k_if*eps_i, with eps_i the mean of the axial strains on
        the two faces of the control volume; on a free edge the face strain is
        lambda*delta(edge)/(M*H) (zero axial force)."""
        x = node_x(c, i)
        sigma = c.M_over_H * (delta0 - tilt * x)
        d_d0 = c.M_over_H
        d_a = -c.M_over_H * x
        d_ul = ft(0.0)
        d_uc = ft(0.0)
        d_ur = ft(0.0)
        if wp.static(poisson):
            # eps = k_if * (e_left + e_right) / 2, sigma -= lam * eps
            f = ft(0.5) * c.kif * c.lam
            e_l = ft(0.0)
            e_r = ft(0.0)
            if i == 0:
                x_edge = ft(-0.5) * c.L
                e_l = c.lam * (delta0 - tilt * x_edge) / c.MH
                d_d0 -= f * c.lam / c.MH
                d_a += f * c.lam * x_edge / c.MH
            else:
                e_l = (u_c - u_l) * c.inv_dx
                d_ul += f * c.inv_dx
                d_uc -= f * c.inv_dx
            if i == n - 1:
                x_edge = ft(0.5) * c.L
                e_r = c.lam * (delta0 - tilt * x_edge) / c.MH
                d_d0 -= f * c.lam / c.MH
                d_a += f * c.lam * x_edge / c.MH
            else:
                e_r = (u_r - u_c) * c.inv_dx
                d_uc += f * c.inv_dx
                d_ur -= f * c.inv_dx
            sigma -= f * (e_l + e_r)
        return stencil_term(sigma, d_ul, d_uc, d_ur, d_d0, d_a)

    @wp.func
    def elastic_force(c: Coeffs, i: int, n: int, u_l: ft, u_c: ft, u_r: ft, delta0: ft, tilt: ft):
        """Elastic force density on node i (Pa): dN/dx - (2G/H)*u + G*a, and its derivatives with
        respect to u_{i-1}, u_i, u_{i+1}, delta0 and a."""
        k = c.MH * c.inv_dx
        div = ft(0.0)
        d_ul = ft(0.0)
        d_uc = ft(0.0)
        d_ur = ft(0.0)
        d_d0 = ft(0.0)
        d_a = c.G
        if i > 0 and i < n - 1:
            # interior: (N_{i+1/2} - N_{i-1/2})/dx, the lambda*delta terms give exactly lambda*a
            div = k * (u_r - ft(2.0) * u_c + u_l) * c.inv_dx + c.lam * tilt
            d_ul = k * c.inv_dx
            d_ur = k * c.inv_dx
            d_uc = ft(-2.0) * k * c.inv_dx
            d_a += c.lam
        else:
            w = ft(0.5) * c.dx
            if i == 0:
                x_face = node_x(c, 0) + ft(0.5) * c.dx
                flux = k * (u_r - u_c) - c.lam * (delta0 - tilt * x_face)
                div = flux / w
                d_ur = k / w
                d_uc = -k / w
                d_d0 = -c.lam / w
                d_a += c.lam * x_face / w
            else:
                x_face = node_x(c, n - 1) - ft(0.5) * c.dx
                flux = k * (u_c - u_l) - c.lam * (delta0 - tilt * x_face)
                div = -flux / w
                d_ul = k / w
                d_uc = -k / w
                d_d0 = c.lam / w
                d_a -= c.lam * x_face / w
        force = div - c.two_G_over_H * u_c + c.G * tilt
        d_uc -= c.two_G_over_H
        if wp.static(not tilt_on):
            d_a = ft(0.0)
        return stencil_term(force, d_ul, d_uc, d_ur, d_d0, d_a)

    return dict(StencilTerm=StencilTerm, normal_stress=normal_stress, elastic_force=elastic_force)


def make_friction_at_gate(ft, model, Coeffs):
    """The friction law's closed-form stage solution at one node for a given slip rate and gate
    (SPEC section 5), as a Friction. ``model`` switches the velocity gate and the viscous term."""
    viscous = bool(model.viscous_friction)
    velocity_gate = model.relaxation_gate == "velocity"

    @wp.struct
    class Friction:
        """The friction law at one node over an implicit stage (interface_friction, friction_at_gate)."""

        stress: ft  # tau_f, Pa
        d_normal: ft  # d tau_f/d sigma_n (1)
        d_slip: ft  # d tau_f/d s, Pa s/m (total: through phi, tau_el and, sliding, the gate)
        elastic_stress: ft  # tau_el, Pa
        contact_age: ft  # phi, s
        elastic_stress_rate: ft  # d tau_el/dt, Pa/s
        contact_age_rate: ft  # d phi/dt (1)
        contact: ft  # 1 where sigma_n >= 0, else 0
        area: ft  # real-contact fraction A (1)
        d_area_normal: ft  # dA/d sigma_n, 1/Pa
        d_area_slip: ft  # dA/ds (gate fixed), s/m
        d_gate: ft  # d tau_f/d gate (slip fixed), Pa
        d_area_gate: ft  # dA/d gate (1)
        gate: ft  # the gate used (1)

    over_den = make_over_den(ft)

    @wp.func
    def friction_at_gate(c: Coeffs, sigma: ft, s: ft, z_tau: ft, z_phi: ft, g: ft, gate: ft):
        """The closed-form stage solution of the friction law at one node for a given slip rate s and
        gate (see interface_friction), as a Friction (d_slip through phi and tau_el, gate fixed)."""
        a_s = wp.abs(s)
        sg = wp.sign(s)
        r = a_s * gate
        dr_ds = sg * gate
        if wp.static(velocity_gate):
            r = wp.sqrt(s * s + c.v0 * c.v0)
            dr_ds = s / r
        den = ft(1.0) + g * r * c.inv_D
        inv_den = ft(1.0) / den
        phi = over_den(z_phi + g, den, inv_den)
        dphi_ds = over_den(-phi * g * dr_ds * c.inv_D, den, inv_den)
        dphi_dgate = over_den(-phi * g * a_s * c.inv_D, den, inv_den)
        contact = ft(0.0)
        if sigma >= ft(0.0):
            contact = ft(1.0)
        sigma_c = sigma * contact
        aging = ft(1.0) + c.b * wp.log(ft(1.0) + over_den(phi, c.phi0, c.inv_phi0))
        age_den = c.phi0 + phi  # s
        slip_den = c.vstar + a_s  # m/s
        inv_dens = ft(1.0)  # float64 with the viscous term: 1/(age_den*slip_den), one division for both
        if wp.static(viscous and ft == wp.float64):
            inv_dens = ft(1.0) / (age_den * slip_den)
            daging_dphi = c.b * slip_den * inv_dens
        else:
            daging_dphi = c.b / age_den
        area = sigma_c * c.inv_hardness * aging
        darea_dsigma = contact * c.inv_hardness * aging
        darea_dphi = sigma_c * c.inv_hardness * daging_dphi
        darea_ds = darea_dphi * dphi_ds
        darea_dgate = darea_dphi * dphi_dgate
        tau_el = over_den(z_tau + g * c.Kh * area * s, den, inv_den)
        dtel_darea = over_den(g * c.Kh * s, den, inv_den)
        dtel_ds = over_den(g * c.Kh * area - tau_el * g * dr_ds * c.inv_D, den, inv_den)
        dtel_dgate = over_den(-tau_el * g * a_s * c.inv_D, den, inv_den)
        tau_f = tau_el
        dtf_darea = dtel_darea
        dtf_ds = dtel_ds
        if wp.static(viscous):
            lg = wp.log(ft(1.0) + over_den(a_s, c.vstar, c.inv_vstar))
            tau_f += c.eta_vstar * area * sg * lg
            dtf_darea += c.eta_vstar * sg * lg
            if wp.static(ft == wp.float64):
                dtf_ds += c.eta_vstar * area * age_den * inv_dens
            else:
                dtf_ds += c.eta_vstar * area / slip_den
        dtf_ds += dtf_darea * darea_ds
        dtf_dsigma = dtf_darea * darea_dsigma
        dtf_dgate = dtel_dgate + dtf_darea * darea_dgate
        out = Friction()
        out.stress = tau_f
        out.d_normal = dtf_dsigma
        out.d_slip = dtf_ds
        out.elastic_stress = tau_el
        out.contact_age = phi
        out.elastic_stress_rate = c.Kh * area * s - tau_el * r * c.inv_D
        out.contact_age_rate = ft(1.0) - phi * r * c.inv_D
        out.contact = contact
        out.area = area
        out.d_area_normal = darea_dsigma
        out.d_area_slip = darea_ds
        out.d_gate = dtf_dgate
        out.d_area_gate = darea_dgate
        out.gate = gate
        return out

    return dict(Friction=Friction, friction_at_gate=friction_at_gate)


def make_friction_law(ft, model, Coeffs, friction_at_gate):
    """The friction law at one node over an implicit stage (interface_friction: with the stress
    gate, a node sliding on the yield surface has its gate solved there) and the stress gate's
    yield margin."""
    stress_gate = model.relaxation_gate == "stress"

    @wp.func
    def sliding_gate_of(c: Coeffs, tau_f: ft, area: ft, scale: ft):
        """theta_w(x) and d theta_w/dx at x = (|tau_f|/A - tau_c)*scale, theta_w = (1 + tanh x)/2."""
        x = (wp.abs(tau_f) / area - c.tau_c) * scale
        th = wp.tanh(x)
        return ft(0.5) * (ft(1.0) + th), ft(0.5) * (ft(1.0) - th * th)

    @wp.func
    def margin_slope(tau_f: ft, area: ft, dtau_f: ft, darea: ft, scale: ft):
        """dx/dq of x = (|tau_f|/A - tau_c)*scale from d tau_f/dq and dA/dq (any variable q)."""
        return (wp.sign(tau_f) * dtau_f - wp.abs(tau_f) * darea / area) / area * scale

    @wp.func
    def interface_friction(
        c: Coeffs, sigma: ft, velocity: ft, v_disc: ft, z_tau: ft, z_phi: ft, g: ft, gate: ft, sliding: ft,
        width: ft,
    ):
        """Friction law (SPEC section 5) at one node, solved implicitly over a stage of coefficient g.

        The stage equations  phi = z_phi + g*dphi/dt  and  tau_el = z_tau + g*dtau_el/dt  are linear
        in phi and tau_el for a given slip rate and gate, so they are solved in closed form; with
        g = 0 this evaluates the law at the state (phi = z_phi, tau_el = z_tau).

        The relaxation of tau_el and the rejuvenation of phi run at the rate r/D:
        r = gate*|s| (stress gate: ``gate`` is the node's yield gate, held fixed over the step; the
        gate-less law passes gate = 1) or r = sqrt(s^2 + v0^2) (velocity gate; ``gate`` unused).
        A node sliding on the yield surface (stress gate, ``sliding`` = 1, g > 0) has its gate
        solved here, implicitly, from gate = theta_w(x), x = (|tau_f|/A - tau_c)/(width*tau_c),
        theta_w(x) = (1 + tanh(x))/2: Filippov's equivalent gate, regularised over a relative
        width of the yield stress (Newton on the gate, started from ``gate``; unique root since
        dx/dgate < 0 there); the derivatives then include the gate's response.

        Returns a Friction (d_slip and d_normal total, including a sliding gate's response).
        """
        s = v_disc - c.kif * velocity
        fr = friction_at_gate(c, sigma, s, z_tau, z_phi, g, gate)
        if wp.static(stress_gate):
            if sliding > ft(0.0) and g > ft(0.0) and fr.area > ft(0.0):
                scale = ft(1.0) / (width * c.tau_c)
                dF_dgate = ft(1.0)
                dtheta = ft(0.0)
                for _it in range(SLIDING_NEWTON_ITERATIONS):
                    theta, dtheta = sliding_gate_of(c, fr.stress, fr.area, scale)
                    dF_dgate = ft(1.0) - dtheta * margin_slope(fr.stress, fr.area, fr.d_gate, fr.d_area_gate, scale)
                    F = gate - theta
                    new_gate = wp.clamp(gate - F / dF_dgate, ft(0.0), ft(1.0))
                    converged = wp.abs(new_gate - gate) <= ft(SLIDING_GATE_TOL)
                    gate = new_gate
                    # one evaluation site for both outcomes: the law's code is compiled once here
                    fr = friction_at_gate(c, sigma, s, z_tau, z_phi, g, gate)
                    if converged:
                        break
                if fr.area > ft(0.0):
                    # the gate follows s and sigma_n: d gate = theta' (dx/ds ds + dx/dsigma dsigma) / dF_dgate
                    theta, dtheta = sliding_gate_of(c, fr.stress, fr.area, scale)
                    dF_dgate = ft(1.0) - dtheta * margin_slope(fr.stress, fr.area, fr.d_gate, fr.d_area_gate, scale)
                    dx_ds = margin_slope(fr.stress, fr.area, fr.d_slip, fr.d_area_slip, scale)
                    dx_dsigma = margin_slope(fr.stress, fr.area, fr.d_normal, fr.d_area_normal, scale)
                    d_slip = fr.d_slip + fr.d_gate * dtheta * dx_ds / dF_dgate
                    d_normal = fr.d_normal + fr.d_gate * dtheta * dx_dsigma / dF_dgate
                    fr.d_slip = d_slip
                    fr.d_normal = d_normal
        return fr

    @wp.func
    def yield_margin(c: Coeffs, tau_f: ft, area: ft, sigma: ft):
        """|tau_f| - tau_c*A (Pa) at normal stress sigma (Pa): the stress gate is open where this is
        > 0, i.e. where the asperity-level stress |tau_f|/A exceeds tau_c; a point without contact
        area (A = 0) that still carries a friction stress is open (the limit A -> 0+), one carrying
        none is closed. Out of contact (sigma < 0) with a friction stress the margin is continued
        linearly in the normal stress, |tau_f| - tau_c*sigma/H (the aging factor 1): the same sign,
        but not flat up to a touchdown, so that a touchdown's crossing lies where sigma crosses 0,
        which the located switches and the predictions then find (kernels/gates.py)."""
        if sigma < ft(0.0) and tau_f != ft(0.0):
            return wp.abs(tau_f) - c.tau_c * (sigma * c.inv_hardness)
        return wp.abs(tau_f) - c.tau_c * area

    return dict(interface_friction=interface_friction, yield_margin=yield_margin)


def make_model_terms(ft, model):
    """Warp functions of the model for scalar type ``ft`` and switches ``model`` (a Model): the
    coefficients, the grid, the elastic stencil and the friction law, joined at the interface by
    contact_terms."""
    coefficients = make_coefficients(ft)
    Coeffs = coefficients["Coeffs"]
    grid = make_grid(ft, Coeffs)
    stencil = make_elastic_stencil(ft, model, Coeffs, grid["node_x"])
    at_gate = make_friction_at_gate(ft, model, Coeffs)
    law = make_friction_law(ft, model, Coeffs, at_gate["friction_at_gate"])
    normal_stress = stencil["normal_stress"]
    interface_friction = law["interface_friction"]

    @wp.func
    def contact_terms(
        c: Coeffs, i: int, n: int, u_l: ft, u_c: ft, u_r: ft, delta0: ft, tilt: ft, velocity: ft, v_disc: ft,
        z_tau: ft, z_phi: ft, g: ft, gate: ft, sliding: ft, width: ft,
    ):
        """The interface at node i: its normal stress (from the displacement stencil and the plate)
        and the friction law there (a stage of coefficient g, or g = 0: the law at the state).
        Returns (StencilTerm, Friction). Every node sweep of the integrator evaluates the interface
        through this one function."""
        ns = normal_stress(c, i, n, u_l, u_c, u_r, delta0, tilt)
        fr = interface_friction(c, ns.value, velocity, v_disc, z_tau, z_phi, g, gate, sliding, width)
        return ns, fr

    viscous = bool(model.viscous_friction)

    @wp.func
    def contact_velocity_scale(c: Coeffs, p: MemberParams, cap: wp.float64, t_new: wp.float64, t_old: wp.float64):
        """The pad velocity's error scale (m/s) at nodes in contact for the step (t_old, t_new]: the
        member's scale u_scale*max(|v_d|, v*)/D (c.v_scale, from the disc's full velocity) capped at
        cap*hardness/viscous_coefficient, but not below u_scale*max(|v_d(t_new)|, v*)/D of the disc's
        velocity now. A velocity error dV moves a sticking node's viscous stress by up to
        eta*A*dV ~ eta*(sigma_n/hardness)*dV, so at the cap an error of rtol times the scale moves
        it by ~cap*rtol*sigma_n, against the stress's tolerance rtol*sigma_0; while the disc ramps
        up, the nodes slip at about its velocity, where the stress is less sensitive. Members whose
        c.v_scale is below the cap keep it, bit for bit; float32 (and the law without viscous
        friction) always keep it (docs/model.md, "Time integration")."""
        scale = c.v_scale
        if wp.static(ft == wp.float64 and viscous):
            sticking = ft(cap * p.hardness / wp.max(p.viscous_coefficient, wp.float64(1.0e-300)))
            if sticking < c.v_scale:  # else the member's own scale, as it is
                v_now = wp.max(wp.abs(disc_velocity_at(p, t_new, t_old)), p.reference_velocity)
                scale = wp.max(c.u_scale * v_now / p.memory_length, sticking)  # float64 here: c.u_scale exact
        return scale

    return dict(
        Coeffs=Coeffs,
        StencilTerm=stencil["StencilTerm"],
        Friction=at_gate["Friction"],
        make_coeffs=coefficients["make_coeffs"],
        node_x=grid["node_x"],
        node_weight=grid["node_weight"],
        node_moment_weight=grid["node_moment_weight"],
        normal_stress=normal_stress,
        elastic_force=stencil["elastic_force"],
        interface_friction=interface_friction,
        contact_terms=contact_terms,
        yield_margin=law["yield_margin"],
        contact_velocity_scale=contact_velocity_scale,
    )
