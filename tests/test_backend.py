"""The backend choice: errors before any work, the portable core under a strict
array-API namespace, curve attributes, the CLI flag, and GPU-vs-CPU checks.

The strict namespace (`array_api_strict`) runs the same engine as CuPy (the
device convolver, `DeviceBlocks`, namespace calls only), so a call that
would not port fails here without a GPU.  Tests marked ``gpu`` compare
CuPy with NumPy and are skipped, with the reason, where there is no card.
"""

from __future__ import annotations

import importlib
import math
import subprocess
import sys
import types

import numpy as np
import pytest

import brushcore.numerics.platform.backend as backend_module
from brushcore import BrushParams, ParameterError, SolverOptions, simulate
from brushcore.cli import main
from brushcore.data.aggregate import build_sweep
from brushcore.data.io import read_curve, write_curve
from brushcore.model import curve as curve_module
from brushcore.model import curve_format
from brushcore.model import solve as solve_module
from brushcore.numerics.platform.backend import resolve_backend
from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.numerics.linear.device_blocks import DeviceBlocks
from brushcore.numerics.halfspace.device_convolution import DeviceConvolver
from brushcore.numerics.linear.precondition import BlockInverse
from brushcore.numerics.linear.tiles import TileCoarse

pytest.importorskip("array_api_strict")

#: Strict and NumPy run the same arithmetic up to summation order.
STRICT_RTOL = 1e-10
#: GPU against CPU (issue 15): CG tolerance and cuFFT round-off, not bit identity.
GPU_RTOL = 2e-4
#: The CPU reference solves the whole grid in double precision, as the device does.
WHOLE_GRID = SolverOptions(symmetry=False, precision="double")


def _no_cupy(monkeypatch, fake: types.ModuleType | None = None) -> None:
    """Make `import cupy` fail (or return ``fake``) inside the backend module."""
    real = importlib.import_module

    def import_module(name, *args, **kwargs):
        if name == "cupy":
            if fake is None:
                raise ImportError("No module named 'cupy'")
            return fake
        return real(name, *args, **kwargs)

    monkeypatch.setattr(backend_module.importlib, "import_module", import_module)


def _forbid_work(monkeypatch) -> None:
    """Any layout or solve after this fails the test: errors must come first."""
    def work(*args, **kwargs):
        raise AssertionError("work started before the backend was checked")

    for module in (curve_module, solve_module):
        monkeypatch.setattr(module, "build_labels", work)
    monkeypatch.setattr(solve_module, "pull_off", work)


def test_unknown_backend_is_refused_naming_the_choices():
    with pytest.raises(ParameterError, match=r"backend='tpu' is invalid: allowed 'cpu'.*'gpu'"):
        resolve_backend("tpu")
    with pytest.raises(ParameterError, match="backend='tpu'"):
        BrushParams("regular", 16, 1.0, 64, backend="tpu")


def test_gpu_without_cupy_fails_before_any_work(monkeypatch):
    _no_cupy(monkeypatch)
    _forbid_work(monkeypatch)
    params = BrushParams("regular", 16, 1.0, 64)
    with pytest.raises(ParameterError) as info:
        simulate(params, backend="gpu")
    text = str(info.value)
    assert "backend='gpu'" in text and "CuPy is not installed" in text, text
    assert "pip install 'brushcore[gpu]'" in text, text


def test_gpu_without_a_card_fails_before_any_work(monkeypatch):
    runtime = types.SimpleNamespace(getDeviceCount=lambda: 0)
    fake = types.SimpleNamespace(cuda=types.SimpleNamespace(runtime=runtime))
    _no_cupy(monkeypatch, fake)
    _forbid_work(monkeypatch)
    with pytest.raises(ParameterError, match="no CUDA device visible"):
        simulate(BrushParams("regular", 16, 1.0, 64), backend="gpu")


def test_cupy_is_not_imported_unless_chosen():
    """An optional backend costs nothing to those who do not use it."""
    code = ("import sys, brushcore, brushcore.cli, brushcore.model.curve; "
            "print('cupy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False", out.stdout + out.stderr


def test_backend_is_not_part_of_the_problem():
    cpu = BrushParams("regular", 16, 1.0, 64)
    other = BrushParams("regular", 16, 1.0, 64, backend="strict")
    assert cpu == other and hash(cpu) == hash(other)
    assert cpu.as_attrs() == other.as_attrs() and "backend" not in cpu.as_attrs()


def test_device_convolver_matches_the_cpu_convolver():
    rng = np.random.default_rng(3)
    n = 24
    stress = rng.standard_normal((n, n))
    be = resolve_backend("strict")
    device = DeviceConvolver(n, 0.5, 2.0, be)
    got = be.to_host(device(be.asarray(stress)))
    want = Convolver(n, 0.5, 2.0)(stress)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(want).max())


