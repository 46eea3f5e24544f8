"""The profile readers of studies/ (sass_sites.py, stall_sites.py, stage_registers.py) on small
hand-written inputs:
nvdisasm's line-info comments give each instruction its call sites and its own source line, and
Nsight Compute's per-instruction warp samples are summed over them. The real inputs need a GPU
host (docs/performance.md, "Where the warps wait")."""

import gzip
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
import sass_sites  # noqa: E402
import stage_registers  # noqa: E402
import stall_sites  # noqa: E402

# three instructions, with nvdisasm -g -gi's comments (innermost frame first, the kernel's own line
# last, without "inlined at"): the first in newton.py line 10 called from integrator.py line 5; the
# second in a Warp header inlined at model_terms.py line 20, called from newton.py line 12, called
# from integrator.py line 5 (its own source line is model_terms.py 20, past the header frame); the
# third at the kernel's own line only
SASS = """\
\t//## File "/x/kernels/newton.py", line 10 inlined at "/x/kernels/integrator.py", line 5
\t//## File "/x/kernels/integrator.py", line 5
        /*0000*/                   DFMA R2, R4, R6, R2 ;
\t//## File "/tmp/site/warp/native/builtin.h", line 3 inlined at "/x/kernels/model_terms.py", line 20
\t//## File "/x/kernels/model_terms.py", line 20 inlined at "/x/kernels/newton.py", line 12
\t//## File "/x/kernels/newton.py", line 12 inlined at "/x/kernels/integrator.py", line 5
\t//## File "/x/kernels/integrator.py", line 5
        /*0010*/              @!P0 LDG.E.64 R8, desc[UR4][R10.64] ;
\t//## File "/x/kernels/integrator.py", line 7
        /*0020*/                   EXIT ;
"""

CSV = """\
"Kernel Name","integrate",
"Address","Source","Warp Stall Sampling (All Samples)","stall_long_sb","stall_no_inst","stall_wait","stall_long_sb (Not Issued)"
"0x10","      DFMA R2, R4, R6, R2","10","0","4","6","0"
"0x20","  @!P0 LDG.E.64 R8, desc[UR4][R10.64]","30","25","5","0","25"
"0x30","      EXIT","2","0","0","0","0"
"""


def test_instructions_carry_their_call_sites_and_source_line():
    got = list(sass_sites.instructions(SASS))
    assert [w for _l, _s, w in got] == [("newton.py", 10), ("model_terms.py", 20), ("integrator.py", 7)]
    assert got[0][1] == {("integrator.py", 5)}
    assert got[1][1] == {("model_terms.py", 20), ("newton.py", 12), ("integrator.py", 5)}
    assert got[2][1] == frozenset()
    total, counts, _by_kind, _kinds = sass_sites.call_sites(SASS)
    assert total == 3 and counts[("integrator.py", 5)] == 2 and counts[("newton.py", 12)] == 1
    assert counts[("model_terms.py", 20)] == 1


@pytest.mark.parametrize("packed", [False, True])
def test_warp_samples_are_summed_by_site_and_line(tmp_path, packed):
    path = tmp_path / ("s.csv.gz" if packed else "s.csv")
    if packed:
        with gzip.open(path, "wt") as f:
            f.write(CSV)
    else:
        path.write_text(CSV)
    samples = stall_sites.read_samples(str(path))
    assert [op for op, _r, _a in samples] == ["DFMA", "LDG.E.64", "EXIT"]
    # the "(Not Issued)" columns are a subset of the samples, not more of them
    assert samples[1][1] == {"long_sb": 25.0, "no_inst": 5.0, "wait": 0.0}
    total, by_site, by_line = stall_sites.stall_tables(list(sass_sites.instructions(SASS)), samples)
    assert total["all"] == 42 and total["long_sb"] == 25 and total["no_inst"] == 9 and total["wait"] == 6
    assert total["other"] == 2  # EXIT's samples, under no named reason
    assert by_site[("integrator.py", 5)]["all"] == 40 and by_site[("newton.py", 12)]["long_sb"] == 25
    assert by_line[("newton.py", 10)]["all"] == 10 and by_line[("model_terms.py", 20)]["all"] == 30
    assert by_line[("integrator.py", 7)]["all"] == 2
    assert sum(row["instructions"] for row in by_line.values()) == 3


