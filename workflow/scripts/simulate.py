"""Script of rule `simulate`: one (layout, N, kbar, seed) -> one curve file."""

import os

# Pin BLAS/OpenMP to the job's threads before numpy can load them (Snakemake
# sets these too; repeating them keeps the script right when run by hand).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = str(snakemake.threads)  # noqa: F821

import traceback  # noqa: E402
from contextlib import redirect_stderr, redirect_stdout  # noqa: E402
from pathlib import Path  # noqa: E402

from brushcore import BrushParams, SolverOptions, simulate  # noqa: E402
from brushcore.io import write_curve  # noqa: E402
from brushcore.threads import pin_threads  # noqa: E402


def main(smk) -> None:
    # A job killed inside write_curve leaves its hidden temporary file
    # (.<name>.*.tmp) behind; one job per output, so any such file is stale.
    out = Path(smk.output[0])
    for stale in out.parent.glob(f".{out.name}.*.tmp"):
        stale.unlink(missing_ok=True)
    pin_threads(smk.threads)
    w = smk.wildcards
    params = BrushParams(
        layout=w.layout,
        n_pillars=int(w.n_pillars),
        kbar=float(w.kbar),
        grid=int(smk.params.grid),
        phi=float(smk.params.phi),
        seed=int(w.seed),
    )
    print(f"{params} on {smk.threads} thread(s)", flush=True)
    curve = simulate(params, SolverOptions(**smk.params.solver))
    write_curve(curve, smk.output[0])
    print(
        f"F_ad = {float(curve['adhesive_force_normalized']):.6g}, "
        f"W = {float(curve['work_of_separation_normalized']):.6g} (normalised), "
        f"{curve.attrs.get('events')} events, {curve.attrs.get('wall_time_s', float('nan')):.3g} s"
    )


with open(snakemake.log[0], "w") as log, redirect_stdout(log), redirect_stderr(log):  # noqa: F821
    try:
        main(snakemake)  # noqa: F821
    except Exception:
        traceback.print_exc()
        raise
