"""Script of rule `simulate`: one (layout, N, kbar, seed, shape, ...) -> one curve file.

A stub on purpose: Snakemake reruns every finished curve when this file
changes, so the job lives in `brushcore.data.simulate_job`.
"""

import os

# Pin BLAS/OpenMP to the job's threads before numpy can load them (Snakemake
# sets these too; repeating them keeps the script right when run by hand).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = str(snakemake.threads)  # noqa: F821

from brushcore.data.simulate_job import run_job  # noqa: E402 - light: numpy loads under the log

run_job(snakemake)  # noqa: F821