def _fake_nvdisasm(tmp_path, text):
    """A CUDA_BIN folder whose nvdisasm prints ``text`` (the cubin is not read)."""
    (tmp_path / "sass.txt").write_text(text)
    tool = tmp_path / "nvdisasm"
    tool.write_text(f"#!/bin/sh\ncat {tmp_path / 'sass.txt'}\n")
    tool.chmod(0o755)
    return str(tmp_path)


def test_stall_sites_prints_the_tables_and_refuses_another_kernel(tmp_path, monkeypatch, capsys):
    (tmp_path / "s.csv").write_text(CSV)
    (tmp_path / "k.cubin").write_bytes(b"")
    monkeypatch.setenv("CUDA_BIN", _fake_nvdisasm(tmp_path, SASS))
    stall_sites.main(["--csv", str(tmp_path / "s.csv"), "--cubin", str(tmp_path / "k.cubin")])
    out = capsys.readouterr().out
    assert out.startswith("3 instructions, 42 warp samples (0 opcodes differ); long_sb 59.5 %")
    # integrator.py:5 holds 40 of the 42 samples
    assert any(line.split()[1:2] == ["95.2"] and "integrator.py:5" in line for line in out.splitlines())
    # a cubin with one instruction fewer is another kernel
    monkeypatch.setenv("CUDA_BIN", _fake_nvdisasm(tmp_path, SASS.rsplit("\t//##", 1)[0]))
    with pytest.raises(SystemExit, match="not the same kernel"):
        stall_sites.main(["--csv", str(tmp_path / "s.csv"), "--cubin", str(tmp_path / "k.cubin")])
    # a build without line information has no Python locations
    bare = "\n".join(line for line in SASS.splitlines() if "//##" not in line)
    monkeypatch.setenv("CUDA_BIN", _fake_nvdisasm(tmp_path, bare))
    with pytest.raises(SystemExit, match="no Python line information"):
        stall_sites.main(["--csv", str(tmp_path / "s.csv"), "--cubin", str(tmp_path / "k.cubin")])


CSV_EXECUTED = """\
"Kernel Name","integrate",
"Address","Source","Warp Stall Sampling (All Samples)","Instructions Executed","stall_long_sb"
"0x10","      DFMA R2, R4, R6, R2","10","100","0"
"0x20","  @!P0 LDG.E.64 R8, desc[UR4][R10.64]","30","1,000","25"
"0x30","      EXIT","2","7","0"
"""


def test_instructions_executed_are_summed_by_opcode_site_and_line(tmp_path, monkeypatch, capsys):
    path = tmp_path / "s.csv"
    path.write_text(CSV_EXECUTED)
    executed = stall_sites.read_executed(str(path))
    assert executed == [100.0, 1000.0, 7.0]  # ncu's thousands separator read
    total, by_opcode, by_site, by_line = stall_sites.executed_tables(list(sass_sites.instructions(SASS)), executed)
    assert total == 1107
    assert by_opcode == {"DFMA": 100, "LDG": 1000, "EXIT": 7}  # predicate and modifiers dropped
    assert by_site[("integrator.py", 5)] == 1100 and by_site[("newton.py", 12)] == 1000
    assert by_site[("model_terms.py", 20)] == 1000 and ("integrator.py", 7) not in by_site
    assert by_line == {("newton.py", 10): 100, ("model_terms.py", 20): 1000, ("integrator.py", 7): 7}
    (tmp_path / "k.cubin").write_bytes(b"")
    monkeypatch.setenv("CUDA_BIN", _fake_nvdisasm(tmp_path, SASS))
    stall_sites.main(["--csv", str(path), "--cubin", str(tmp_path / "k.cubin"), "--executed"])
    out = capsys.readouterr().out
    assert "1107 warp instructions executed; by opcode: LDG 90.3 %, DFMA 9.0 %, EXIT 0.6 %" in out
    assert any(line.split()[:2] == ["99.4", "integrator.py:5"] for line in out.splitlines())
    # a profile without the column (no SourceCounters section) is refused by name
    (tmp_path / "bare.csv").write_text(CSV)
    with pytest.raises(SystemExit, match="no 'Instructions Executed' column"):
        stall_sites.read_executed(str(tmp_path / "bare.csv"))


