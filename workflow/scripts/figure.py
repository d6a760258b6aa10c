"""Script of rules `fig5`-`fig8`: results/sweep.nc -> one figure (PNG + PDF)."""

import traceback
from contextlib import redirect_stderr, redirect_stdout

import xarray as xr

from brushcore import figures


def main(smk) -> None:
    draw = getattr(figures, smk.params.figure)
    with xr.open_dataset(smk.input[0]) as sweep:
        fig = draw(sweep, **dict(smk.params.options))
    for path in smk.output:
        figures.save(fig, path)
        print(f"wrote {path}")


with open(snakemake.log[0], "w") as log, redirect_stdout(log), redirect_stderr(log):  # noqa: F821
    try:
        main(snakemake)  # noqa: F821
    except Exception:
        traceback.print_exc()
        raise
