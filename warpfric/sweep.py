"""warpfric.sweep: sweep files (TOML) and running them.

Reading and checking a sweep file lives in :mod:`warpfric.sweep_file` (format: its docstring and
docs/sweeps.md), running one in chunks in :mod:`warpfric.runner`; this module is their public face.
The runner reads sweep files, so the parser must not import the runner: that is why they are two
modules and this one imports both.
"""

from __future__ import annotations

from .runner import RunReport, run_sweep
from .sweep_file import (MEMBER_NUMBER_LIMIT, Sweep, SweepError, check_member_offset, load_sweep,  # noqa: F401
                         parse_sweep)


def run(sweep_file, output=None, **options) -> RunReport:
    """Run a sweep file in resumable chunks, here or on a Dask cluster (``client=``, ``scheduler=``,
    ``local=True``): see :func:`warpfric.runner.run_sweep`."""
    return run_sweep(sweep_file, output, **options)
