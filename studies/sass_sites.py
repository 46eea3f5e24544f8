"""The integrate kernel's machine code by inlined call site, on a CUDA host: how many SASS
instructions each call in the kernel's Python source became (static counts; a function that
CUDA inlined at k sites counts k times), and of them the local-memory (stack: LDL/STL), barrier
(BAR), shared-memory (LDS/STS) and FP64-reciprocal (MUFU.RCP64H, one per division or reciprocal)
instructions; then the kernel's registers and stack (cuobjdump -res-usage).
docs/performance.md, "Instruction cache".

    python studies/sass_sites.py [--nodes 200] [--lanes 32] [--top 25] [--relaxation-gate stress]
                                 [--arch 90]

Compiles the default law's team kernel with line info (wp.config.lineinfo), disassembles its cubin
with nvdisasm (CUDA toolkit) and prints the total and the call sites with the most instructions.
Without a GPU (or with --arch), the kernel is compiled ahead of time by Warp's NVRTC for that
architecture (sm_90: the H100), which needs no driver; nvdisasm and cuobjdump then come from
$CUDA_BIN, the PATH or /usr/local/cuda/bin (the PyPI wheels nvidia-cuda-nvdisasm and
nvidia-cuda-cuobjdump carry them). WARPFRIC_TEAM_EXCHANGE picks the team's lane exchange.
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


# instruction kinds counted apart, by opcode prefix
KINDS = {"local": ("LDL", "STL"), "barrier": ("BAR",), "shared": ("LDS", "STS"), "rcp64": ("MUFU.RCP64H",),
         "shuffle": ("SHFL",)}
OPCODE = re.compile(r"/\*[0-9a-f]{4,}\*/\s+(?:@!?U?P\w+\s+)?([A-Z][A-Z0-9_.]*)")


def kind_of(line: str):
    """The KINDS key of an instruction line, or None."""
    m = OPCODE.search(line)
    if not m:
        return None
    op = m.group(1)
    for kind, prefixes in KINDS.items():
        if any(op == p or op.startswith(p + ".") for p in prefixes):
            return kind
    return None


def instructions(sass: str):
    """Each instruction of nvdisasm -g -gi output, in order, as (line, sites, where): sites, the
    frozenset of (file, line) of the inlined calls it sits in (Python files only); where, the
    (file, line) of the Python source line it belongs to (the innermost .py location), or None."""
    sites, where, comment, group = frozenset(), None, False, []
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
            own = [g for g in group if g.group(1).endswith(".py")]
            where = (os.path.basename(own[0].group(1)), int(own[0].group(2))) if own else None
            comment = False
        if INSTRUCTION.search(line):
            yield line, sites, where


def call_sites(sass: str) -> tuple:
    """(total instructions, Counter of (file, line) of the inlined calls each instruction sits in,
    {kind: Counter of the same sites for that kind's instructions}, {kind: total})."""
    counts, total = collections.Counter(), 0
    by_kind = {k: collections.Counter() for k in KINDS}
    kind_totals = collections.Counter()
    for line, sites, _where in instructions(sass):
        total += 1
        counts.update(sites)
        kind = kind_of(line)
        if kind:
            kind_totals[kind] += 1
            by_kind[kind].update(sites)
    return total, counts, by_kind, kind_totals


REGISTER = re.compile(r"\bR(\d+)(\.64)?\b")
STACK_STORE = re.compile(r"\bSTL((?:\.\w+)*)\s+\[R1(?:\+(0x[0-9a-f]+))?\]")
STORE_BYTES = {"U8": 1, "S8": 1, "U16": 2, "S16": 2, "64": 8, "128": 16}
# how far back (instructions, in address order) a register's writer is looked for
WRITER_WINDOW = 300
MEMORY_OPS = ("LD", "LDG", "LDL", "LDS", "LDC", "ST", "STG", "STL", "STS", "ATOM", "ATOMG", "ATOMS", "RED")
NO_WRITE_OPS = ("ST", "STG", "STL", "STS", "RED", "BRA", "EXIT", "BAR", "RET", "CALL", "BSSY", "BSYNC", "WARPSYNC")
WIDE_TYPES = ("F64", "S64", "U64")


def register_operands(line: str) -> tuple:
    """(opcode without modifiers, registers written, registers read) of one SASS line. Each
    operand's width in registers: a memory operation's data by its .64 / .128 suffix, its address
    registers one each (two with .64: desc[UR4][R10.64]); FP64 opcodes two each; a conversion
    (F2F, I2F, F2I) by its destination and source types; .WIDE and CS2R a pair written. Stores,
    reductions (RED), branches and barriers write nothing; SHFL writes its second operand (the
    first is a predicate). Uniform registers (UR) and predicates are not registers here."""
    text = OPCODE.search(line)
    if not text:
        return "", set(), set()
    full = text.group(1)
    parts = full.split(".")
    op = parts[0]
    body = line[text.end():].split(";")[0]
    operands = [o.strip() for o in body.split(",") if o.strip()]
    suffix = 4 if "128" in parts else 2 if "64" in parts else 1

    def regs(texts, width):
        out = set()
        for t in texts:
            for r, pair in REGISTER.findall(t):
                if "[" in t:  # an address: one register, or a pair where it says .64
                    out |= {int(r), int(r) + 1} if pair else {int(r)}
                else:
                    out |= {int(r) + k for k in range(width)}
        return out

    if op in MEMORY_OPS:
        dest_width = src_width = suffix
    elif op.startswith("D"):
        dest_width = src_width = 2
    elif op in ("F2F", "I2F", "F2I", "I2I", "F2IP"):
        types = [t for t in parts[1:] if t[:1] in "FSU" and t[1:].isdigit()]
        dest_width = 2 if types and types[0] in WIDE_TYPES and op != "F2I" else 1
        src_width = 2 if types and types[-1] in WIDE_TYPES and (len(types) > 1 or op == "F2I") else 1
    elif "WIDE" in parts or op == "CS2R" and "32" not in parts:
        dest_width, src_width = 2, 1
    else:
        dest_width = src_width = 1
    if not operands or op in NO_WRITE_OPS:
        return op, set(), regs(operands, src_width)
    first = 1 if op == "SHFL" else 0
    written = regs(operands[first:first + 1], dest_width)
    read = regs(operands[:first] + operands[first + 1:], src_width)
    if "WIDE" in parts and len(operands) > 3:  # the addend of IMAD.WIDE is a pair
        read |= regs(operands[3:4], 2)
    return op, written, read


def writer_of(operands: list, k: int, wanted: set, accept: tuple | None = None):
    """The index of the nearest instruction before k (address order, within WRITER_WINDOW) that
    writes one of the registers ``wanted``, from register_operands() of each instruction; with
    ``accept`` (opcodes), only such an instruction counts, and a register another instruction
    writes first is dropped from the search. None where there is none."""
    wanted = set(wanted)
    for j in range(k - 1, max(-1, k - WRITER_WINDOW), -1):
        op, written, _read = operands[j]
        hit = written & wanted
        if not hit:
            continue
        if accept is None or op in accept:
            return j
        wanted -= hit
        if not wanted:
            return None
    return None


def stack_bytes(sass: str) -> collections.Counter:
    """The stack (local memory: spilled registers) by the Python source line of the value first
    stored in each of its slots: for each stack offset, the first STL to it in address order, and
    the line of the nearest earlier instruction that wrote the stored register (within
    WRITER_WINDOW; else the store's own line). Bytes per (file, line); address order is not control
    flow, so this is a map of what the stack holds, not an exact account."""
    instr = list(instructions(sass))
    operands = [register_operands(line) for line, _sites, _where in instr]
    seen = set()
    out = collections.Counter()
    for k, (line, _sites, where) in enumerate(instr):
        store = STACK_STORE.search(line)
        if not store:
            continue
        offset = int(store.group(2) or "0", 16)
        if offset in seen:
            continue
        seen.add(offset)
        writer = writer_of(operands, k, operands[k][2] - {1})  # the stored registers, not the stack pointer R1
        if writer is not None:
            where = instr[writer][2] or where
        sizes = [STORE_BYTES[m] for m in store.group(1).split(".") if m in STORE_BYTES]
        out[where] += sizes[-1] if sizes else 4
    return out


def source_text(kernels: str, name: str, lineno: int, width: int = 70) -> str:
    """Line ``lineno`` of ``name`` in the folder ``kernels``, stripped and cut to ``width``
    characters; "" where there is no such file or line (an older profile read against another tree)."""
    path = os.path.join(kernels, name)
    if not os.path.exists(path):
        return ""
    with open(path) as f:
        lines = f.read().splitlines()
    return lines[lineno - 1].strip()[:width] if 0 < lineno <= len(lines) else ""


def tool(name: str) -> str:
    """A CUDA binary utility: $CUDA_BIN/name, on the PATH, or /usr/local/cuda/bin/name."""
    if os.environ.get("CUDA_BIN"):
        return os.path.join(os.environ["CUDA_BIN"], name)
    return shutil.which(name) or os.path.join("/usr/local/cuda/bin", name)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lanes", type=int, default=32)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--relaxation-gate", default="stress")
    ap.add_argument("--arch", type=int, default=None, help="compile ahead of time for this sm (no GPU needed)")
    ap.add_argument("--stack", action="store_true",
                    help="also the stack's bytes by the source line of the value first stored in each slot")
    args = ap.parse_args(argv)
    nvdisasm = tool("nvdisasm")
    wp.config.lineinfo = True
    wp.config.quiet = True
    wp.init()
    model = wf.Model(relaxation_gate=args.relaxation_gate)
    if args.arch is None and wp.get_cuda_device_count() > 0:
        wf.simulate({"eccentricity": [0.1]}, model=model, solver=wf.Solver(nodes=args.nodes, lanes=args.lanes),
                    fronts=None, device="cuda:0", progress=False)
        cubin = max(glob.glob(os.path.join(wp.config.kernel_cache_dir or os.path.expanduser("~/.cache/warp"),
                                           "**", "*integrate*.cubin"), recursive=True), key=os.path.getmtime)
    else:
        from warpfric.engine import observer_set
        from warpfric.kernels.integrator import block_threads, get_integrator, team_layout

        # the kernel simulate(fronts=None) of 10,000 members runs on an H100 (132 SMs, 227 KB of
        # shared memory a block), as on a GPU above
        layout = team_layout(args.lanes, args.nodes, 10_000, True, 132, 227 * 1024)
        built = get_integrator("float64", model, args.lanes, "tr_bdf2", cuda=True, observed=observer_set(None),
                               shared_work=layout.shared_work)
        kernel = built["integrate"]
        # as the engine launches it (warpfric/engine.py)
        kernel.module.options["block_dim"] = block_threads(args.lanes, built["blocked"])
        cubin = str(wp.compile_aot_module(kernel.module, arch=args.arch or 90, use_ptx=False,
                                          module_dir=os.path.join(wp.config.kernel_cache_dir, "sass_sites"))[0])
    sass = subprocess.run([nvdisasm, "-g", "-gi", cubin], capture_output=True, text=True, check=True).stdout
    total, counts, by_kind, kind_totals = call_sites(sass)
    print(f"SASS instructions {total} ({cubin})")
    print("of which " + ", ".join(f"{k} {kind_totals[k]}" for k in KINDS))
    kernels = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "kernels")
    print(f"{'instr':>7s} " + " ".join(f"{k:>7s}" for k in KINDS) + "  site")
    for (name, line), n in counts.most_common(args.top):
        src = source_text(kernels, name, line, 80)
        kinds = " ".join(f"{by_kind[k][(name, line)]:7d}" for k in KINDS)
        print(f"{n:7d} {kinds}  {name}:{line}  {src}")
    if args.stack:
        slots = stack_bytes(sass)
        print(f"\nstack bytes {sum(slots.values())}, by the source line of the value first stored in each slot")
        for where, n in slots.most_common(args.top):
            name, line = where if where else ("?", 0)
            print(f"{n:7d}  {name}:{line}  {source_text(kernels, name, line, 80)}")
    cuobjdump = tool("cuobjdump")
    if os.path.exists(cuobjdump):
        usage = subprocess.run([cuobjdump, "-res-usage", cubin], capture_output=True, text=True).stdout
        print("\n".join(ln.strip() for ln in usage.splitlines() if "REG" in ln or "Function" in ln))


if __name__ == "__main__":
    main()
