"""Script of rule `aggregate`: all curve files -> results/sweep.nc."""

import traceback
from contextlib import redirect_stderr, redirect_stdout

from brushcore.aggregate import build_sweep, write_sweep


def main(smk) -> None:
    sweep = build_sweep(
        list(smk.input), keep_snapshots=[tuple(k) for k in smk.params.keep_snapshots]
    )
    write_sweep(sweep, smk.output[0])
    print(sweep)


with open(snakemake.log[0], "w") as log, redirect_stdout(log), redirect_stderr(log):  # noqa: F821
    try:
        main(snakemake)  # noqa: F821
    except Exception:
        traceback.print_exc()
        raise