def _relative(a: float, b: float) -> float:
    return abs(a - b) / abs(b)


def _assert_same_curve(got, want, rtol: float) -> None:
    for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
        assert _relative(float(got[name]), float(want[name])) <= rtol, (
            f"{name}: {float(got[name])!r} vs {float(want[name])!r}")


STRICT_CASES = {
    "regular rigid": BrushParams("regular", 16, math.inf, 64),
    "regular soft": BrushParams("regular", 16, 0.455, 96),
    "random": BrushParams("random", 12, 1.0, 64, seed=1),
    # soft enough for the far-field warm start (`WarmStart._far_response`)
    "random soft": BrushParams("random", 12, 1e-4, 64, seed=1),
    "rough preloaded": BrushParams("regular", 16, 0.455, 64, roughness=0.5, preload=1.0,
                                   seed=2),
}


@pytest.mark.parametrize("name", list(STRICT_CASES))
def test_strict_namespace_runs_the_pull_off_like_numpy(name):
    """The portable core (device convolver, DeviceBlocks, namespace calls) on CPU."""
    params = STRICT_CASES[name]
    want = simulate(params, WHOLE_GRID)
    got = simulate(params, WHOLE_GRID, backend="strict")
    _assert_same_curve(got, want, STRICT_RTOL)
    np.testing.assert_array_equal(got.detachment_step.values, want.detachment_step.values)
    assert got.attrs["parameter_hash"] == want.attrs["parameter_hash"]
    assert got.attrs["backend"] == "strict" and want.attrs["backend"] == "cpu"
    assert got.attrs["preconditioner"] == want.attrs["preconditioner"] == "blocks"
    assert want.attrs["device_name"] == "cpu" and want.attrs["device_memory_bytes"] == 0


