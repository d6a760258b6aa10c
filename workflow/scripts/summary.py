"""Script of rule `summary`: results/sweep.nc -> headline table (CSV, Markdown)."""

import xarray as xr

from brushcore.data.summary import headline_rows, write_summary
from brushcore.data.joblog import logged


def main(smk) -> None:
    fig5 = smk.params.fig5
    with xr.open_dataset(smk.input[0]) as sweep:
        rows = headline_rows(
            sweep, fig5_layout=fig5["layout"], fig5_n_pillars=int(fig5["n_pillars"]),
            fig5_kbar=float(fig5["kbar"][0]) if fig5["kbar"] else float("nan"),
            fig5_shape=fig5["shape"],
        )
    write_summary(rows, smk.output.csv, smk.output.md)
    print(open(smk.output.md).read())


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
