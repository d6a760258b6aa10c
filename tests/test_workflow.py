"""The Snakemake workflow end to end, on a temporary copy of the repository.

The tiny sweep of ``config/test.yaml`` runs once per module (fixture
`test_run`); the other tests inspect its outputs or ask Snakemake for dry
runs, lint and config validation, which start no job.
"""

from __future__ import annotations

import math
import re
import shutil
import hashlib
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

xr = pytest.importorskip("xarray")
pytest.importorskip("snakemake")

import snakemake_runner  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: The rule files of plain Python helpers, in the Snakefile's order.
RULE_HELPERS = ("config_checks.smk", "cases.smk", "resources.smk", "targets.smk",
                "layout_files.smk")
SNAKEMAKE = [sys.executable, "-m", "snakemake"]
FIGURES = [f"fig{n}.{ext}" for n in (5, 6, 7, 8) for ext in ("png", "pdf")]
CASE_DIMS = ("layout", "n_pillars", "kbar", "seed")
SWEEP_DIMS = (*CASE_DIMS, "grid")
SCALARS = (
    "adhesive_force_normalized",
    "work_of_separation_normalized",
    "adhesive_force",
    "work_of_separation",
    "events",
    "operator_applications",
    "wall_time_s",
)
CURVES = (
    "displacement",
    "force",
    "displacement_normalized",
    "force_normalized",
    "contact_area",
    "attached_pillars",
)
# Things a run leaves behind that must not leak into the copy.
IGNORE = shutil.ignore_patterns(
    ".git", ".snakemake", "results", "logs", "__pycache__", "*.egg-info", ".pytest_cache",
    ".hypothesis", "report.html",
)


def snakemake(workdir: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run Snakemake in `workdir`, capturing its (merged) output.  Dry runs and
    lint run in a child of a process that imported Snakemake and brushcore
    already (`snakemake_runner`): the same command, 3-4 s less start-up each."""
    if not snakemake_runner.needs_fresh_process(args):
        return snakemake_runner.run(workdir, *args, timeout=timeout)
    return subprocess.run(
        [*SNAKEMAKE, *args], cwd=workdir, capture_output=True, text=True, timeout=timeout
    )


def output(proc: subprocess.CompletedProcess) -> str:
    return proc.stdout + proc.stderr


def expected_cases(config: dict) -> set[tuple[str, int, float, int]]:
    """The (layout, N, kbar, seed) a config asks for, counted independently of the rules."""
    cases = {("regular", n, float(k), 0) for n in config["regular"] for k in config["kbar"]}
    cases |= {("regular", config["fig5"]["n_pillars"], float(k), 0) for k in config["fig5"]["kbar"]}
    cases |= {("random", n, float(k), s) for n in config["random"] for k in config["kbar"]
              for s in config["seeds"]}
    return cases


def planned_simulations(text: str) -> int:
    match = re.search(r"^simulate\s+(\d+)\s*$", text, flags=re.MULTILINE)
    assert match, f"no simulate line in the job stats:\n{text}"
    return int(match.group(1))


@pytest.fixture(scope="module")
def repo_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The repository without results, Snakemake state or git, in a temp dir."""
    dest = tmp_path_factory.mktemp("workflow") / "repo"
    shutil.copytree(REPO, dest, ignore=IGNORE)
    return dest


@pytest.fixture(scope="module")
def test_run(repo_copy: Path) -> Path:
    """Run the test sweep once end to end; return the working directory."""
    proc = snakemake(repo_copy, "--cores", "2", "--configfile", "config/test.yaml")
    assert proc.returncode == 0, f"test sweep failed:\n{output(proc)[-6000:]}"
    return repo_copy


@pytest.fixture(scope="module")
def test_config(repo_copy: Path) -> dict:
    return yaml.safe_load((repo_copy / "config/test.yaml").read_text())


def test_sweep_dataset(test_run: Path, test_config: dict) -> None:
    with xr.open_dataset(test_run / "results/sweep.nc") as sweep:
        for dim in (*SWEEP_DIMS, "step"):
            assert dim in sweep.dims, f"sweep.nc lacks dimension {dim}"
        assert sweep["grid"].values.tolist() == [test_config["grid"]]
        sweep = sweep.squeeze("grid", drop=True)  # one grid: the rest is as before
        for name in SCALARS:
            assert sweep[name].dims == CASE_DIMS, f"{name} has dims {sweep[name].dims}"
        for name in CURVES:
            assert sweep[name].dims == (*CASE_DIMS, "step"), f"{name}: {sweep[name].dims}"
        for attr in ("brushcore_version", "git_commit", "source_files", "date_created", "Conventions"):
            assert attr in sweep.attrs, f"sweep.nc lacks provenance attribute {attr}"
        # the config that made it, after every --configfile: the test config over the default
        made_by = yaml.safe_load(sweep.attrs["workflow_config"])
        assert made_by["grid"] == test_config["grid"] and made_by["kbar"] == test_config["kbar"]
        default = yaml.safe_load((test_run / "config/config.yaml").read_text())["solver"]
        assert default.items() <= made_by["solver"].items()  # with the schema's defaults

        cases = expected_cases(test_config)
        assert set(sweep.layout.values) == {c[0] for c in cases}
        assert set(sweep.n_pillars.values.tolist()) == {c[1] for c in cases}
        assert np.allclose(sorted(sweep.kbar.values), sorted({c[2] for c in cases}))
        ran = np.zeros(tuple(sweep.sizes[d] for d in CASE_DIMS), dtype=bool)
        for layout, n, kbar, seed in cases:
            case = sweep.sel(layout=layout, n_pillars=n, kbar=kbar, seed=seed)
            ran[tuple(int(np.flatnonzero(sweep[d].values == v)[0])
                      for d, v in zip(CASE_DIMS, (layout, n, kbar, seed)))] = True
            for name in SCALARS:
                assert math.isfinite(float(case[name])), f"{name} is NaN for run {case}"
            steps = int(case["n_steps"])
            for name in CURVES:
                values = case[name].values
                assert np.isfinite(values[:steps]).all(), f"{name} has NaN inside the curve"
                assert np.isnan(values[steps:]).all(), f"{name} is not NaN-padded"
        # combinations not run are NaN
        assert np.isnan(sweep["adhesive_force_normalized"].values[~ran]).all()
        assert "contact_snapshot" in sweep, "Fig. 5 snapshots missing from sweep.nc"


def test_figures_and_summary(test_run: Path) -> None:
    for name in FIGURES:
        path = test_run / "results/figures" / name
        assert path.is_file() and path.stat().st_size > 0, f"{path} missing or empty"
    summary = (test_run / "results/summary.csv").read_text()
    assert summary.startswith("quantity,") and "n/a" in summary  # 2304 pillars not in test sweep


def test_readme_reads_the_sweep(test_run: Path, test_config: dict, monkeypatch) -> None:
    """The README's "Reading `results/sweep.nc`" code runs on a sweep the
    workflow made, with the test config's Fig. 5 brush in place of 16 x 16."""
    text = (REPO / "README.md").read_text()
    section = text[text.index("## Reading `results/sweep.nc`"):]
    code = section[section.index("```python") + len("```python"):]
    code = code[:code.index("```")]
    n = test_config["fig5"]["n_pillars"]
    assert code.count("256") == 3, code  # the Fig. 5 brush, as the README names it
    code = code.replace("n_pillars=256", f"n_pillars={n}").replace('"regular", 256', f'"regular", {n}')
    monkeypatch.chdir(test_run)
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)  # noqa: S102 - the README's own snippet
    table = scope["table"]  # N x kbar, random brushes
    for n_random in test_config["random"]:
        assert np.isfinite(table.loc[n_random, test_config["kbar"]].to_numpy()).all(), table
    assert scope["curve"].sizes["step"] == int(scope["run"].n_steps) > 2
    assert tuple(scope["snaps"].dims) == ("snapshot", "y", "x")


def test_second_run_does_nothing(test_run: Path) -> None:
    proc = snakemake(test_run, "--cores", "2", "--configfile", "config/test.yaml")
    assert proc.returncode == 0, output(proc)
    assert "Nothing to be done" in output(proc), output(proc)


def test_keys_that_change_no_curve_rerun_nothing(test_run: Path, tmp_path: Path) -> None:
    """allow_coarse and backend decide whether and where a case runs, not its
    curve: setting them plans no simulation over a finished sweep."""
    config = tmp_path / "same.yaml"
    config.write_text(yaml.safe_dump({"allow_coarse": True, "backend": "cpu"}))
    proc = snakemake(test_run, "-n", "--configfile", "config/test.yaml", str(config))
    assert proc.returncode == 0, output(proc)
    assert "Nothing to be done" in output(proc), output(proc)
    # Nor do the solver's defaults written out in another order (they reran
    # every curve: Snakemake compares the param as written).
    config.write_text("solver:\n  settle_decisions: true\n  cascade: local\n  rtol: 1.0e-4\n")
    proc = snakemake(test_run, "-n", "--configfile", "config/test.yaml", str(config))
    assert "Nothing to be done" in output(proc), output(proc)