def test_batched_downdate_matches_the_per_pillar_one():
    """`DeviceBlocks.detach` removes slots from every touched pillar in one
    batched Schur complement (pillars losing 1, 2 and 3 slots padded to 1,
    2 and 4, and one pillar letting go whole); the inverses and the local
    responses must be `BlockInverse`'s per-pillar ones to round-off."""
    from brushcore.model.layout import build_labels
    params = BrushParams("regular", 16, 1e-2, 64)
    flat = build_labels(params).ravel()
    elements = np.flatnonzero(flat >= 0)
    pillar_of = flat[elements].astype(np.intp)
    compliance = np.full(16, 0.3)
    args = (elements, pillar_of, 64, compliance, params.h, params.e_star)
    cpu = BlockInverse(*args)
    strict = resolve_backend("strict")
    dev = DeviceBlocks(*args, backend=strict)
    gone = np.concatenate([np.flatnonzero(pillar_of == p)[:k] for p, k in ((0, 1), (5, 2), (6, 3))]
                          + [np.flatnonzero(pillar_of == 9)])
    stress = np.random.default_rng(3).random(elements.size)
    want = cpu.detach(gone, stress.copy(), cpu.pos)
    got = dev.detach(strict.asarray(gone), strict.asarray(stress), strict.asarray(cpu.pos))
    np.testing.assert_allclose(strict.to_host(dev.inv), cpu.inv, rtol=0, atol=1e-12 * np.abs(cpu.inv).max())
    np.testing.assert_allclose(strict.to_host(got), want, rtol=1e-10, atol=1e-12 * np.abs(want).max())
    assert not strict.to_host(dev.inv)[9].any() and dev.respond  # strict keeps the warm start
    # re-attaching (a protocol's approach): blocks inverted afresh on the device
    # against the host's bordered ones, coarse vectors and sums of |G| alike
    back = np.concatenate([gone[:2], gone[-5:]])
    cpu.attach(back)
    dev.attach(strict.asarray(back))
    scale = np.abs(cpu.inv).max()
    np.testing.assert_allclose(strict.to_host(dev.inv), cpu.inv, rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(strict.to_host(dev._z), cpu._z, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(strict.to_host(dev._reach), np.abs(cpu.inv).sum(axis=2), rtol=0,
                               atol=1e-10 * scale)  # the host's is computed where read


def test_device_setup_computes_the_hosts_numbers():
    """The kernel, its spectrum, the blocks' coefficient table and the initial
    blocks, computed in the device's namespace (strict here), are the host's
    numbers: the same formula, one namespace for both."""
    from brushcore.model.layout import build_labels
    from brushcore.numerics.halfspace.kernel import wrapped_kernel
    strict = resolve_backend("strict")
    host = wrapped_kernel(48, 0.5, 2.0)
    device = strict.to_host(wrapped_kernel(48, 0.5, 2.0, strict.xp))
    np.testing.assert_allclose(device, host, rtol=1e-14, atol=0)
    assert device[48].max() == 0.0 and device[:, 48].max() == 0.0  # the unreached middle lines
    spectrum = strict.to_host(DeviceConvolver(48, 0.5, 2.0, strict).spectrum)
    np.testing.assert_allclose(spectrum, np.fft.rfft2(host).real, rtol=0,
                               atol=1e-13 * np.abs(spectrum).max())
    params = BrushParams("random", 12, 1e-2, 64, seed=4)
    flat = build_labels(params).ravel()
    elements = np.flatnonzero(flat >= 0)
    pillar_of = flat[elements].astype(np.intp)
    args = (elements, pillar_of, 64, np.full(12, 0.3), params.h, params.e_star)
    cpu, dev = BlockInverse(*args), DeviceBlocks(*args, backend=strict)
    np.testing.assert_allclose(dev._table, cpu._table, rtol=1e-14, atol=0)
    for p in range(12):
        k = int(np.count_nonzero(pillar_of == p))
        np.testing.assert_allclose(strict.to_host(dev._device_block(p, np.arange(k))),
                                   cpu._block(p, np.arange(k)), rtol=1e-14, atol=0)


def test_strict_matrix_free_path_when_blocks_do_not_fit(monkeypatch):
    """Without room for blocks the device takes the Sherman-Morrison diagonal,
    as the CPU does without room for blocks or tiles."""
    monkeypatch.setattr(BlockInverse, "fits", classmethod(lambda cls, *a, **k: False))
    monkeypatch.setattr(TileCoarse, "fits", classmethod(lambda cls, *a, **k: False))
    monkeypatch.setattr(DeviceBlocks, "fits_device", classmethod(lambda cls, *a, **k: False))
    params = BrushParams("regular", 16, 0.455, 64)
    want = simulate(params, WHOLE_GRID)
    got = simulate(params, WHOLE_GRID, backend="strict")
    _assert_same_curve(got, want, STRICT_RTOL)
    np.testing.assert_array_equal(got.detachment_step.values, want.detachment_step.values)
    assert got.attrs["preconditioner"] == want.attrs["preconditioner"] == "diagonal"


def test_device_blocks_budget_reads_free_memory():
    pillar_of = np.repeat(np.arange(4), 100)  # 4 blocks of 100 x 100 doubles: 320 kB
    small = types.SimpleNamespace(free_memory=lambda: 400e3)
    large = types.SimpleNamespace(free_memory=lambda: 1e9)
    assert not DeviceBlocks.fits_device(pillar_of, small)  # half of it is the budget
    assert DeviceBlocks.fits_device(pillar_of, large)


def test_sweep_ignores_where_curves_ran(tmp_path):
    paths = []
    for kbar, device in ((1.0, "cpu"), (math.inf, "NVIDIA H200")):
        ds = simulate(BrushParams("regular", 4, kbar, 32, allow_coarse=True))
        if device != "cpu":
            ds.attrs.update(backend="gpu", device_name=device, device_memory_bytes=2**37)
        paths.append(tmp_path / f"{kbar}.nc")
        write_curve(ds, paths[-1])
    sweep = build_sweep(paths)
    assert not {"backend", "device_name", "device_memory_bytes"} & set(sweep.attrs)
    assert not {"backend", "device_name", "device_memory_bytes"} & set(sweep.variables)


def test_cli_backend_flag(tmp_path, monkeypatch, capsys):
    out = tmp_path / "c.nc"
    args = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "1",
            "--grid", "48", "--out", str(out), "--quiet"]
    assert main([*args, "--backend", "cpu"]) == 0
    assert read_curve(out).attrs["backend"] == "cpu"
    _no_cupy(monkeypatch)
    gpu_out = tmp_path / "g.nc"
    assert main([*args[:-3], "--out", str(gpu_out), "--quiet", "--backend", "gpu"]) == 2
    err = capsys.readouterr().err
    assert "--backend gpu is invalid" in err and "CuPy is not installed" in err, err
    assert not gpu_out.exists()
    with pytest.raises(SystemExit) as info:  # a test namespace, not a user choice
        main([*args, "--backend", "strict"])
    assert info.value.code == 2


# --- on a GPU ----------------------------------------------------------------


def _gpu_or_skip() -> None:
    try:
        resolve_backend("gpu")
    except ParameterError as exc:
        pytest.skip(f"no GPU backend here: {exc}")


def _detach_displacement(ds) -> np.ndarray:
    """d at which each pillar element detached (ties: the same d)."""
    step = ds.detachment_step.values
    return ds.displacement.values[step[step >= 0]]


GPU_CASES = {
    "16x16 kbar 0.455 at 256": BrushParams("regular", 256, 0.455, 256),
    "16x16 kbar 0.455 at 512": BrushParams("regular", 256, 0.455, 512),
    "rigid 8x8 at 256": BrushParams("regular", 64, math.inf, 256),
    # the engine's other paths on a card: a whole-grid random brush with its
    # far-field warm start, and the protocol engine (blocks re-inverted on attach)
    "random 64 kbar 1e-4 at 256": BrushParams("random", 64, 1e-4, 256, seed=1),
    "rough 4x4 preloaded at 128": BrushParams("regular", 16, 0.455, 128, roughness=0.5,
                                              preload=1.0, seed=2),
}


@pytest.mark.gpu
@pytest.mark.parametrize("name", list(GPU_CASES))
def test_gpu_matches_cpu(name):
    _gpu_or_skip()
    params = GPU_CASES[name]
    want = simulate(params, WHOLE_GRID)
    got = simulate(params, WHOLE_GRID, backend="gpu")
    _assert_same_curve(got, want, GPU_RTOL)
    # The same detachment sequence up to ties: every element lets go at the same d.
    np.testing.assert_allclose(_detach_displacement(got), _detach_displacement(want),
                               rtol=GPU_RTOL)
    assert got.attrs["backend"] == "gpu" and got.attrs["device_memory_bytes"] > 0


def _cupy13_bincount(x, weights=None, minlength=0):
    """`cupy.bincount` as CuPy 13 has it: an empty ``x`` raises (cupy#8116),
    where NumPy returns zeros."""
    if x.size == 0:
        raise ValueError("zero-size array to reduction operation maximum which has no identity")
    return np.bincount(x, weights=weights, minlength=minlength)


def _fake_gpu() -> backend_module.Backend:
    """The gpu backend's wiring with NumPy standing in for CuPy (array_api_compat's
    NumPy view as the namespace, a fake card of 8 GiB, CuPy 13's bincount)."""
    compat = pytest.importorskip("array_api_compat.numpy")
    device = types.SimpleNamespace(id=0, synchronize=lambda: None)
    runtime = types.SimpleNamespace(memGetInfo=lambda: (6 * 2**30, 8 * 2**30),
                                    getDeviceProperties=lambda i: {"name": b"Fake GPU"})
    pool = types.SimpleNamespace(total_bytes=lambda: 0, used_bytes=lambda: 0)
    native = types.SimpleNamespace(
        ndarray=np.ndarray, asnumpy=np.asarray, flatnonzero=np.flatnonzero,
        bincount=_cupy13_bincount, get_default_memory_pool=lambda: pool,
        cuda=types.SimpleNamespace(runtime=runtime, Device=lambda: device))
    return backend_module.Backend("gpu", compat, native)


def test_gpu_wiring_with_numpy_standing_in_for_cupy(monkeypatch):
    fake = _fake_gpu()
    real = resolve_backend
    for module in (curve_module, curve_format, solve_module):
        monkeypatch.setattr(module, "resolve_backend",
                            lambda name: fake if name == "gpu" else real(name))
    params = BrushParams("random", 12, 1.0, 64, seed=1)
    want = simulate(params, WHOLE_GRID)
    got = simulate(params, WHOLE_GRID, backend="gpu")
    _assert_same_curve(got, want, STRICT_RTOL)
    np.testing.assert_array_equal(got.detachment_step.values, want.detachment_step.values)
    assert got.attrs["device_name"] == "Fake GPU"
    assert got.attrs["device_memory_bytes"] == 8 * 2**30
    assert fake.free_memory() == 6 * 2**30
