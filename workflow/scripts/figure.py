"""Script of the sweep figures (fig5-fig8, rough, lattices): results/sweep.nc -> PNG + PDF."""

import xarray as xr

from brushcore.data import figures
from brushcore.data.views import flat_slice, shape_slice
from brushcore.data.joblog import logged


def main(smk) -> None:
    draw = getattr(figures, smk.params.figure)
    with xr.open_dataset(smk.input[0]) as sweep:
        # The paper's figures show the flat brushes of one pillar shape (discs unless
        # Fig. 5 asks for another); the rough ones the whole sweep of that shape;
        # shape None (the lattice figure) keeps every shape.
        flat = smk.params.get("flat", True)
        shape = smk.params.get("shape", "disc")
        sweep = flat_slice(sweep, shape) if flat else shape_slice(sweep, shape)
        fig = draw(sweep, **dict(smk.params.options))
    for path in smk.output:
        figures.save(fig, path)
        print(f"wrote {path}")


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
