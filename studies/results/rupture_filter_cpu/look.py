import sys, numpy as np
d = np.load(sys.argv[1]); t, x, v, s = d["t"], d["x"], d["v"], d["s"]
N = len(x)
print("yield times min/max", np.nanmin(d["yt"]), np.nanmax(d["yt"]))
# decompose v into mean (uniform), alternating (grid) and the rest
alt = (-1.0) ** np.arange(N)
vm = v.mean(axis=1)
va = (v * alt).mean(axis=1)
print(f"{'t':>10} {'mean v':>11} {'max|v|':>11} {'alt comp':>11} {'v_rms-dev':>11} {'mean slip':>11} {'mu':>10}")
idx = np.linspace(0, len(t) - 1, 41).astype(int)
for i in idx:
    dev = np.sqrt(((v[i] - vm[i]) ** 2).mean())
    print(f"{t[i]:10.5f} {vm[i]:11.3e} {np.abs(v[i]).max():11.3e} {va[i]:11.3e} {dev:11.3e} {s[i].mean():11.3e} {d['mu'][i]:10.7f}")
