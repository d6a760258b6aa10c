"""Script of rule `curve_figure`: one curve file -> one figure."""

from brushcore.data import figures
from brushcore.data.io import read_curve
from brushcore.data.joblog import logged


def main(smk) -> None:
    fig = getattr(figures, smk.params.figure)(read_curve(smk.input[0]))
    for path in smk.output:
        figures.save(fig, path)
        print(f"wrote {path}")


with logged(snakemake.log[0]):  # noqa: F821
    main(snakemake)  # noqa: F821
