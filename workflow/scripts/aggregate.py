"""Script of rule `aggregate`: all curve files -> results/sweep.nc."""

import sys

import yaml

from brushcore.data.aggregate import (AggregationError, CaseKey, build_sweep, mixed_runs,
                                      write_sweep)
from brushcore.data.joblog import logged


def main(smk) -> None:
    # Each file must hold the case its name stands for (case fields, then phi).
    expected = [(CaseKey(*case[:-1]), case[-1]) for case in smk.params.cases]
    sweep = build_sweep(
        list(smk.input), keep_snapshots=[tuple(k) for k in smk.params.keep_snapshots],
        expected=expected,
    )
    # The config that made it, for a methods section; read here, not as a param,
    # so that keys that change no curve (threads, backend) rerun nothing.
    sweep.attrs["workflow_config"] = yaml.safe_dump(dict(smk.config), sort_keys=True)
    write_sweep(sweep, smk.output[0])
    print(sweep)
    mixed = mixed_runs(sweep)
    if mixed:  # on the terminal too: the log alone would hide it
        note = (f"{smk.output[0]}: its curves differ in {mixed}; "
                "`snakemake -R simulate` recomputes them alike")
        print(note)
        print(note, file=sys.__stderr__, flush=True)


with logged(snakemake.log[0]):  # noqa: F821
    try:
        main(snakemake)  # noqa: F821
    except AggregationError as exc:  # explained: its message, not a traceback
        print(exc)
        print(f"aggregate: {exc}", file=sys.__stderr__, flush=True)
        raise SystemExit(1) from None
