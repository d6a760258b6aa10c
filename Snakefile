"""Reproduce He, Li & Popov (2020), Figs. 5-8, from one config.

snakemake --cores 2                                 # the paper's sweep
snakemake --cores 2 --configfile config/test.yaml   # a tiny sweep
snakemake --cores 2 --configfile config/convergence.yaml   # mesh refinement
"""

from snakemake.logging import logger
from snakemake.utils import min_version, validate

from brushcore.model.provenance import other_code

min_version("9.0")


configfile: "config/config.yaml"


include: "workflow/rules/config_checks.smk"
include: "workflow/rules/cases.smk"
include: "workflow/rules/resources.smk"
include: "workflow/rules/targets.smk"
include: "workflow/rules/layout_files.smk"


check_config_files(workflow.configfiles)
check_config(config, workflow.source_path("workflow/schemas/config.schema.yaml"))


validate(config, "workflow/schemas/config.schema.yaml", set_default=True)
canonical_solver(config, workflow.source_path("workflow/schemas/config.schema.yaml"))
# The Snakemake that plans the run, not one running a job (locally or on Slurm).
planning = not (workflow.remote_exec or workflow.subprocess_exec)
check_cases(config, main=planning)
check_cluster_threads(
    config,
    workflow.resource_settings.cores,
    workflow.resource_settings.nodes,
    main=planning,
)
if clipped := clipped_runtimes(config):  # one walk over the sweep's cases
    logger.warning(clipped)
if planning and (
    other := other_code(workflow.basedir)
):  # the code the curves will name
    logger.warning(f"brushcore: {other}")


report: "workflow/report/workflow.rst"


include: "workflow/rules/simulate.smk"
include: "workflow/rules/aggregate.smk"
include: "workflow/rules/figures.smk"
include: "workflow/rules/convergence.smk"


localrules:
    all,
    aggregate,
    summary,
    fig5,
    fig6,
    fig7,
    fig8,
    rough_figure,
    curve_figure,
    convergence,
    lattices,
    rigid_phi,


rule all:
    default_target: True
    input:
        sweep_targets(config),


# Once the executor and the groups are known (not while the Snakefile is read):
# a local run with backend gpu needs CuPy and a card here, a cluster's jobs on
# their node; a cluster's bundles of fine-grid curves are warned of (not in
# a dry run).
onstart:
    check_local_backend(config, workflow.local_exec)
    groups = {} if workflow.local_exec else workflow.group_settings.group_components
    if bundled := bundled_fine_grids(config, groups):
        logger.warning(bundled)


# Figures and tables an earlier sweep made that this config does not: they stay
# in results/ beside this sweep's files, and would be read as this sweep's.
onsuccess:
    if stale := stale_outputs(config):
        logger.warning(stale)
