"""Script of rules `fig5`-`fig8`: results/sweep.nc -> one figure (PNG + PDF)."""

import xarray as xr

from brushcore.data import figures
from brushcore.data.aggregate import flat_slice
from brushcore.data.joblog import logged


def main(smk) -> None:
    draw = getattr(figures, smk.params.figure)
    with xr.open_dataset(smk.input[0]) as sweep:
        # The paper's figures show the flat brushes; the rough ones the whole sweep.
        flat = smk.params.get("flat", True)
        fig = draw(flat_slice(sweep) if flat else sweep, **dict(smk.params.options))
    for path in smk.output:
        figures.save(fig, path)
        print(f"wrote {path}")


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