def test_report(test_run: Path) -> None:
    proc = snakemake(test_run, "--configfile", "config/test.yaml", "--report", "report.html")
    assert proc.returncode == 0, output(proc)
    assert (test_run / "report.html").stat().st_size > 0


def test_default_config_plans_paper_grid(repo_copy: Path) -> None:
    config = yaml.safe_load((repo_copy / "config/config.yaml").read_text())
    proc = snakemake(repo_copy, "-n", "--cores", "2")
    assert proc.returncode == 0, output(proc)
    assert planned_simulations(output(proc)) == len(expected_cases(config))
    # the paper's grid, at two or more kbar per decade over 1e-6 ... 1e2
    assert config["regular"] == [64, 256, 576, 2304] and config["random"] == [64, 220, 425, 1620]
    decades = np.floor(np.log10(config["kbar"]) + 1e-9)
    assert all((decades == d).sum() >= 2 for d in range(-6, 2))


def test_readme_example_sweep_plans(repo_copy: Path, tmp_path: Path) -> None:
    """The README's "Editing a sweep" file plans, merged over the default config,
    exactly the cases it names (the default's kbar and Fig. 5 brush kept)."""
    text = (REPO / "README.md").read_text()
    start = text.index("cat > my-sweep.yaml <<'EOF'\n") + len("cat > my-sweep.yaml <<'EOF'\n")
    example = text[start:text.index("EOF\n", start)]
    (tmp_path / "my-sweep.yaml").write_text(example)
    proc = snakemake(repo_copy, "-n", "--forceall", "--configfile", str(tmp_path / "my-sweep.yaml"))
    assert proc.returncode == 0, output(proc)[-3000:]
    merged = {**yaml.safe_load((REPO / "config/config.yaml").read_text()),
              **yaml.safe_load(example)}
    assert planned_simulations(output(proc)) == len(expected_cases(merged))


def test_default_config_makes_no_convergence_study(repo_copy: Path) -> None:
    proc = snakemake(repo_copy, "-n", "--cores", "2")
    assert proc.returncode == 0, output(proc)
    assert "rule convergence" not in output(proc)


def test_values_no_brush_reads_are_said_at_plan_time(repo_copy: Path, tmp_path: Path) -> None:
    """A seed only flat lattices would run, a spread of rigid pillars and a
    rough brush at preload 0 (first touch) each plan, with a warning."""
    config = tmp_path / "unused.yaml"
    config.write_text(yaml.safe_dump({
        "regular": [4], "random": [], "kbar": [float("inf")], "seeds": [0, 3],
        "kbar_spread": [0.0, 0.3], "roughness": [0.0, 0.2], "fig5": {"kbar": []}}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config))
    text = output(proc)
    assert proc.returncode == 0, text
    assert "'kbar_spread' holds [0.3], which no brush of the sweep runs" in text, text
    assert "'roughness' holds [0.2] and 'preload' holds 0.0: a rough brush's approach" in text
    assert "'seeds' holds [3]" not in text, text  # roughness draws from every seed
    # one value written two ways (0.1 * 0.1) would run twice
    config.write_text(yaml.safe_dump({"regular": [4], "random": [], "seeds": [0, 3],
                                      "kbar": [0.01, 0.1 * 0.1]}))
    text = output(snakemake(repo_copy, "-n", "--cores", "2", "--configfile",
                            "config/test.yaml", str(config)))
    assert "'seeds' holds [3], which no brush of the sweep draws from" in text, text
    assert ("config key 'kbar': 0.01 and 0.010000000000000002 differ by 2e-16 (relative): "
            "they run as two cases") in text, text
    # a tensile first waypoint (a preload of the wrong sign?) pulls off the first touch
    config.write_text(yaml.safe_dump({
        "regular": [4], "random": [], "kbar": [0.01], "roughness": [0.0, 0.3],
        "protocol": "force:2, displacement:1, force:-1, separation", "fig5": {"kbar": []}}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config))
    text = output(proc)
    assert proc.returncode == 0, text
    assert ("'protocol' starts with a tensile force of 2 F_K: the brushes of roughness = "
            "0.3 touch with their highest pillars only at first") in text, text


def test_a_default_shape_setting_beside_discs_plans(repo_copy: Path, tmp_path: Path) -> None:
    """config/lattices.yaml sets orientation: 0.0 (the default); a config
    layered on it with discs only cannot remove the key, and plans (the
    CLI's rule: only a value other than the default is refused)."""
    config = tmp_path / "discs.yaml"
    config.write_text(yaml.safe_dump({"shape": ["disc"], "fig5": {"shape": "disc"}}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/lattices.yaml",
                     str(config))
    assert proc.returncode == 0 and planned_simulations(output(proc)) > 0, output(proc)


def test_three_grids_plan_the_convergence_rule(repo_copy: Path, tmp_path: Path) -> None:
    """A list of grids multiplies the jobs, and three or more add the refinement study."""
    config = tmp_path / "tiny3.yaml"
    config.write_text(yaml.safe_dump({
        # kbar values the test sweep does not run: every curve is new in this copy
        "grid": [32, 48, 64], "regular": [4], "random": [], "kbar": [2.0e-2, 2.0],
        "fig5": {"n_pillars": 4, "kbar": [2.0]},
        "grid_by_n": [{"n_pillars": 16, "grid": 64}],
    }))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", str(config))
    text = output(proc)
    assert proc.returncode == 0, text
    assert planned_simulations(text) == 2 * 3, text  # 2 kbar x 3 grids (N = 16 not in sweep)
    # ... which is said: a mistyped N would leave its brush on `grid` silently
    assert "grid_by_n names N = [16], which no brush of the sweep has" in text, text
    assert re.search(r"^convergence\s+1\s*$", text, flags=re.MULTILINE), text
    for name in ("results/convergence.nc", "results/convergence.csv", "results/convergence.md",
                 "results/figures/convergence.png"):
        assert name in text, f"{name} not planned:\n{text}"
    for grid in (32, 48, 64):
        assert f"_grid{grid}_phi0.12.nc" in text
    assert "run on two grids" not in text, text
    # r = 3.1 on 32^2: the study's flag, said before any job
    assert ("the convergence study's coarsest grid gives pillars a radius under 4 elements, "
            "so their fits will be flagged as it says (regular N = 4 on 32: 3.1 elements "
            "(coarsest_under_resolved; n = 41 gives 4))") in text, text
    # two grids: a refinement, and no study, which planning says
    config.write_text(config.read_text().replace("- 48\n", ""))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", str(config))
    text = output(proc)
    assert proc.returncode == 0 and planned_simulations(text) == 2 * 2, text
    assert "N = [4] run on two grids each; the convergence study" in text, text
    assert "convergence.nc" not in text, text


def test_convergence_config_plans_the_study(repo_copy: Path) -> None:
    config = yaml.safe_load((repo_copy / "config/convergence.yaml").read_text())
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/convergence.yaml")
    text = output(proc)
    assert proc.returncode == 0, text
    # 3 brushes x 3 kbar x 3 grids, and the 48 x 48 brush on its own 3 grids
    assert planned_simulations(text) == len(config["regular"]) * len(config["kbar"]) * 3, text
    assert re.search(r"^convergence\s+1\s*$", text, flags=re.MULTILINE), text
    assert "_grid2048_" in text and "N64_kbar1e-06_seed0_grid2048" not in text
    # 16 x 16 and 24 x 24 start at r = 3.1 and 2.1 on 256^2, 48 x 48 at 2.1 on 512^2
    assert re.search(r"coarsest grid gives pillars a radius under 4 elements, .*\(regular "
                     r"N = 256 on 256: 3\.1 elements \(coarsest_under_resolved; n = \d+ gives "
                     r"4\); regular N = 576 on 256: 2\.1 .*; regular N = 2304 on 512: 2\.1 "
                     r"elements", text), text


def test_random_convergence_config_plans_the_study(repo_copy: Path) -> None:
    config = yaml.safe_load((repo_copy / "config/convergence_random.yaml").read_text())
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile",
                     "config/convergence_random.yaml")
    text = output(proc)
    assert proc.returncode == 0, text
    # brushes on `grid`'s 3 grids, N = 1620 on its own 2, the Fig. 5 brush on 3
    kbar, own = len(config["kbar"]), len(config["grid_by_n"])
    assert planned_simulations(text) == (len(config["random"]) - own) * kbar * 3 \
        + own * kbar * 2 + 3, text
    assert re.search(r"^convergence\s+1\s*$", text, flags=re.MULTILINE), text
    assert "random/N1620_kbar1e-06_seed0_grid1024" in text
    assert "random/N1620_kbar1e-06_seed0_grid256" not in text


