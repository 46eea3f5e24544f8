"""Where the integrate kernel's warps wait, by Python source: Nsight Compute's warp-state samples of
each SASS instruction, summed over the instructions of each call site and each source line of
kernels/ (the instructions' sites come from the cubin's line info, as in studies/sass_sites.py).

    python studies/stall_sites.py --csv stall_sass.csv[.gz] --cubin integrate.cubin[.gz] [--top 25] [--executed]
                                  [--waits-on]

The two inputs come from a GPU host (`bash studies/gpu_bench.sh stall-sites`): the SASS source page
of an `ncu --section SourceCounters --section WarpStateStats --import-source yes` profile of one
launch of the line-info kernel (`ncu -i REPORT --page source --csv --print-source sass`), and that
kernel's cubin from Warp's kernel cache. nvdisasm comes from $CUDA_BIN, the PATH or
/usr/local/cuda/bin (the PyPI wheel nvidia-cuda-nvdisasm carries it). Prints the samples by stall
reason in all, then the call sites (an instruction counts in every call that inlines it) and the
source lines (each instruction counts once, at its own line) with the most samples. --executed adds
the warp instructions executed (the profile's "Instructions Executed" column) by opcode, call site
and source line: where the instructions go, beside where the warps wait. --waits-on gives each
long-scoreboard sample to the load whose register it waits for (waits_on: the stack's spill reloads
LDL, global LDG, generic LD, ...), and the stack's reloads by their source line.
"""

import argparse
import collections
import csv
import gzip
import io
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sass_sites import OPCODE, instructions, register_operands, source_text, tool, writer_of  # noqa: E402

# stall reasons shown apart (ncu's column names, "stall_" dropped); the rest is summed as "other"
REASONS = ("long_sb", "no_inst", "wait", "short_sb", "branch_resolving", "selected", "math", "lg", "mio", "barrier")


def source_rows(path: str) -> list:
    """The rows (dicts by column name) of ncu's SASS source page, one per instruction in address
    order (CSV; gzip if the name ends in .gz; its first line names the kernel)."""
    raw = gzip.open(path, "rt") if path.endswith(".gz") else open(path)
    with raw:
        lines = raw.read().splitlines()
    return list(csv.DictReader(io.StringIO("\n".join(lines[1:]))))


def read_samples(path: str) -> list:
    """[(opcode, {reason: samples}, total samples)] per SASS instruction, in address order, from
    ncu's source page (source_rows)."""
    out = []
    for row in source_rows(path):
        reasons = {k[len("stall_"):]: float(v) for k, v in row.items()
                   if k.startswith("stall_") and "Not Issued" not in k and v not in ("", "-")}
        op = row["Source"].split()
        op = [t for t in op if not t.startswith("@")]
        all_samples = row["Warp Stall Sampling (All Samples)"]
        out.append((op[0] if op else "", reasons, float(all_samples) if all_samples not in ("", "-") else 0.0))
    return out


def read_executed(path: str) -> list:
    """Warp instructions executed per SASS instruction, in address order, from the same source page
    as read_samples (its "Instructions Executed" column; 0 where a row has none)."""
    rows = source_rows(path)
    if rows and "Instructions Executed" not in rows[0]:
        raise SystemExit(f"{path} has no 'Instructions Executed' column (profile with --section SourceCounters)")
    return [float(v.replace(",", "")) if (v := row["Instructions Executed"]) not in ("", "-", None) else 0.0
            for row in rows]


def executed_tables(instr: list, executed: list) -> tuple:
    """(total, by opcode, by call site, by source line): Counters of the warp instructions executed,
    from instructions() of the cubin and read_executed() of the profile, matched by position; the
    opcode without its modifiers (DFMA, LDG, ...)."""
    by_opcode = collections.Counter()
    by_site = collections.Counter()
    by_line = collections.Counter()
    for (line, sites, where), count in zip(instr, executed):
        by_opcode[opcode_of(line).split(".")[0]] += count
        for site in sites:
            by_site[site] += count
        if where is not None:
            by_line[where] += count
    return sum(executed), by_opcode, by_site, by_line


def stall_tables(instr: list, samples: list) -> tuple:
    """(totals, by call site, by source line): Counters of samples per stall reason (REASONS,
    "other" for the rest), "all" and "instructions", from instructions() of the cubin and
    read_samples() of the profile, matched by position."""
    total = collections.Counter()
    by_site = collections.defaultdict(collections.Counter)
    by_line = collections.defaultdict(collections.Counter)
    for (line, sites, where), (_op, reasons, all_samples) in zip(instr, samples):
        row = collections.Counter({r: reasons.get(r, 0.0) for r in REASONS})
        row["other"] = all_samples - sum(row.values())
        row["all"] = all_samples
        row["instructions"] = 1
        total.update(row)
        for site in sites:
            by_site[site].update(row)
        if where is not None:
            by_line[where].update(row)
    return total, by_site, by_line