# a long-scoreboard wait and the load it waits for: DADD reads the pair R4:R5 that the stack
# reload LDL.64 wrote; DMUL reads R12 (DADD's, not a load: dropped) and R8 (the global load's);
# FADD reads R2, written by a MOV (no load: the reload of R2 before it is not waited for); the
# store reads R7 of a 32-bit stack reload
SASS_WAITS = """\
\t//## File "/x/kernels/esdirk.py", line 3
        /*0000*/                   LDL R2, [R1+0x30] ;
        /*0008*/                   LDL.64 R4, [R1+0x10] ;
\t//## File "/x/kernels/newton.py", line 8
        /*0010*/                   LDG.E.64 R8, desc[UR4][R10.64] ;
        /*0020*/                   MOV R2, R3 ;
        /*0030*/                   DADD R12, R4, 1 ;
        /*0040*/                   DMUL R14, R8, R12 ;
        /*0050*/                   FADD R6, R2, R2 ;
\t//## File "/x/kernels/gates.py", line 5
        /*0060*/                   LDL R7, [R1+0x20] ;
        /*0070*/                   STG.E desc[UR4][R10.64], R7 ;
"""

CSV_WAITS = """\
"Kernel Name","integrate",
"Address","Source","Warp Stall Sampling (All Samples)","stall_long_sb","stall_wait"
"0x00","      LDL R2, [R1+0x30]","1","0","0"
"0x00","      LDL.64 R4, [R1+0x10]","1","0","0"
"0x10","      LDG.E.64 R8, desc[UR4][R10.64]","1","0","0"
"0x20","      MOV R2, R3","1","0","1"
"0x30","      DADD R12, R4, 1","20","20","0"
"0x40","      DMUL R14, R8, R12","12","10","2"
"0x50","      FADD R6, R2, R2","3","3","0"
"0x60","      LDL R7, [R1+0x20]","1","0","0"
"0x70","      STG.E desc[UR4][R10.64], R7","7","7","0"
"""


def test_a_stored_pair_waits_on_the_load_of_the_pair(tmp_path):
    """A 64-bit store waits for the 64-bit load of its pair, not for a 32-bit stack reload of a
    register next to the stack pointer (an operand width applied to every operand would read R2
    in [R1+0x8])."""
    sass = """\
\t//## File "/x/kernels/newton.py", line 8
        /*0000*/                   LDG.E.64 R4, desc[UR4][R10.64] ;
\t//## File "/x/kernels/esdirk.py", line 3
        /*0010*/                   LDL R2, [R1+0x30] ;
        /*0020*/                   STL.64 [R1+0x8], R4 ;
"""
    (tmp_path / "s.csv").write_text('"Kernel Name","integrate",\n"Address","Source","Warp Stall Sampling (All Samples)",'
                                    '"stall_long_sb"\n"0x00","LDG.E.64 R4","1","0"\n"0x10","LDL R2","1","0"\n'
                                    '"0x20","STL.64 [R1+0x8], R4","9","9"\n')
    by_op, by_line, unattributed = stall_sites.waits_on(list(sass_sites.instructions(sass)),
                                                        stall_sites.read_samples(str(tmp_path / "s.csv")))
    assert by_op == {"LDG": 9} and by_line == {("LDG", "newton.py", 8): 9} and unattributed == 0