def test_lint(repo_copy: Path) -> None:
    """No lint but the conda/container one: software is pip-installed (README)."""
    proc = snakemake(repo_copy, "--lint")
    titles = re.findall(r"^\s+\* (.+?):?$", output(proc), flags=re.MULTILINE)
    others = [t for t in titles if "conda environment or container" not in t]
    assert not others, output(proc)
    assert "Error" not in output(proc), output(proc)


def test_snakefmt_clean() -> None:
    """DESIGN.md asks for rule files that ``snakefmt --check`` leaves alone."""
    pytest.importorskip("snakefmt")
    files = [str(REPO / "Snakefile"), *map(str, sorted((REPO / "workflow").rglob("*.smk")))]
    proc = subprocess.run([sys.executable, "-m", "snakefmt", "--check", *files],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"kbar": [-1.0e-3, 1.0]}, "config key 'kbar.0': -0.001 is less than the minimum"),
        ({"kbar": [float("nan"), 1.0]},
         "config key 'kbar.0': nan is not a number; allowed a number >= 1e-09"),
        ({"phi": float("nan")}, r"config key 'phi': nan is not a number; allowed a number in \(0, 0.5\]"),
        # YAML 1.1's booleans and an empty key, said as such
        ({"backend": False}, "YAML reads yes/no/on/off/true/false as true or false"),
        ({"kbar": None}, r"the key is empty \(YAML reads that as null\)"),
        ({"solver": {"rtol": 1.0e-8, "precision": "mixed"}},
         "config: solver.rtol = 1e-08 is invalid: allowed a number >= 1e-06 with "
         "solver.precision 'mixed'"),
        ({"threads": 100000}, "config key 'threads': 100000 is greater than the maximum of 256"),
        # the key the user wrote, not the parameter it becomes
        ({"fig5": {"n_pillars": 5}}, "config: fig5.n_pillars = 5 is invalid: allowed a perfect"),
        ({"grid_by_n": [{"n_pillars": 16, "grid": 16}]},
         r"config: grid_by_n.grid = 16 is invalid .*allowed grid_by_n.grid 41, the next "),
        # cycles: the waypoint and the syntax named, and no preload beside them
        ({"protocol": "force:-1, push:2"},
         r"config: protocol = force:-1, push:2 is invalid \(waypoint 1 \('push:2'\) is of "
         r"no kind in .*allowed waypoints separated by commas"),
        # the sweep reads the last retraction as a pull-off: it must end apart
        ({"protocol": "force:-1, displacement:0.5"},
         r"config key 'protocol': 'force:-1, displacement:0.5' does not end with "
         r"'separation'; allowed a protocol that does"),
        ({"protocol": ""}, r"config key 'protocol': '' should be non-empty"),  # was null
        ({"protocol": "force:-5000, separation"},
         r"waypoint 0 is a force of -5000 F_K\): allowed force waypoints in \[-1000, 1000\]"),
        ({"protocol": "force:-1, separation", "preload": [0.0, 1.0]},
         r"config key 'preload': \[0.0, 1.0\] must be \[0.0\] when 'protocol' is given"),
        ({"colour": "red"}, "config key 'colour' is unknown"),
        ({"kbar": 0.01}, r"config key 'kbar': 0.01 is not of type 'array'; write a list, "
                         r"even of one value: \[0.01\]"),
        ({"grid": 64.5}, "config key 'grid': 64.5 fits none of its forms: 64.5 is not of type "
                         "'integer'; 64.5 is not of type 'array'"),
        ({"kbars": [1.0]}, "config key 'kbars' is unknown; did you mean 'kbar'?"),
        ({"solver": {"rtoll": 1e-5}}, "config key 'solver.rtoll' is unknown; did you mean"),
        ({"solver": {"max_iter": 0}}, "config key 'solver.max_iter': 0 is less than the minimum"),
        ({"regular": [4, 10]}, "config: regular = 10 is invalid: allowed a perfect square"),
        # a shape setting no brush reads would seem to count (its default hides it later)
        ({"aspect": 3.0}, r"config key 'aspect': applies to ellipse pillars only, and no brush "
                          r"of this config has them \(shape: \['disc'\]\); add ellipse"),
        ({"orientation": 30.0, "fig5": {"n_pillars": 16, "kbar": [0.455], "shape": "disc"}},
         r"config key 'orientation': applies to square and ellipse pillars only"),
        # checks that need the layout run at plan time too
        ({"grid": 32, "regular": [256]}, r"config: grid = 32 is invalid .*allowed grid \d+, the "
                                         r"next .*, or allow_coarse: true to run it anyway"),
        ({"grid": 128, "regular": [256]}, "config: grid = 128 is invalid"),
        # a grid list: every grid that refuses the brush, in one message
        ({"grid": [32, 48, 256, 24], "regular": [256]},
         r"config: grid = 24 is invalid .*\(case regular N = 16, grid = 24, phi = 0.12\); "
         r"grid = \[32, 48\] refuse it too"),
        ({"grid_by_n": [{"n_pillars": 16, "grid": [16, 24, 256]}]},
         r"config: grid_by_n.grid = 16 is invalid .*; grid_by_n.grid = \[24\] refuses it too"),
        # allow_coarse already on: no "or allow_coarse to run it anyway" (it was hinted twice)
        ({"grid": 8, "allow_coarse": True},
         r"allowed grid 15, the next .*0\.12 asked for\) \(case regular N = 16, grid = 8"),
        ({"regular": [16], "random": [], "phi": 0.05},
         r"phi is realised as 0.04688 instead of 0.05 .*allowed grid 65, the next"),
        # a random layout too dense to pack, found by packing it as its job would
        ({"regular": [], "random": [16], "phi": 0.5},
         r"config: random = 16 is invalid \(random layout: only 14 discs .*allowed fewer "
         r"pillars or a smaller phi \(case random"),  # the gap is at its least: no way out
        # the case in the keys the user wrote, not the file name's suffix
        ({"regular": [64], "random": [], "grid": 64, "roughness": [0.5],
          "fig5": {"n_pillars": 64, "kbar": [0.1]}},
         r"\(case regular N = 64, grid = 64, phi = 0.12, roughness = 0.5\)"),
    ],
)
def test_bad_config_stops_before_any_job(repo_copy: Path, tmp_path: Path, bad: dict,
                                         message: str) -> None:
    """One short message naming the key, from `snakemake -n` already."""
    assert_refused_at_plan_time(repo_copy, tmp_path, bad, message)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # YAML keeps the second of two equal keys and drops the first silently
        ("kbar: [1.0e-3]\ngrid: 64\nkbar: [1.0]\n",
         r"config file \S+bad.yaml: key 'kbar' is given twice in one mapping \(lines 1 and 3\)"),
        ("solver:\n  rtol: 1.0e-5\n  rtol: 1.0e-6\n",
         r"key 'rtol' is given twice in one mapping \(lines 2 and 3\)"),
        # a literal beyond a float had read as inf, i.e. rigid pillars
        ("kbar: [1.0e+400, 1.0]\n",
         r"bad.yaml, line 1: 1.0e\+400 is beyond the largest float .*write .inf"),
        ("kbar: [1e400, 1.0]\n", r"bad.yaml, line 1: 1e400 is beyond the largest float"),
        # on one line (flow style, JSON), beside a merge key, and JSON's 1e400
        ("solver: {rtol: 1.0e-5, rtol: 1.0e-6}\n", r"key 'rtol' is given twice .*both on line 1"),
        ('{"kbar": [0.001], "kbar": [1.0]}\n', r"key 'kbar' is given twice .*both on line 1"),
        ("solver:\n  <<: {rtol: 1.0e-5}\n  rtol: 1.0e-6\n  rtol: 1.0e-7\n",
         r"key 'rtol' is given twice in one mapping \(lines 3 and 4\)"),
        ('{\n  "kbar": [1e400, 1.0]\n}\n', r"bad.yaml, line 2: 1e400 is beyond the largest float"),
    ],
)
def test_config_text_that_yaml_would_misread_is_refused(repo_copy: Path, tmp_path: Path,
                                                        text: str, message: str) -> None:
    assert_refused_at_plan_time(repo_copy, tmp_path, text, message)


def test_an_overflowing_number_on_the_command_line_is_refused(repo_copy: Path) -> None:
    """`--config kbar=[1e400]` reaches the checks as text, which they would
    turn into inf (rigid pillars); they name the key instead."""
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     "--config", "kbar=[1e400]")
    text = output(proc)
    assert proc.returncode != 0, text
    assert "config key 'kbar.0': 1e400 is beyond the largest float" in text, text


