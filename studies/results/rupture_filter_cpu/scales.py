"""Frequencies, error scales, the velocity filter's factor and TR-BDF2's amplification at the step sizes seen
(defaults of wf.Parameters; F = 1000 N)."""
import numpy as np
G, nu, rho, H, L, p, D, F, vmax = 3.1e9, 0.35, 1200.0, 0.015, 0.2, 0.12, 5e-7, 1000.0, 1e-4
M = 2 * G * (1 - nu) / (1 - 2 * nu); rhoH = rho * H
gam = 2 - np.sqrt(2.0)            # TR-BDF2's TR stage ends at gamma*h
g_factor = gam / 2                # the diagonal coefficient of the implicit stages (gamma_d = gamma/2 = 0.293)
w0 = np.sqrt(2 * G / (rho * H * H))
print(f"uniform shear mode omega_0 = sqrt(2G/(rho H^2)) = {w0:.3e} rad/s (period {2*np.pi/w0*1e6:.1f} us)")
u_scale = F / (p * L) * H / (2 * G); v_scale = u_scale * vmax / D
print(f"u_scale {u_scale:.3e} m, v_scale {v_scale:.3e} m/s, rtol*v_scale at rtol 1e-5: {1e-5*v_scale:.2e} m/s")
def R(z):  # TR-BDF2 stability function (TR to gamma*h, then BDF2 over the step)
    y1 = (1 + gam * z / 2) / (1 - gam * z / 2)
    a, b, c = 1 / (gam * (2 - gam)), (1 - gam) ** 2 / (gam * (2 - gam)), (1 - gam) / (2 - gam)
    return (a * y1 - b) / (1 - c * z)
for N in (25, 50, 100, 200):
    dx = L / (N - 1)
    wd = np.sqrt(2 * M / (rho * dx * dx) + 2 * G / (rho * H * H))   # the node's own (diagonal) frequency
    print(f"N={N:3d} dx={dx:.3e} m  diagonal omega_d = {wd:.3e} rad/s = {wd/w0:5.1f} omega_0; "
          f"filter factor 1/(1+(g h omega_d)^2), g = {g_factor:.3f}:", end="")
    for h in (1.5e-6, 1e-5, 5e-5):
        print(f"  h={h:.1e}: {1/(1+(g_factor*h*wd)**2):.1e}", end="")
    print()
for h in (3e-7, 1.5e-6, 3.5e-6, 1e-5, 5e-5):
    y = h * w0
    print(f"h={h:.1e} s: h*omega_0 = {y:.3f}, |R(i h omega_0)| = {abs(R(1j*y)):.6f} (damping per step {1-abs(R(1j*y)):.1e}; "
          f"per ms {1-abs(R(1j*y))**(1e-3/h):.1e}); exact-resolvent filter of the uniform mode 1/(1+(g h omega_0)^2) = {1/(1+(g_factor*h*w0)**2):.2f}")
