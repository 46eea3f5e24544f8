"""Front speeds against the grid: v_left, v_middle, v_right and their time-discretisation
error estimates for the default scene and e = +-0.2, at N = 50, 100, 200, 400 and rtol 1e-5, 1e-7.

    python studies/front_grid.py [--relaxation-gate stress] [--device cpu] [--front-event velocity]
                                 [--out studies/results/front_grid_cpu_GATE.json]

What it shows (docs/performance.md, "Front speeds against the grid"): at a fixed grid the speeds
converge in rtol and v_*_error tracks that; across grids a slow front converges, a fast middle front
(hundreds of m/s, crossing its segment in < 0.5 ms) does not. Prints a table last.
"""

import argparse
import json
import time
from pathlib import Path

import warpfric as wf

MEMBERS = {"eccentricity": [0.0, 0.2, -0.2]}
OUTPUTS = ("mu_s", "v_left", "v_middle", "v_right", "v_left_error", "v_middle_error", "v_right_error",
           "left_front_length", "middle_front_length", "right_front_length", "nucleation_position", "status")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--relaxation-gate", default="stress", choices=("stress", "none", "velocity"))
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", default=None)
    ap.add_argument("--front-event", default="velocity", choices=("contact", "strength", "velocity"),
                    help="the front event (default velocity: the event of the committed rows, "
                         "studies/results/front_grid_cpu_*.json)")
    args = ap.parse_args(argv)
    out = Path(args.out or Path(__file__).with_name("results") / f"front_grid_cpu_{args.relaxation_gate}.json")
    rows = []
    for nodes in (50, 100, 200, 400):
        for rtol in (1e-5, 1e-7):
            t0 = time.perf_counter()
            ds = wf.simulate(MEMBERS, model=wf.Model(relaxation_gate=args.relaxation_gate),
                             solver=wf.Solver(nodes=nodes, rtol=rtol), fronts=wf.Fronts(event=args.front_event),
                             device=args.device, progress=False)
            row = dict(nodes=nodes, rtol=rtol, wall_s=time.perf_counter() - t0)
            row.update({k: ds[k].values.tolist() for k in OUTPUTS})
            rows.append(row)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(dict(command="python studies/front_grid.py " + " ".join(argv or []),
                                   device=args.device, eccentricity=MEMBERS["eccentricity"], rows=rows,
                                   warpfric=wf.__version__), indent=1))
    print(f"relaxation_gate={args.relaxation_gate}, default scene, e = {MEMBERS['eccentricity']} (m/s; +- v_*_error)")
    print(f"{'N':>4} {'rtol':>6}  " + "  ".join(f"{'e=' + format(e, 'g'):>44}" for e in MEMBERS["eccentricity"]))
    for r in rows:
        cells = []
        for m in range(len(MEMBERS["eccentricity"])):
            cells.append(" ".join(f"{r[s][m]:8.3g}±{r[s + '_error'][m]:<6.2g}" for s in ("v_left", "v_middle", "v_right")))
        print(f"{r['nodes']:>4} {r['rtol']:>6g}  " + "  ".join(f"{c:>44}" for c in cells))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