# loads whose results a long-scoreboard wait can be for: local (the stack: spills), global,
# generic (the work array in shared memory is reached through a generic pointer), shared, constant
LOADS = ("LDL", "LDG", "LD", "LDS", "LDC")
def waits_on(instr: list, samples: list) -> tuple:
    """(by load opcode, by the load's source line, unattributed): the long-scoreboard samples of
    each instruction given to the load that wrote the register it waits for, found as the nearest
    earlier load (LOADS) that writes one of its source registers (sass_sites.writer_of: address
    order, within WRITER_WINDOW); a register written by another instruction first is dropped from
    the search. Address order is not control flow: a value loaded in an earlier loop
    iteration or another branch may be credited to the wrong load, and samples with no load found
    are "unattributed"."""
    operands = [register_operands(line) for line, _sites, _where in instr]
    by_op = collections.Counter()
    by_line = collections.Counter()
    unattributed = 0.0
    for k, (_op, reasons, _all) in enumerate(samples[:len(instr)]):
        waiting = reasons.get("long_sb", 0.0)
        if not waiting:
            continue
        found = writer_of(operands, k, operands[k][2], LOADS)
        if found is None:
            unattributed += waiting
            continue
        by_op[operands[found][0]] += waiting
        if instr[found][2] is not None:
            by_line[(operands[found][0],) + instr[found][2]] += waiting
    return by_op, by_line, unattributed


def opcode_of(line: str) -> str:
    m = OPCODE.search(line)
    return m.group(1) if m else ""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--csv", required=True, help="ncu's SASS source page of the profiled launch (CSV, .gz allowed)")
    ap.add_argument("--cubin", required=True, help="the profiled kernel's cubin (line info on; .gz allowed)")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--kernels", default=os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                                      "kernels"),
                    help="the profiled tree's kernels/ folder, for the source text (default: this tree's; an "
                         "older profile's lines: `git archive COMMIT kernels | tar -x -C DIR`, then DIR/kernels)")
    ap.add_argument("--executed", action="store_true",
                    help="also the warp instructions executed, by opcode, call site and source line")
    ap.add_argument("--waits-on", action="store_true",
                    help="also the long-scoreboard samples by the load they wait for (stack, global, ...) and, "
                         "for the stack's reloads, by the reload's source line")
    args = ap.parse_args(argv)
    samples = read_samples(args.csv)
    cubin = args.cubin
    if cubin.endswith(".gz"):
        with gzip.open(cubin, "rb") as packed, tempfile.NamedTemporaryFile(suffix=".cubin", delete=False) as plain:
            plain.write(packed.read())
        cubin = plain.name
    sass = subprocess.run([tool("nvdisasm"), "-g", "-gi", cubin], capture_output=True, text=True, check=True).stdout
    if cubin != args.cubin:
        os.unlink(cubin)
    instr = list(instructions(sass))
    if len(instr) != len(samples):
        raise SystemExit(f"the cubin has {len(instr)} instructions, the profile {len(samples)}: not the same kernel")
    mismatched = sum(1 for (line, _s, _w), (op, _r, _t) in zip(instr, samples)
                     if opcode_of(line).split(".")[0] != op.split(".")[0])
    if mismatched > len(instr) // 100:
        raise SystemExit(f"{mismatched} of {len(instr)} opcodes differ between the cubin and the profile")
    if not any(where for _line, _sites, where in instr):
        raise SystemExit("the cubin has no Python line information: not the line-info build (bench_engine.py --lineinfo)")
    total, by_site, by_line = stall_tables(instr, samples)
    grand = total["all"]
    print(f"{len(instr)} instructions, {grand:.0f} warp samples ({mismatched} opcodes differ); "
          + ", ".join(f"{r} {100 * total[r] / grand:.1f} %" for r in REASONS + ("other",)))
    # the table shows the first five reasons; "rest" is every other reason (selected included)
    columns = ("all",) + REASONS[:5] + ("rest",)
    head = f"{'instr':>6s} " + " ".join(f"{c[:8]:>8s}" for c in columns) + "  (% of all samples)  site"

    def show(title, table):
        print(f"\n{title}\n{head}")
        for (name, lineno), row in sorted(table.items(), key=lambda kv: -kv[1]["all"])[:args.top]:
            src = source_text(args.kernels, name, lineno)
            other = row["all"] - sum(row[r] for r in REASONS[:5])
            cells = [row["all"]] + [row[r] for r in REASONS[:5]] + [other]
            print(f"{row['instructions']:6.0f} " + " ".join(f"{100 * v / grand:8.1f}" for v in cells)
                  + f"  {name}:{lineno}  {src}")

    show("call sites (an instruction counts in every inlined call it sits in)", by_site)
    show("source lines (each instruction once, at its own line)", by_line)
    if args.waits_on:
        by_op, by_load_line, unattributed = waits_on(instr, samples)
        print("\nlong-scoreboard samples by the load waited for (% of all samples): "
              + ", ".join(f"{op} {100 * n / grand:.1f} %" for op, n in by_op.most_common())
              + f", not found {100 * unattributed / grand:.1f} %")
        print("\nthe stack's reloads (LDL) waited for, by the reload's source line (% of all samples)")
        for (op, name, lineno), n in [(k, v) for k, v in by_load_line.most_common() if k[0] == "LDL"][:args.top]:
            print(f"{100 * n / grand:6.1f}  {name}:{lineno}  {source_text(args.kernels, name, lineno)}")
    if args.executed:
        executed, by_opcode, ex_site, ex_line = executed_tables(instr, read_executed(args.csv))
        if executed <= 0:
            raise SystemExit(f"{args.csv}: no instruction executed (the profile's SourceCounters are empty)")
        print(f"\n{executed:.4g} warp instructions executed; by opcode: "
              + ", ".join(f"{op} {100 * n / executed:.1f} %" for op, n in by_opcode.most_common(12)))
        for title, table in (("call sites", ex_site), ("source lines", ex_line)):
            print(f"\n{title} by warp instructions executed (% of all)")
            for (name, lineno), n in table.most_common(args.top):
                print(f"{100 * n / executed:6.1f}  {name}:{lineno}  {source_text(args.kernels, name, lineno)}")


if __name__ == "__main__":
    main()