def test_long_scoreboard_waits_are_given_to_the_load_they_wait_for(tmp_path, monkeypatch, capsys):
    ops = sass_sites.register_operands
    assert ops("/*0000*/ DFMA R2, R4, R6, R2 ;") == ("DFMA", {2, 3}, {2, 3, 4, 5, 6, 7})
    assert ops("/*0000*/ @!P0 LDG.E.128 R8, desc[UR4][R2.64] ;") == ("LDG", {8, 9, 10, 11}, {2, 3})
    assert ops("/*0000*/ LDG.E R8, desc[UR4][R10.64] ;") == ("LDG", {8}, {10, 11})
    assert ops("/*0000*/ STL [R1+0x8], R5 ;") == ("STL", set(), {1, 5})
    assert ops("/*0000*/ STL.64 [R1+0x8], R4 ;") == ("STL", set(), {1, 4, 5})
    assert ops("/*0000*/ RED.E.ADD.STRONG.GPU desc[UR4][R2.64], R5 ;") == ("RED", set(), {2, 3, 5})
    assert ops("/*0000*/ SHFL.BFLY PT, R5, R4, 0x1, 0x1f ;") == ("SHFL", {5}, {4})
    assert ops("/*0000*/ IMAD.WIDE.U32 R10, R3, UR6, R10 ;") == ("IMAD", {10, 11}, {3, 10, 11})
    assert ops("/*0000*/ CS2R R4, SRZ ;") == ("CS2R", {4, 5}, set())
    assert ops("/*0000*/ F2F.F64.F32 R4, R2 ;") == ("F2F", {4, 5}, {2})
    assert ops("/*0000*/ F2I.F64.TRUNC R4, R2 ;") == ("F2I", {4}, {2, 3})
    assert ops("/*0000*/ ISETP.GE.AND P0, PT, R36, RZ, PT ;") == ("ISETP", set(), {36})
    instr = list(sass_sites.instructions(SASS_WAITS))
    (tmp_path / "s.csv").write_text(CSV_WAITS)
    by_op, by_line, unattributed = stall_sites.waits_on(instr, stall_sites.read_samples(str(tmp_path / "s.csv")))
    assert by_op == {"LDL": 27, "LDG": 10} and unattributed == 3
    assert by_line == {("LDL", "esdirk.py", 3): 20, ("LDG", "newton.py", 8): 10, ("LDL", "gates.py", 5): 7}
    (tmp_path / "k.cubin").write_bytes(b"")
    monkeypatch.setenv("CUDA_BIN", _fake_nvdisasm(tmp_path, SASS_WAITS))
    stall_sites.main(["--csv", str(tmp_path / "s.csv"), "--cubin", str(tmp_path / "k.cubin"), "--waits-on"])
    out = capsys.readouterr().out
    # 47 samples in all: the stack 27 (57.4 %), global 10 (21.3 %), no load 3 (6.4 %)
    assert "by the load waited for (% of all samples): LDL 57.4 %, LDG 21.3 %, not found 6.4 %" in out
    reloads = out.split("by the reload's source line")[1].splitlines()[1:3]
    assert [r.split()[:2] for r in reloads] == [["42.6", "esdirk.py:3"], ["14.9", "gates.py:5"]]


# the stack's slots by the value first stored there: 0x8 holds a pair loaded at newton.py 8 (the
# store itself sits at integrator.py 2), stored again later (not counted twice); 0x10 a 32-bit sum
# of esdirk.py 4, 0x28 a byte of it; 0x18 a 128-bit store of a register no instruction before it
# writes (its own line)
SASS_STACK = """\
\t//## File "/x/kernels/newton.py", line 8
        /*0000*/                   LDG.E.64 R4, desc[UR4][R10.64] ;
\t//## File "/x/kernels/esdirk.py", line 4
        /*0010*/                   IADD3 R7, R2, R3, RZ ;
\t//## File "/x/kernels/integrator.py", line 2
        /*0020*/                   STL.64 [R1+0x8], R4 ;
        /*0030*/                   STL [R1+0x10], R7 ;
        /*0040*/                   STL.64 [R1+0x8], R6 ;
        /*0050*/                   STL.128 [R1+0x18], R12 ;
        /*0060*/                   STL.U8 [R1+0x28], R7 ;
"""


def test_stack_bytes_by_the_line_of_the_stored_value():
    assert sass_sites.stack_bytes(SASS_STACK) == {("newton.py", 8): 8, ("esdirk.py", 4): 5, ("integrator.py", 2): 16}


# cuobjdump -res-usage of a cubin with the kernel and one function kept out of line (the format of
# CUDA 13.4's cuobjdump)
RES_USAGE = """\

Resource usage:
 Common:
  GLOBAL:154 CONSTANT[3]:5720 CONSTANT[4]:336
 Function friction_at_gate_0:
  REG:96 STACK:48 SHARED:0 LOCAL:0 CONSTANT[0]:0 TEXTURE:0 SURFACE:0 SAMPLER:0
 Function piece_kernel__locals__stage_piece_4bf00729_cuda_kernel_forward:
  REG:128 STACK:1256 SHARED:25856 LOCAL:0 CONSTANT[0]:1520 TEXTURE:0 SURFACE:0 SAMPLER:0
"""


def test_stage_registers_reads_the_kernels_registers_and_stack():
    assert stage_registers.parse_res_usage(RES_USAGE) == (128, 1256)
    with pytest.raises(RuntimeError, match="no REG/STACK line"):
        stage_registers.parse_res_usage("Resource usage:\n Common:\n  GLOBAL:0\n")
