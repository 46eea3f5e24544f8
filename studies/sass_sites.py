"""The integrate kernel's machine code by inlined call site, on a CUDA host: how many SASS
instructions each call in the kernel's Python source became (static counts; a function that
CUDA inlined at k sites counts k times). docs/performance.md, "Instruction cache".

    python studies/sass_sites.py [--nodes 200] [--lanes 32] [--top 25]

Compiles the default law's team kernel with line info (wp.config.lineinfo), disassembles its cubin
with nvdisasm (CUDA toolkit) and prints the total and the call sites with the most instructions.
"""

import argparse
import collections
import glob
import os
import re
import shutil
import subprocess

import warp as wp

import warpfric as wf

SITE = re.compile(r'//## File "([^"]+)", line (\d+)(?: inlined at "([^"]+)", line (\d+))?')
INSTRUCTION = re.compile(r"/\*[0-9a-f]{4,}\*/\s+(@!?U?P\w+\s+)?[A-Z]")  # not the .byte data lines


def call_sites(sass: str) -> tuple:
    """(total instructions, Counter of (file, line) of the inlined calls each instruction sits in)."""
    sites, counts, total, comment, group = frozenset(), collections.Counter(), 0, False, []
    for line in sass.splitlines():
        m = SITE.search(line)
        if m:
            group = group if comment else []
            group.append(m)
            comment = True
            continue
        if comment:
            sites = frozenset((os.path.basename(g.group(3)), int(g.group(4))) for g in group
                              if g.group(3) and g.group(3).endswith(".py"))
            comment = False
        if INSTRUCTION.search(line):
            total += 1
            counts.update(sites)
    return total, counts


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lanes", type=int, default=32)
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args(argv)
    nvdisasm = shutil.which("nvdisasm") or "/usr/local/cuda/bin/nvdisasm"
    wp.config.lineinfo = True
    wp.config.quiet = True
    wf.simulate({"eccentricity": [0.1]}, solver=wf.Solver(nodes=args.nodes, lanes=args.lanes), fronts=None,
                device="cuda:0", progress=False)
    cubin = max(glob.glob(os.path.join(wp.config.kernel_cache_dir or os.path.expanduser("~/.cache/warp"),
                                       "**", "*integrate*.cubin"), recursive=True), key=os.path.getmtime)
    sass = subprocess.run([nvdisasm, "-g", "-gi", cubin], capture_output=True, text=True, check=True).stdout
    total, counts = call_sites(sass)
    print(f"SASS instructions {total} ({cubin})")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for (name, line), n in counts.most_common(args.top):
        path = os.path.join(root, "kernels", name)
        src = open(path).read().splitlines()[line - 1].strip()[:90] if os.path.exists(path) else ""
        print(f"{n:7d}  {name}:{line}  {src}")


if __name__ == "__main__":
    main()