def test_config_values_on_the_command_line_read_as_in_a_file(repo_copy: Path) -> None:
    """Snakemake reads `--config` lists through YAML's BaseLoader, as text:
    `kbar=[0.001]`, `regular=[16]`, `kbar=[.inf]` and `allow_coarse=true` were
    refused as "not of type 'number'"; they mean what a config file means (and
    inf what the CLI's --kbar inf means)."""
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     "--config", "kbar=[0.001, inf]", "regular=[16]", "random=[]",
                     "allow_coarse=true", "--forceall")
    text = output(proc)
    assert proc.returncode == 0, text
    names = set(re.findall(r"results/curves/\S+\.nc", text))
    assert {"results/curves/regular/N16_kbar0.001_seed0_grid64_phi0.12.nc",
            "results/curves/regular/N16_kbarinf_seed0_grid64_phi0.12.nc"} <= names, names


def test_a_local_gpu_run_without_a_card_stops_before_any_job(repo_copy: Path) -> None:
    """`backend: gpu` on a machine without CuPy or a card: a local run stops
    once the executor is known, naming the key, before its first job (a dry
    run cannot tell where the jobs will run, and a cluster's jobs check on
    their node)."""
    from brushcore import ParameterError
    from brushcore.numerics.platform.backend import resolve_backend

    try:
        resolve_backend("gpu")
        pytest.skip("this machine has CuPy and a card")
    except ParameterError:
        pass
    proc = snakemake(repo_copy, "--cores", "2", "--configfile", "config/test.yaml",
                     "--config", "backend=gpu", "--forceall")
    text = output(proc)
    assert proc.returncode != 0, text
    assert "config key 'backend': 'gpu' is invalid on this machine (CuPy is not installed" \
        in text, text
    assert "rule simulate" not in text and "Finished job" not in text, text


def assert_refused_at_plan_time(repo_copy: Path, tmp_path: Path, bad: dict | str,
                                message: str) -> None:
    """`snakemake -n` with `bad` (a mapping, or the file's text) over the test
    config stops with one short message."""
    config = tmp_path / "bad.yaml"
    config.write_text(bad if isinstance(bad, str) else yaml.safe_dump(bad))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config))
    text = output(proc)
    assert proc.returncode != 0, text
    assert re.search(message, text), f"error does not say {message!r}:\n{text}"
    assert len(text.strip().splitlines()) <= 6, text  # no schema dump, no long traceback
    assert "Job stats" not in text and "rule simulate" not in text, text


@pytest.mark.parametrize("text", [
    # PyYAML reads 1e-4 (no point) as text; the config means a number and plans
    # as if it had written 1.0e-4 (it was refused as "not of type 'number'")
    "kbar: [1e-4, 1.0e-2, 1E0]\nsolver:\n  rtol: 1e-5\n",
    # a key overriding what YAML's merge key `<<` merged is no duplicate
    "solver:\n  <<: {rtol: 1.0e-5}\n  rtol: 1.0e-6\n",
], ids=["exponent without a point", "merge key overridden"])
def test_config_text_plans_as_meant(repo_copy: Path, tmp_path: Path, test_config: dict,
                                    text: str) -> None:
    config = tmp_path / "meant.yaml"
    config.write_text(text)
    proc = snakemake(repo_copy, "-n", "--forceall", "--configfile", "config/test.yaml",
                     str(config))
    assert proc.returncode == 0, output(proc)[-3000:]
    assert planned_simulations(output(proc)) == len(expected_cases(test_config))


def test_integral_float_grid_plans_as_its_integer(repo_copy: Path, tmp_path: Path,
                                                  test_config: dict) -> None:
    """JSON Schema counts 64.0 as an integer; the plan must too (it once crashed)."""
    config = tmp_path / "float.yaml"
    config.write_text(yaml.safe_dump({"grid": float(test_config["grid"])}))
    proc = snakemake(repo_copy, "-n", "--forceall", "--configfile", "config/test.yaml",
                     str(config))  # --forceall: the test sweep may have run here already
    assert proc.returncode == 0, output(proc)[-3000:]
    assert planned_simulations(output(proc)) == len(expected_cases(test_config))


def test_allow_coarse_key_runs_what_is_refused(repo_copy: Path, tmp_path: Path) -> None:
    config = tmp_path / "coarse.yaml"
    config.write_text(yaml.safe_dump({"grid": 128, "regular": [256], "allow_coarse": True}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config))
    assert proc.returncode == 0, output(proc)


def test_curve_names_carry_grid_and_phi(repo_copy: Path, tmp_path: Path) -> None:
    """Another grid or phi plans new files instead of overwriting the earlier curves."""
    names = {}
    for grid, phi in ((64, 0.12), (96, 0.12), (64, 0.2)):
        config = tmp_path / f"g{grid}_{phi}.yaml"
        config.write_text(yaml.safe_dump({"grid": grid, "phi": phi}))
        proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                         str(config), "--forceall")
        assert proc.returncode == 0, output(proc)
        names[grid, phi] = set(re.findall(r"results/curves/\S+\.nc", output(proc)))
        assert all(f"_grid{grid}_phi{phi}.nc" in n for n in names[grid, phi])
    assert not names[64, 0.12] & names[96, 0.12] and not names[64, 0.12] & names[64, 0.2]


def test_aggregation_refuses_a_file_holding_another_case(test_run: Path) -> None:
    """A curve copied over another's name would enter the sweep as its own case
    and leave the named one NaN: the workflow says which case each file must hold."""
    from brushcore.data.aggregate import AggregationError, CaseKey, build_sweep, case_key
    from brushcore.data.io import read_curve

    good = sorted((test_run / "results/curves").rglob("*.nc"))[:2]
    named = [(case_key(c), float(c.attrs["phi"])) for c in map(read_curve, good)]
    sweep = build_sweep(good, expected=named)  # each as named: fine
    assert int(sweep["adhesive_force_normalized"].notnull().sum()) == 2
    with pytest.raises(AggregationError, match=rf"curve file {good[0]} holds layout=.* not "
                                               r"the case its name stands for \(layout="):
        build_sweep(good, expected=named[::-1])
    moved = CaseKey(**{**vars(named[0][0]), "grid": named[0][0].grid + 1})
    with pytest.raises(AggregationError, match="not the case its name stands for"):
        build_sweep(good[:1], expected=[(moved, named[0][1])])


def test_aggregation_names_a_bad_curve_file(test_run: Path, tmp_path: Path) -> None:
    from brushcore.data.aggregate import AggregationError, build_sweep

    good = sorted((test_run / "results/curves").rglob("*.nc"))
    bad = tmp_path / "truncated.nc"
    bad.write_bytes(good[0].read_bytes()[:200])
    worse = tmp_path / "empty.nc"
    worse.write_bytes(b"")
    # every bad file at once, and how to get them back: the workflow's
    # (it names the case of each file) reruns them, a user reruns simulate
    from brushcore import read_curve
    from brushcore.data.aggregate import case_key

    named = [(case_key(c), float(c.attrs["phi"])) for c in map(read_curve, good)]
    with pytest.raises(AggregationError, match=r"2 curve file\(s\): .*truncated\.nc .*"
                                               r"empty\.nc .*Delete them and run snakemake"):
        build_sweep([*good, bad, worse], expected=named + named[:2])
    with pytest.raises(AggregationError, match=r"empty\.nc .*Run their brushcore simulate"):
        build_sweep([*good, bad, worse])
    with pytest.raises(AggregationError, match="same case"):
        build_sweep([good[0], good[0]])


def test_rough_keys_plan_suffixed_curves_and_leave_flat_names(repo_copy: Path,
                                                              tmp_path: Path) -> None:
    """roughness / preload / kbar_spread: defaults plan today's names; other values
    add a suffix, and rough regular brushes run every seed (their heights are drawn)."""
    config = tmp_path / "rough.yaml"
    config.write_text(yaml.safe_dump({"regular": [16], "random": [], "kbar": [0.01],
                                      "seeds": [0, 1], "fig5": {"n_pillars": 16, "kbar": [0.01]},
                                      "roughness": [0.0, 0.2], "preload": [0.0, 1.0]}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config), "--forceall")
    assert proc.returncode == 0, output(proc)
    names = set(re.findall(r"results/curves/\S+\.nc", output(proc)))
    assert names == {
        "results/curves/regular/N16_kbar0.01_seed0_grid64_phi0.12.nc",
        "results/curves/regular/N16_kbar0.01_seed0_grid64_phi0.12_S0.0_P1.0_C0.0.nc",
        *(f"results/curves/regular/N16_kbar0.01_seed{s}_grid64_phi0.12_S0.2_P{p}_C0.0.nc"
          for s in (0, 1) for p in ("0.0", "1.0")),
    }, names


