"""Script of rule `aggregate`: all curve files -> results/sweep.nc."""

from brushcore.data.aggregate import CaseKey, build_sweep, write_sweep
from brushcore.data.joblog import logged


def main(smk) -> None:
    # Each file must hold the case its name stands for (case fields, then phi).
    expected = [(CaseKey(*case[:-1]), case[-1]) for case in smk.params.cases]
    sweep = build_sweep(
        list(smk.input), keep_snapshots=[tuple(k) for k in smk.params.keep_snapshots],
        expected=expected,
    )
    write_sweep(sweep, smk.output[0])
    print(sweep)


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
