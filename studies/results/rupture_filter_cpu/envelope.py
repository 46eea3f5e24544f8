"""Envelope of the ringing of the pad velocity: rms over 50-us blocks of (v - its linear trend per block), for the
uniform part (mean over nodes) and for the rest; with the gate openings (yield_time) in each block.
usage: envelope.py file.npz [block_us]"""
import sys, numpy as np
d = np.load(sys.argv[1]); t, x, v = d["t"], d["x"], d["v"]; yt = np.sort(np.asarray(d["yt"]).ravel())
blk = float(sys.argv[2]) * 1e-6 if len(sys.argv) > 2 else 50e-6
nb = int(round((t[-1] - t[0]) / blk)); per = (len(t) - 1) // nb
print(sys.argv[1], "N =", len(x))
print(f"{'block start':>12} {'rms uniform':>12} {'rms nonunif':>12} {'openings':>8}")
for b in range(nb):
    sl = slice(b * per, (b + 1) * per + 1); tt = t[sl] - t[sl][0]
    vm = v[sl].mean(axis=1); dev = v[sl] - vm[:, None]
    vm = vm - np.polyval(np.polyfit(tt, vm, 1), tt)
    dev = dev - np.array([np.polyval(np.polyfit(tt, dev[:, j], 1), tt) for j in range(dev.shape[1])]).T
    n_open = int(((yt >= t[sl][0]) & (yt < t[sl][-1])).sum())
    print(f"{t[sl][0]:12.5f} {np.sqrt((vm**2).mean()):12.3e} {np.sqrt((dev**2).mean()):12.3e} {n_open:8d}")