def test_a_protocol_names_every_curve_by_its_digest(repo_copy: Path, tmp_path: Path) -> None:
    """`protocol`: every curve, flat ones included, carries the protocol's
    digest in its name (another protocol, other files), and the job gets
    the rough curves' time (re-attachment is an approach element by element)."""
    config = tmp_path / "cycles.yaml"
    text = "force:-1, displacement:2.5, force:-1, separation"
    config.write_text(yaml.safe_dump({"regular": [16], "random": [], "kbar": [0.01],
                                      "fig5": {"n_pillars": 16, "kbar": [0.01]},
                                      "protocol": text}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config), "--forceall")
    assert proc.returncode == 0, output(proc)
    names = set(re.findall(r"results/curves/\S+\.nc", output(proc)))
    canonical = b"force:-1.0, displacement:2.5, force:-1.0, separation"  # parse_protocol's
    digest = hashlib.sha256(canonical).hexdigest()[:8]
    assert names == {
        f"results/curves/regular/N16_kbar0.01_seed0_grid64_phi0.12_S0.0_P0.0_C0.0_Q{digest}.nc"
    }, names
    assert "rough_loop.png" in output(proc)  # the loop of every cycle is drawn


def test_rough_curves_get_the_time_their_approach_takes(repo_copy: Path,
                                                       tmp_path: Path) -> None:
    """A rough brush's approach is one event per element touching down: on
    1024^2 it asks for 3 x the rough 8 x 8 brush's estimated 6 h (README),
    1085 min; a flat preload or a stiffness spread is a flat pull-off on the
    whole grid, 3 x random 64's 666 s plus 5 min, 39 min."""
    _, planned = _plan_resources(repo_copy, tmp_path, {
        "regular": [16], "random": [], "kbar": [0.01], "grid": 1024,
        "fig5": {"n_pillars": 16, "kbar": [0.01]}, "roughness": [0.0, 0.5], "preload": [1.0]})
    limits = {name: res["runtime"] for name, res in planned.items()}
    assert limits == {"regular/N16_kbar0.01_seed0_grid1024_phi0.12_S0.0_P1.0_C0.0": "39",
                      "regular/N16_kbar0.01_seed0_grid1024_phi0.12_S0.5_P1.0_C0.0": "1085"}, limits


def test_a_flat_brushs_preload_protocol_asks_for_a_pull_offs_time(repo_copy: Path,
                                                                    tmp_path: Path) -> None:
    """A flat brush under "force:-P, separation" is a pull-off
    (`protocol.dispatches`): the whole grid's 10 min at 512^2, not a rough
    curve's 26 (and 18 h at 1024^2) as before; a cycle is the protocol
    engine's, 26 min."""
    asked = {}
    for text in ("force:-1, separation", "force:-1, displacement:0.5, force:-1, separation"):
        _, planned = _plan_resources(repo_copy, tmp_path, {
            "regular": [16], "random": [], "kbar": [0.01], "grid": 512,
            "fig5": {"n_pillars": 16, "kbar": [0.01]}, "protocol": text})
        asked[text] = sorted(res["runtime"] for res in planned.values())
    assert asked == {"force:-1, separation": ["10"],
                     "force:-1, displacement:0.5, force:-1, separation": ["26"]}, asked


def test_time_and_memory_requests_follow_the_measured_curves(repo_copy: Path,
                                                             tmp_path: Path) -> None:
    """3 x the slowest curve measured at each grid and kind, plus 5 min: the
    flat regular brushes (mirror quadrant) ask for far less than the random
    ones at 1024^2 and 2048^2 (12 and 66 min against 39 and 785); memory
    follows the brush (`cost.job_memory_mb`: 16 pillars of 2,000-32,000
    elements on the tiles, a quarter of them on the quadrant), where the rule
    before asked 1.15, 5.6 and 7.4 GB whatever the brush."""
    text, planned = _plan_resources(repo_copy, tmp_path, {
        "regular": [16], "random": [16], "kbar": [0.01], "grid": [512, 1024, 2048],
        "fig5": {"n_pillars": 16, "kbar": [0.01]}})
    asked = {name: (int(res["runtime"]), int(res["mem_mb"])) for name, res in planned.items()}
    assert asked == {
        "regular/N16_kbar0.01_seed0_grid512_phi0.12": (7, 700),
        "regular/N16_kbar0.01_seed0_grid1024_phi0.12": (12, 800),
        "regular/N16_kbar0.01_seed0_grid2048_phi0.12": (66, 1300),
        "random/N16_kbar0.01_seed0_grid512_phi0.12": (10, 800),
        "random/N16_kbar0.01_seed0_grid1024_phi0.12": (39, 1100),
        "random/N16_kbar0.01_seed0_grid2048_phi0.12": (785, 2100),
    }, asked
    assert "slurm_max_runtime_min" not in text  # no cap, no warning


def test_runtime_cap_clips_every_request_and_says_so(repo_copy: Path, tmp_path: Path) -> None:
    """slurm_max_runtime_min clips each request above it (random 2048^2:
    785 -> 300 min), leaves the others and warns at plan time."""
    text, planned = _plan_resources(repo_copy, tmp_path, {
        "regular": [], "random": [16], "kbar": [0.01], "grid": [1024, 2048],
        "slurm_max_runtime_min": 300, "fig5": {"n_pillars": 16, "kbar": [0.01]}})
    limits = {name: res["runtime"] for name, res in planned.items()}
    assert limits == {"random/N16_kbar0.01_seed0_grid1024_phi0.12": "39",
                      "random/N16_kbar0.01_seed0_grid2048_phi0.12": "300",
                      "regular/N16_kbar0.01_seed0_grid1024_phi0.12": "12",
                      "regular/N16_kbar0.01_seed0_grid2048_phi0.12": "66"}, limits
    assert ("slurm_max_runtime_min = 300 clips the time limit of 1 of 4 simulations (the "
            "largest: 785 min for results/curves/random/N16_kbar0.01_seed0_grid2048_phi0.12"
            ".nc)") in text, text


def test_a_retry_asks_for_twice_the_time_and_half_as_much_memory_again() -> None:
    """Snakemake gives a resource function the attempt, not the cause of the
    failure: the retry doubles the time (within the cap) and asks for 1.5x
    the memory (a retry after a memory kill asked the same and failed again)."""
    common = _common_rules()
    runtime = common["simulate_runtime"]({})
    capped = common["simulate_runtime"]({"slurm_max_runtime_min": 60})
    memory = common["simulate_mem_mb"]({})
    base = {"layout": "random", "shape": "", "rough": "", "grid": "1024", "n_pillars": "16",
            "phi": "0.12"}

    def jobs(**changed):
        return type("Wildcards", (), {**base, **changed})()

    wildcards = jobs()
    assert [runtime(wildcards, attempt) for attempt in (1, 2)] == [39, 78]
    assert [capped(wildcards, attempt) for attempt in (1, 2)] == [39, 60]
    # 16 pillars of 8,101 elements on the tiles: 0.79 GB, x 1.3; x 1.5 on the retry
    assert [memory(wildcards, attempt) for attempt in (1, 2)] == [1100, 1600]
    # a rough curve's floor (the rule before, 5.6 GB at 1024^2) takes 1.5x too, not 2x
    rough = jobs(rough="_S0.5_P0.0_C0.0")
    assert [memory(rough, attempt) for attempt in (1, 2)] == [5600, 8400]
    # a GPU job's host memory is unmeasured: the floor, rounded (not the quadrant's 700)
    flat = jobs(layout="regular", grid="512")
    assert memory(flat, 1) == 700
    assert common["simulate_mem_mb"]({"backend": "gpu"})(flat, 1) == 1200
    # near MAX_BLOCK a pillar of 1,483 elements (estimated 1,523) takes the blocks: both
    # paths priced (random 64 at 888^2 reached 1.8 GB in 100 s; 1.5 GB was asked)
    edge = jobs(grid="888", n_pillars="64")
    assert memory(edge, 1) == 3200


