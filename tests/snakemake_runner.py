"""`python -m snakemake ...` for the tests' dry runs, without its start-up.

A dry run, lint or refused config is over in about a second, but a fresh
interpreter first spends 3-4 s importing Snakemake and brushcore (the rule
files import it): most of test_workflow.py's and test_lattice_workflow.py's
time.  Here each run is a child forked from a server process that imported
them once (multiprocessing's forkserver), and then runs what
``python -m snakemake ARGS`` runs, in ``workdir``, with the caller's
environment and with both output streams merged into the returned ``stdout``.
Runs that start jobs keep a fresh interpreter (`needs_fresh_process`).
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import subprocess
import sys
import tempfile

#: What the server imports once: what every `python -m snakemake` imports
#: (Snakemake's command line and workflow; brushcore through the rule files).
PRELOAD = ["snakemake.cli", "snakemake.api", "snakemake.workflow", "brushcore",
           "brushcore.data.simulate_job", "jsonschema", "yaml"]

_CONTEXT: list = []


def needs_fresh_process(args: tuple[str, ...]) -> bool:
    """True unless `args` plan without running a job (a dry run or a lint) on a
    platform with the forkserver (not Windows)."""
    return (not ({"-n", "--dry-run", "--dryrun", "--lint"} & set(args))
            or "forkserver" not in multiprocessing.get_all_start_methods())


def _context():
    if not _CONTEXT:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        _CONTEXT.append(ctx)
    return _CONTEXT[0]


def _child(workdir: str, args: tuple[str, ...], env: dict, out_path: str) -> None:
    fd = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    os.chdir(workdir)
    os.environ.clear()
    os.environ.update(env)
    sys.path.insert(0, os.getcwd())  # as `python -m` does
    import snakemake.workflow
    from snakemake.cli import main

    sys.argv = [os.path.join(os.path.dirname(snakemake.workflow.__file__), "__main__.py"),
                *args]
    snakemake.workflow.Workflow._rundir = os.getcwd()  # a class default set at import
    code = 0
    try:
        main(list(args))
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:  # noqa: BLE001  (what an interpreter prints on an uncaught error)
        import traceback

        traceback.print_exc()
        code = 1
    atexit._run_exitfuncs()  # what an interpreter runs at its end
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def run(workdir, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """``python -m snakemake *args`` in `workdir`, as `subprocess.run` with
    ``capture_output=True, text=True`` would return it (stderr merged into stdout)."""
    with tempfile.NamedTemporaryFile("r", suffix=".log") as log:
        proc = _context().Process(target=_child,
                                  args=(str(workdir), args, dict(os.environ), log.name))
        proc.start()
        proc.join(timeout)
        if proc.is_alive():
            proc.kill()
            proc.join()
            raise subprocess.TimeoutExpired([sys.executable, "-m", "snakemake", *args],
                                            timeout)
        text = log.read()
    return subprocess.CompletedProcess([sys.executable, "-m", "snakemake", *args],
                                       proc.exitcode, text, "")
