"""Script of rule `simulate`: one (layout, N, kbar, seed, shape, ...) -> one curve file."""

import os

# Pin BLAS/OpenMP to the job's threads before numpy can load them (Snakemake
# sets these too; repeating them keeps the script right when run by hand).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = str(snakemake.threads)  # noqa: F821

# light; the rest is imported under the log and the SIGTERM handler
from brushcore.data.joblog import CurveClock, logged, stops_on_sigterm  # noqa: E402


def main(smk, clock: CurveClock) -> None:
    from brushcore import BrushParams, SolverOptions, simulate
    from brushcore.data.io import check_output_path, remove_stale_temporaries, write_curve
    from brushcore.data.joblog import parent_watch
    from brushcore.numerics.threads import pin_threads

    orphaned = parent_watch()  # Snakemake killed: stop, and write nothing later

    def progress(events: int, attached: int, total: int) -> None:
        clock(events, attached, total)  # for the line a SIGTERM leaves
        orphaned()

    check_output_path(smk.output[0])  # an unwritable folder fails now, not after the solve
    remove_stale_temporaries(smk.output[0])  # left by a job killed while writing
    pin_threads(smk.threads)
    w = smk.wildcards
    params = BrushParams(
        layout=w.layout,
        n_pillars=int(w.n_pillars),
        kbar=float(w.kbar),
        grid=int(w.grid),
        phi=float(w.phi),
        seed=int(w.seed),
        allow_coarse=bool(smk.config["allow_coarse"]),
        backend=smk.config["backend"],
        **smk.params.rough,  # roughness, preload, kbar_spread; {} for a flat brush
        **smk.params.shape,  # shape, aspect, orientation; {} for discs
    )
    print(f"{params} on {smk.threads} thread(s), backend {params.backend}", flush=True)
    curve = simulate(params, SolverOptions(**smk.params.solver), progress=progress)
    orphaned()
    write_curve(curve, smk.output[0])
    print(
        f"F_ad = {float(curve['adhesive_force_normalized']):.6g}, "
        f"W = {float(curve['work_of_separation_normalized']):.6g} (normalised), "
        f"{curve.attrs.get('events')} events, {curve.attrs.get('wall_time_s', float('nan')):.3g} s; "
        f"pillar radius {curve.attrs['pillar_radius_elements']:.3g} elements, "
        f"phi realised {curve.attrs['phi_actual']:.4g}"
    )


# Slurm's time limit and scancel send SIGTERM: one line in the log, status 143, no curve.
clock = CurveClock()
with logged(snakemake.log[0]), stops_on_sigterm(clock.where):  # noqa: F821
    main(snakemake, clock)  # noqa: F821