def test_a_file_brushs_memory_counts_its_largest_pillar(tmp_path: Path, monkeypatch) -> None:
    """A table of unequal pillars: the blocks are as large as its largest
    pillar (pi r^2 n^2 elements, 515 for r = 0.1 on 128^2), not as its mean
    one (phi n^2 / N, 276), which a generated brush's rule would take."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "two.csv").write_text("x,y,radius\n0.3,0.3,0.1\n0.75,0.75,0.02\n")
    common = _common_rules()
    config = {"layout_files": ["two.csv"], "kbar": [0.01], "grid": 128}
    largest = common["_file_largest_pillar"](config, "file_two", 128)
    assert largest == pytest.approx(math.pi * 0.1**2 * 128**2, rel=0.02)
    assert common["_file_largest_pillar"](config, "random", 128) is None
    # ... and the request prices that pillar, not the mean one (a spy in the rules' scope)
    job = type("Wildcards", (), {"layout": "file_two", "shape": "", "rough": "", "grid": "128",
                                 "n_pillars": "2", "phi": "0.0327"})()
    priced = []
    common["job_memory_mb"] = lambda **kwargs: priced.append(kwargs) or 0
    common["simulate_mem_mb"](config)(job, 1)
    assert (priced[0]["largest"], priced[0]["counted"]) == (largest, True)


#: Peak RSS measured [MiB] of single curves, one thread (2048^2: two): (layout, N,
#: grid, phi, mirror quadrant, peak).  A helper's runs of 2026-12-07 (those
#: marked >= were stopped: a lower bound) and docs/SPEED.md's rows at 1024^2 and
#: 2048^2.  The two at phi 0.3 and 0.5 ran out of the request before 2026-12-07.
MEASURED_PEAKS_MIB = [
    ("regular", 64, 256, 0.12, True, 153.9), ("regular", 2304, 256, 0.12, True, 168.0),
    ("random", 64, 256, 0.12, False, 178.6), ("random", 1620, 256, 0.12, False, 399.8),
    ("regular", 64, 512, 0.12, True, 204.4), ("regular", 2304, 512, 0.12, True, 191.8),
    ("random", 64, 512, 0.12, False, 372.6), ("random", 1620, 512, 0.12, False, 444.4),
    ("random", 22, 512, 0.12, False, 678.2),
    ("regular", 100, 512, 0.5, False, 2228.5),  # >=, symmetry off: its blocks 2.07 GB
    ("random", 60, 512, 0.3, False, 1243.0),  # >=
    ("regular", 2304, 1024, 0.12, True, 272.2), ("random", 220, 1024, 0.12, False, 1075.2),
    ("regular", 2304, 2048, 0.12, True, 829.4), ("regular", 576, 2048, 0.12, True, 1628.2),
    ("regular", 64, 2048, 0.12, True, 737.3), ("random", 64, 2048, 0.12, False, 1331.2),
    ("random", 1620, 2048, 0.12, False, 2754.6),  # >=, 15 min of an estimated 130
    # pillars a few elements under MAX_BLOCK, estimated over it (a review helper's runs):
    ("random", 64, 888, 0.12, False, 1815.0),  # >=, 100 s
    ("random", 16, 444, 0.12, False, 596.0),
]


@pytest.mark.parametrize("layout,n_pillars,grid,phi,mirrored,peak", MEASURED_PEAKS_MIB)
def test_a_jobs_memory_request_covers_the_peaks_measured(layout, n_pillars, grid, phi,
                                                         mirrored, peak) -> None:
    """The request covers each measured peak and the job step's Snakemake
    (192 MiB measured) by at least 1.3x and asks at most 2x it; the estimate
    itself lies above each peak and within 1.5x of it.  The rule before
    asked 1.15 GB for the two brushes at phi 0.3 and 0.5 on 512^2 (peaks
    1.3 and 2.3 GB: killed, and the retry asked the same) and 4-12x the
    peaks above 512^2."""
    from brushcore.model import cost

    largest = cost.largest_pillar(n_pillars, phi, grid)
    estimate = cost.peak_mb(n_pillars=n_pillars, grid=grid, largest=largest,
                            mirrored=mirrored, protocol_engine=False)
    asked = cost.job_memory_mb(n_pillars=n_pillars, grid=grid, largest=largest,
                               mirrored=mirrored, protocol_engine=False)
    peak_mb, job_mb = peak * 2**20 / 1e6, (peak + 192) * 2**20 / 1e6
    assert 1.0 < estimate / peak_mb < 1.5
    assert 1.3 <= asked / job_mb < 2.0


def test_bundles_of_fine_grid_curves_are_warned_of() -> None:
    """A bundle fails as a whole and Snakemake removes the curves it finished:
    `--group-components sims=N` over grids finer than 512 is warned of at the
    run's start, naming the grids; sims=1 or coarse grids only, not."""
    common = _common_rules()
    config = {"fig5": {"kbar": [], "layout": "regular", "n_pillars": 256},
              "regular": [16], "hexagonal": [], "random": [], "grid": [256, 1024, 2048],
              "grid_by_n": [], "roughness": [0.0], "preload": [0.0], "kbar_spread": [0.0],
              "shape": ["disc"], "layout_files": [], "kbar": [0.01], "phi": 0.5, "seeds": 1}
    warn = common["bundled_fine_grids"]
    text = warn(config, {"sims": 8})
    assert text.startswith("--group-components sims=8 bundles curves on grids [1024, 2048]"), text
    assert warn(config, {"sims": 1}) is None and warn(config, {}) is None
    assert warn(config | {"grid": [256, 512]}, {"sims": 8}) is None


def test_snapshots_are_kept_for_fig5_only_when_it_is_drawn() -> None:
    """sweep.nc keeps the Fig. 5 brush's contact snapshots beside any others
    small enough; with `fig5: {kbar: []}` (no Fig. 5) none is asked for."""
    brushes = _common_rules()["snapshot_brushes"]
    fig5 = {"layout": "regular", "n_pillars": 256}
    assert brushes({"fig5": fig5 | {"kbar": [0.455]}}) == [("regular", 256)]
    assert brushes({"fig5": fig5 | {"kbar": []}}) == []


def test_outputs_of_an_earlier_sweep_are_named(tmp_path: Path) -> None:
    """Snakemake leaves in results/ the figures and tables of an earlier
    config that this one does not make (a convergence study, Fig. 5): the
    run ends with a warning naming them, and names none it made itself."""
    common = _common_rules()
    config = {"fig5": {"kbar": [], "layout": "regular", "n_pillars": 256},
              "regular": [16], "hexagonal": [], "random": [], "grid": [64], "grid_by_n": [],
              "roughness": [0.0], "preload": [0.0], "kbar_spread": [0.0], "shape": ["disc"],
              "layout_files": [], "kbar": [0.01]}
    figures = tmp_path / "results/figures"
    figures.mkdir(parents=True)
    for name in ("fig6.png", "fig5.png", "convergence.pdf"):
        (figures / name).write_text("")
    (tmp_path / "results/convergence.md").write_text("")
    later = time.time() + 1.0  # files written before this run read its Snakefile
    text = common["stale_outputs"](config, root=tmp_path, since=later)
    assert text.startswith("3 files in results/ are from an earlier sweep"), text
    for name in ("results/convergence.md", "results/figures/convergence.pdf",
                 "results/figures/fig5.png"):
        assert name in text
    assert "fig6" not in text
    # written by this run (`snakemake results/figures/fig5.png`): its own, not stale
    assert common["stale_outputs"](config, root=tmp_path, since=0.0) is None
    config["fig5"]["kbar"] = [0.455]
    config["grid"] = [64, 128, 256]
    assert common["stale_outputs"](config, root=tmp_path, since=later) is None


def test_time_requests_follow_the_solver_settings() -> None:
    """symmetry: false solves a regular brush on the whole grid, exact mode's
    global cascades run 4-6x longer, double transforms 1.5x on a random
    brush: the requests follow (2048^2: regular 66 min by default)."""
    runtime = _common_rules()["simulate_runtime"]
    regular = type("Wildcards", (), {"layout": "regular", "shape": "", "rough": "",
                                     "grid": "2048"})()
    random = type("Wildcards", (), {"layout": "random", "shape": "", "rough": "",
                                    "grid": "1024"})()
    assert runtime({})(regular, 1) == 66  # 5 + 3 x 1,218 s
    assert runtime({"solver": {"symmetry": False}})(regular, 1) == 785  # 5 + 3 x 15,600 s
    exact = {"solver": {"rtol": 1e-8, "cascade": "global", "precision": "double"}}
    assert runtime(exact)(regular, 1) == 371  # 5 + 6 x 3 x 1,218 s
    assert runtime(exact)(random, 1) == 307  # 5 + 6 x 1.5 x 3 x 670 s
    assert runtime({"solver": {"precision": "double"}})(random, 1) == 56  # 5 + 1.5 x 3 x 670 s


def _common_rules() -> dict:
    """The functions of the workflow's rule files (plain Python), as the
    Snakefile sees them (one scope, in the Snakefile's order)."""
    scope: dict = {}
    for name in RULE_HELPERS:
        path = REPO / "workflow/rules" / name
        exec(compile(path.read_text(), str(path), "exec"), scope)  # noqa: S102 - our own rules
    return scope


