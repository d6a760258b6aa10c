"""Script of rule `aggregate`: all curve files -> results/sweep.nc."""

from brushcore.data.aggregate import build_sweep, write_sweep
from brushcore.data.joblog import logged


def main(smk) -> None:
    sweep = build_sweep(
        list(smk.input), keep_snapshots=[tuple(k) for k in smk.params.keep_snapshots]
    )
    write_sweep(sweep, smk.output[0])
    print(sweep)


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
