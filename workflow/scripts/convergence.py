"""Script of rule `convergence`: results/sweep.nc -> F_ad, W extrapolated to h -> 0."""

import xarray as xr

from brushcore.data.convergence_report import write_study
from brushcore.data.joblog import logged


def main(smk) -> None:
    with xr.open_dataset(smk.input[0]) as sweep:
        write_study(sweep, smk.output.nc, smk.output.csv, smk.output.md,
                    (smk.output.png, smk.output.pdf))
    print(open(smk.output.md).read())


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
