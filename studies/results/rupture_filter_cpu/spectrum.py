"""Spatial modes (DCT-I over the nodes: free-edge cosine modes k = 0..N-1) of the recorded pad velocity,
their rms amplitude and dominant angular frequency over the window. usage: spectrum.py file.npz"""
import sys, numpy as np
from scipy.fft import dct
d = np.load(sys.argv[1]); t, x, v = d["t"], d["x"], d["v"]
N = len(x); dt = t[1] - t[0]
a = dct(v, type=1, axis=1) / (N - 1)          # mode amplitudes a_k(t)
a = a - a.mean(axis=0)                         # fluctuation about the window mean (trend removed below)
tt = t - t[0]
rms = []
print(f"{sys.argv[1]}  N={N} window {t[0]:.6f}-{t[-1]:.6f} s, dt {dt:.2e} s")
print(f"{'k':>3} {'rms amp (m/s)':>14} {'peak omega rad/s':>17} {'omega_grid(k) rad/s':>20}")
G, nu, rho, H, L = 3.1e9, 0.35, 1200.0, 0.015, 0.2
M = 2 * G * (1 - nu) / (1 - 2 * nu); dx = L / (N - 1)
for k in range(N):
    y = a[:, k] - np.polyval(np.polyfit(tt, a[:, k], 1), tt)
    Y = np.abs(np.fft.rfft(y * np.hanning(len(y))))
    f = np.fft.rfftfreq(len(y), dt) * 2 * np.pi
    wk = np.sqrt(2 * G / (rho * H * H) + (2 * np.sqrt(M / rho) / dx * np.sin(np.pi * k / (2 * (N - 1)))) ** 2)
    r = np.sqrt((y ** 2).mean()); rms.append(r)
    if N <= 40 or k < 10 or k > N - 6:
        print(f"{k:3d} {r:14.3e} {f[1 + np.argmax(Y[1:])]:17.3e} {wk:20.3e}")
rms = np.array(rms)
print("share of fluctuation energy: k=0 (uniform) %.3f, k>=N/2 %.3f, top mode %.3f" % (
    rms[0] ** 2 / (rms ** 2).sum(), (rms[N // 2:] ** 2).sum() / (rms ** 2).sum(), rms[-1] ** 2 / (rms ** 2).sum()))
