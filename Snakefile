"""Reproduce He, Li & Popov (2020), Figs. 5-8, from one config.

snakemake --cores 2                                 # the paper's sweep
snakemake --cores 2 --configfile config/test.yaml   # a tiny sweep
"""

from snakemake.utils import min_version, validate

min_version("9.0")


configfile: "config/config.yaml"


include: "workflow/rules/common.smk"


check_config(config, workflow.source_path("workflow/schemas/config.schema.yaml"))


validate(config, "workflow/schemas/config.schema.yaml", set_default=True)
check_cases(config)


report: "workflow/report/workflow.rst"


include: "workflow/rules/simulate.smk"
include: "workflow/rules/aggregate.smk"
include: "workflow/rules/figures.smk"


localrules:
    all,
    aggregate,
    summary,
    fig5,
    fig6,
    fig7,
    fig8,


rule all:
    default_target: True
    input:
        "results/sweep.nc",
        "results/summary.csv",
        "results/summary.md",
        expand("results/figures/fig{n}.{ext}", n=[5, 6, 7, 8], ext=["png", "pdf"]),
