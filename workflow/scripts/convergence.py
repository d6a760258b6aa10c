"""Script of rule `convergence`: results/sweep.nc -> F_ad, W extrapolated to h -> 0."""

import xarray as xr

from brushcore.data import figures
from brushcore.data.convergence import extrapolate_sweep, write_dataset
from brushcore.data.convergence_report import write_tables
from brushcore.data.joblog import logged


def main(smk) -> None:
    with xr.open_dataset(smk.input[0]) as sweep:
        conv = extrapolate_sweep(sweep)
    write_dataset(conv, smk.output.nc)
    write_tables(conv, smk.output.csv, smk.output.md)
    fig = figures.convergence(conv)
    for path in (smk.output.png, smk.output.pdf):
        figures.save(fig, path)
    print(open(smk.output.md).read())


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