def _plan_resources(repo_copy: Path, tmp_path: Path,
                    settings: dict) -> tuple[str, dict[str, dict[str, str]]]:
    """Dry-run the test config with ``settings`` on top: Snakemake's output
    and the resources of every planned simulate job (`_planned_resources`)."""
    config = tmp_path / "settings.yaml"
    config.write_text(yaml.safe_dump(settings))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config), "--forceall")
    text = output(proc)
    assert proc.returncode == 0, text
    return text, _planned_resources(text)


def _planned_resources(text: str) -> dict[str, dict[str, str]]:
    """Curve name (layout/stem) -> resources of every planned simulate job."""
    jobs = re.findall(r"^rule simulate:\n\s*output: results/curves/(\S+)\.nc"
                      r".*?^ *resources: ([^\n]*)$", text, flags=re.MULTILINE | re.DOTALL)
    return {name: dict(item.split("=", 1) for item in line.split(", ")) for name, line in jobs}


def _simulate_resources(text: str) -> list[dict[str, str]]:
    """The resources of every planned simulate job (the only rule with `gres`)."""
    lines = re.findall(r"^\s*resources: (.*gres=.*)$", text, flags=re.MULTILINE)
    return [dict(item.split("=", 1) for item in line.split(", ")) for line in lines]


def _slurm_gpu_flags(resources: dict[str, str]) -> str:
    """What snakemake-executor-plugin-slurm adds to sbatch for these resources."""
    from snakemake_executor_plugin_slurm.utils import set_gres_string

    class Resources(dict):
        __getattr__ = dict.get

    typed = Resources({k: int(v) if v.isdigit() else v for k, v in resources.items()})
    return set_gres_string(type("Job", (), {"resources": typed})()).strip()


def test_gpu_backend_requests_one_card_per_curve(repo_copy: Path, tmp_path: Path) -> None:
    """backend: gpu -> resource gpu=1 locally (--resources gpu=N), --gres=gpu:1 on Slurm."""
    pytest.importorskip("snakemake_executor_plugin_slurm")
    config = tmp_path / "gpu.yaml"
    config.write_text(yaml.safe_dump({"backend": "gpu"}))
    test = ("--configfile", "config/test.yaml")
    # --forceall: plan every job even where an earlier test ran the sweep here
    local = snakemake(repo_copy, "-n", "--forceall", "--cores", "2", *test, str(config),
                      "--resources", "gpu=1")
    assert local.returncode == 0, output(local)
    jobs = _simulate_resources(output(local))
    assert jobs and all(j["gpu"] == "1" and j["gres"] == "gpu:1" for j in jobs), jobs
    slurm = snakemake(repo_copy, "-n", "--forceall", "--profile", "workflow/profiles/slurm",
                      *test, str(config))
    assert slurm.returncode == 0, output(slurm)
    jobs = _simulate_resources(output(slurm))
    assert jobs and {_slurm_gpu_flags(j) for j in jobs} == {"--gres=gpu:1"}, jobs
    cpu = snakemake(repo_copy, "-n", "--forceall", "--profile", "workflow/profiles/slurm",
                    *test)
    assert cpu.returncode == 0, output(cpu)
    jobs = _simulate_resources(output(cpu))
    assert jobs and {_slurm_gpu_flags(j) for j in jobs} == {""}, jobs


def test_slurm_profile_submits_one_simulation_a_job(repo_copy: Path) -> None:
    """A failed bundle loses its finished members' curves (Snakemake cleans up
    every member of a failed group job), so the profile bundles nothing by
    default: 11 simulations, 11 Slurm jobs; --group-components bundles on purpose."""
    test = ("-n", "--forceall", "--profile", "workflow/profiles/slurm",
            "--configfile", "config/test.yaml")
    alone = snakemake(repo_copy, *test)
    assert alone.returncode == 0, output(alone)
    assert planned_simulations(output(alone)) == 11
    assert output(alone).count("Group job sims") == 11, output(alone)
    bundled = snakemake(repo_copy, *test, "--group-components", "sims=4")
    assert bundled.returncode == 0, output(bundled)
    assert output(bundled).count("Group job sims") == 3, output(bundled)


def test_slurm_profile_checks_status_within_min_job_age() -> None:
    """squeue lists a finished job for MinJobAge seconds, and the plugin (2.8)
    takes a job missing from it for one still running: it checks at most
    every 180 s and uses squeue only where MinJobAge >= 3 x the first
    interval, which must therefore be at least 60 s."""
    profile = yaml.safe_load((REPO / "workflow/profiles/slurm/config.yaml").read_text())
    assert profile["slurm-status-command"] == "squeue"
    assert 3 * profile["slurm-init-seconds-before-status-checks"] >= 180


def test_a_run_whose_cores_would_cut_threads_stops(repo_copy: Path) -> None:
    """The profile's `cores: 1` capped config `threads: 2` to one thread and
    one CPU without a word; the dry run now stops and says what to set, and
    runs with --cores 2 (two threads, so --cpus-per-task=2).  More cores
    than threads is harmless, and a local run with --jobs (which the check
    cannot tell from a cluster's) runs."""
    test = ("-n", "--forceall", "--profile", "workflow/profiles/slurm",
            "--configfile", "config/test.yaml")
    capped = snakemake(repo_copy, *test, "--config", "threads=2")
    assert capped.returncode != 0
    assert ("config key 'threads': 2, but Snakemake's cores is 1, which caps every job at 1 "
            "thread(s) (and on a cluster 1 CPU(s)): set `cores: 2` in the profile or pass "
            "--cores 2") in output(capped), output(capped)
    wide = snakemake(repo_copy, *test, "--cores", "4")
    assert wide.returncode == 0, output(wide)
    agreed = snakemake(repo_copy, *test, "--cores", "2", "--config", "threads=2")
    assert agreed.returncode == 0, output(agreed)
    threads = re.findall(r"^\s*threads: (\d+)$", output(agreed), flags=re.MULTILINE)
    assert len(threads) == 11 and set(threads) == {"2"}, threads
    for local in (("--cores", "1", "--config", "threads=2"), ("--cores", "2", "--jobs", "2")):
        proc = snakemake(repo_copy, "-n", "--forceall", "--configfile", "config/test.yaml",
                         *local)
        assert proc.returncode == 0, output(proc)  # locally --cores is the machine's share


def test_unknown_backend_key_is_refused(repo_copy: Path, tmp_path: Path) -> None:
    assert_refused_at_plan_time(repo_copy, tmp_path, {"backend": "tpu"},
                                "config key 'backend': 'tpu' is not one of")


def test_a_refused_brush_the_user_did_not_list_says_where_it_comes_from(
        repo_copy: Path, tmp_path: Path) -> None:
    """A config of one's own extends config/config.yaml key by key: leaving
    out `random` keeps the paper's random brushes, and when one of them is
    refused (random 64 on 64^2: radius 1.56 elements) the message says so."""
    config = tmp_path / "mine.yaml"
    config.write_text(yaml.safe_dump({"grid": [64, 128, 256], "regular": [16],
                                      "kbar": [math.inf]}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", str(config))
    text = output(proc)
    assert proc.returncode != 0, text
    assert ("(case random N = 64, grid = 64, phi = 0.12); this brush's 'random' is "
            "config/config.yaml's, which your config files extend: set 'random: []' to run "
            "none") in text, text
    # the Fig. 5 brush too (the schema adds fig5's defaults to the config)
    config.write_text(yaml.safe_dump({"grid": [64], "regular": [16], "random": [],
                                      "kbar": [math.inf]}))
    text = output(snakemake(repo_copy, "-n", "--cores", "2", "--configfile", str(config)))
    assert "regular N = 256" in text and "set 'fig5: {kbar: []}' to run none" in text, text


def test_rough_figures_pick_the_brush_with_the_axis_they_draw() -> None:
    """A brush as made comes first for the rough figures, but for those with a
    roughness axis when `roughness` draws heights (a brush as made has none);
    the one-curve figures keep it first."""
    from types import SimpleNamespace

    scope = _common_rules()
    made = SimpleNamespace(inputs=("heights",), n_pillars=9)
    scope["file_brushes"] = lambda config: {"file_mine": made}
    config = {"regular": [16], "hexagonal": [], "random": [], "roughness": [0.0],
              "fig5": {"layout": "regular", "n_pillars": 16}}
    assert scope["rough_brush"](config) == ("file_mine", 9)
    config["roughness"] = [0.0, 0.3]
    assert scope["rough_brush"](config) == ("regular", 16)
    assert scope["rough_brush"](config, axes=False) == ("file_mine", 9)
    # tables alone: the one that roughness draws heights for, not the one given them
    plain = SimpleNamespace(inputs=("kbar_values",), n_pillars=12)
    scope["file_brushes"] = lambda config: {"file_mine": made, "file_plain": plain}
    config["regular"] = []
    assert scope["rough_brush"](config) == ("file_plain", 12)
    assert scope["rough_brush"](config, axes=False) == ("file_mine", 9)


def test_a_jobs_log_says_what_the_command_says_of_its_curve() -> None:
    """The log names touching pillars (random 16 on 64^2, seed 0: 3 pairs) and
    how far a first-touch approach pressed, in the config's words."""
    import warnings

    from brushcore import BrushParams, FirstTouchWarning, simulate
    from brushcore.data.simulate_job import log_lines

    lines = log_lines(simulate(BrushParams("random", 16, 1.0, 64)))
    assert lines[0].startswith("F_ad = ") and "phi realised" in lines[0]
    assert lines[1].startswith("3 pillar pairs share an element edge"), lines
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FirstTouchWarning)
        rough = simulate(BrushParams("regular", 16, 0.01, 64, roughness=0.3))
    assert log_lines(rough)[-1] == (
        "1 of 16 pillars in contact at the first touch (preload 0 stops the approach there; "
        "add a load to the config's 'preload' list to press the brush on)")


def test_the_config_schema_bounds_are_the_solvers():
    """Each bound the schema states is the Python constant the parameters are
    checked against, so a config refused by the one is refused by the other
    in the same words (the schema once bounded orientation to [-180, 180]
    where the CLI and the API took any finite angle; all three take a turn
    either way now)."""
    from brushcore.model import params as p
    from brushcore.numerics.options import SolverOptions
    from brushcore.numerics.platform.threads import MAX_THREADS

    schema = yaml.safe_load((REPO / "workflow/schemas/config.schema.yaml").read_text())
    grid, phi, props = schema["$defs"]["grid"], schema["$defs"]["phi"], schema["properties"]
    assert (grid["minimum"], grid["maximum"]) == (p.MIN_GRID, p.MAX_GRID)
    assert (phi["exclusiveMinimum"], phi["maximum"]) == (0, p.MAX_PHI)
    # a number or a list of them, each of that range
    assert [form.get("$ref", form.get("items", {}).get("$ref"))
            for form in props["phi"]["oneOf"]] == ["#/$defs/phi"] * 2
    for name in ("aspect", "orientation"):
        assert [form.get("$ref", form.get("items", {}).get("$ref"))
                for form in props[name]["oneOf"]] == [f"#/$defs/{name}"] * 2
    assert props["kbar"]["items"]["minimum"] == p.MIN_KBAR
    assert props["fig5"]["properties"]["kbar"]["items"]["minimum"] == p.MIN_KBAR
    aspect, orientation = (schema["$defs"][name] for name in ("aspect", "orientation"))
    assert (aspect["minimum"], aspect["maximum"]) == (1, p.MAX_ASPECT)
    assert (orientation["minimum"], orientation["maximum"]) == (
        -p.MAX_ORIENTATION, p.MAX_ORIENTATION)
    assert props["seeds"]["items"]["maximum"] == p.MAX_SEED
    for name in ("roughness", "preload"):
        assert props[name]["items"]["maximum"] == p.MAX_ROUGH
    assert props["kbar_spread"]["items"]["maximum"] == p.MAX_KBAR_SPREAD
    assert props["threads"]["maximum"] == MAX_THREADS
    rtol = props["solver"]["properties"]["rtol"]
    assert (rtol["minimum"], rtol["maximum"]) == (SolverOptions.MIN_RTOL,
                                                  SolverOptions.MAX_RTOL)
    tie = props["solver"]["properties"]["tie_rtol"]
    assert (tie["minimum"], tie["maximum"]) == (0, SolverOptions.MAX_TIE_RTOL)
    assert props["solver"]["properties"]["max_iter"]["minimum"] == 1
    # no defaults filled in: they would reach every job's params and rerun finished curves
    assert "default" not in tie and "default" not in props["solver"]["properties"]["max_iter"]


@pytest.mark.parametrize("case,wildcards", [
    (dict(layout="regular", n_pillars=16), ("regular", "", "")),
    (dict(layout="random", n_pillars=16), ("random", "", "")),
    (dict(layout="regular", n_pillars=16, shape="ellipse", aspect=2.0),
     ("regular", "_ellipse2.0_0.0", "")),
    (dict(layout="regular", n_pillars=16, preload=1.0), ("regular", "", "_S0.0_P1.0_C0.0")),
    (dict(layout="regular", n_pillars=16, roughness=0.3), ("regular", "", "_S0.3_P0.0_C0.0")),
    (dict(layout="regular", n_pillars=4, heights=np.array([0.1, 0.0, 0.0, -0.1])),
     ("file_mine", "", "", "offsets")),
    # a protocol runs on the whole grid; a flat brush's preload protocol is a pull-off
    # (the command priced it as the mirror quadrant: 20 min against 4.3 h at 2048^2)
    (dict(layout="regular", n_pillars=16), ("regular", "", "_S0.0_P0.0_C0.0_Q0123abcd",
                                            "force:-1, separation")),
    (dict(layout="random", n_pillars=16), ("random", "", "_S0.0_P0.0_C0.0_Q0123abcd",
                                           "force:-1, displacement:0.5, force:-1, separation")),
], ids=["regular", "random", "ellipse", "preload", "rough", "given heights",
        "preload protocol", "cycle protocol"])
def test_the_command_and_the_workflow_price_a_curve_alike(case, wildcards):
    """One table of measured curves (`brushcore.model.cost`) sets the
    workflow's Slurm time and the command's note before a long run: each
    brush is of the same kind in both, and the request is 3 x its bound
    plus 5 min."""
    from brushcore import BrushParams, SolverOptions
    from brushcore.model import cost
    from brushcore.model.inputs import parse_protocol

    common = _common_rules()
    offsets = wildcards[3:] == ("offsets",)  # a layout_files brush given heights
    protocol = (parse_protocol(wildcards[3]) if len(wildcards) > 3 and not offsets
                else None)
    for grid in (512, 1024):
        params = BrushParams(kbar=0.01, grid=grid, **case)
        kind = cost.curve_kind(params, SolverOptions(), protocol)
        assert common["curve_kind"](*wildcards[:3], None, offsets, protocol) == kind
        minutes = common["curve_minutes"](*wildcards[:3], grid, None, offsets, protocol)
        assert minutes == math.ceil(
            5 + 3 * cost.expected_seconds(params, SolverOptions(), protocol) / 60)
    if protocol is not None:
        assert kind == ("whole" if len(protocol) == 2 else "rough")
    note = cost.cost_note(BrushParams(kbar=0.01, grid=2048, **case), SolverOptions(),
                          protocol)
    assert note.startswith("this run may take up to about ") and "measured at" in note
    assert cost.cost_note(BrushParams(kbar=0.01, grid=64, **case), SolverOptions()) == ""
    # a bound of the host's curves: not said of a GPU run
    gpu = BrushParams(kbar=0.01, grid=2048, backend="gpu", **case)
    assert cost.cost_note(gpu, SolverOptions()) == ""


def test_near_duplicates_are_floats_one_ulp_apart_not_integers() -> None:
    """0.1 * 3 beside 0.3 is one value written two ways; seeds such as
    1700000000 and 1700000001 (timestamps) are two brushes, 6e-10 apart
    relative (a diff reviewer's find: they were told to merge)."""
    near = _common_rules()["_near_duplicates"]
    assert near([0.3, 1.0, 0.1 * 3]) == (0.3, 0.30000000000000004)
    assert near([1700000000, 1700000001]) is None
    assert near([12345678901, 12345678902, 0.5]) is None
    assert near([1e-4, 1.00000001e-4]) is None  # 1e-8 apart: two values meant
    assert near([True, 1.0, float("inf"), float("inf")]) is None


def test_a_stiffness_spread_asks_for_its_figure() -> None:
    """`kbar_spread` reached no figure: `rough_spread` (F_ad against C) is a
    target where the config asks for a spread C > 0, and not otherwise (a
    rough config of equal stiffness); stale-output checks know its name."""
    from snakemake.utils import validate

    rules = _common_rules()

    def config(**keys) -> dict:
        merged = {**yaml.safe_load((REPO / "config/test.yaml").read_text()), **keys}
        validate(merged, str(REPO / "workflow/schemas/config.schema.yaml"), set_default=True)
        return merged

    for keys, drawn in (({"kbar_spread": [0.0, 0.25, 0.5]}, True), ({"kbar_spread": [0.5]}, True),
                        ({"roughness": [0.0, 0.3]}, False), ({}, False)):
        files = rules["rough_figure_files"](config(**keys))
        assert ("results/figures/rough_spread.png" in files) == drawn, (keys, files)
    assert "rough_spread" in rules["SPREAD_FIGURES"]
