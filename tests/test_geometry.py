"""Any brush geometry: hexagonal lattices, square and elliptic pillars, file layouts."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest
from conftest import full_contact_stiffness, punch_params

from brushcore import BrushParams, ParameterError, SolverOptions, simulate, theory
from brushcore.model.solve import run
from brushcore.model.lattices import hexagonal_fill, hexagonal_lattice
from brushcore.model.labelmap import touching_pillars
from brushcore.model.layout import build_labels, hexagonal_centres
from brushcore.model.layout_file import file_params, read_label_map, save_label_map
from brushcore.model.params import MAX_PHI_ERROR

SHAPES = [("disc", 1.0, 0.0), ("square", 1.0, 0.0), ("square", 1.0, 30.0),
          ("ellipse", 2.0, 0.0), ("ellipse", 2.5, 60.0)]


def _geometry(layout: str, n_pillars: int, kbar: float, grid: int, shape=SHAPES[0], **kw):
    kind, aspect, orientation = shape
    return BrushParams(layout, n_pillars, kbar, grid, shape=kind, aspect=aspect,
                       orientation=orientation, **kw)


# -- filling factor ------------------------------------------------------------------

@pytest.mark.parametrize("layout", ["regular", "random", "hexagonal"])
@pytest.mark.parametrize("shape", SHAPES, ids=lambda s: f"{s[0]}-{s[1]:g}-{s[2]:g}")
def test_filling_factor_is_real_pillar_area(layout, shape):
    """phi is the real pillar area / L^2 for every shape and layout.

    Tolerance: the discretisation rule of issue 16 (MAX_PHI_ERROR = 5 %),
    which build_labels enforces.  Measured on these grids (equal-area radius
    12.5 elements for 4 regular pillars on 128^2, 6.25 for 16 random or
    hexagonal ones): at most 1.6 %; pillars at different sub-element
    offsets (random, hexagonal) average their boundary errors out, pillars
    of a regular lattice share one offset and hence one error.
    """
    n_pillars = 4 if layout == "regular" else 16
    p = _geometry(layout, n_pillars, 1.0, 128, shape, phi=0.12, seed=1)
    labels = build_labels(p)
    assert labels.max() + 1 == n_pillars
    counts = np.bincount(labels[labels >= 0])
    assert counts.size == n_pillars and counts.min() > 0
    error = np.count_nonzero(labels >= 0) / labels.size / 0.12 - 1
    assert abs(error) <= MAX_PHI_ERROR, f"phi realised {100 * error:+.2f} %"
    assert not touching_pillars(labels)


def test_grid_aligned_square_side_is_rounded_to_whole_elements():
    """A square centred on an element corner covers 2 round(s/2h) x 2 round(s/2h) elements.

    Exact, and the reason axis-aligned squares on a regular lattice need a
    finer grid than discs: 16 squares on 128^2 (side 11.08 elements) come
    out 12 x 12 (+17 % area), which build_labels refuses.
    """
    p = _geometry("regular", 16, 1.0, 256, SHAPES[1], phi=0.12)
    side = math.sqrt(p.pillar_area) / p.h  # 22.17 elements
    labels = build_labels(p)
    expected = (2 * round(side / 2)) ** 2
    assert np.all(np.bincount(labels[labels >= 0]) == expected)
    with pytest.raises(ParameterError, match=r"grid=128 .*phi is realised as 0.1406"):
        build_labels(_geometry("regular", 16, 1.0, 128, SHAPES[1], phi=0.12))


def test_ellipse_axes_and_orientation():
    """An ellipse of aspect 3 at 90 degrees is the 0-degree one transposed (to rounding)."""
    flat = build_labels(_geometry("regular", 1, 1.0, 96, ("ellipse", 3.0, 0.0), phi=0.1))
    tall = build_labels(_geometry("regular", 1, 1.0, 96, ("ellipse", 3.0, 90.0), phi=0.1))
    rows = np.flatnonzero(flat.max(axis=1) >= 0)
    cols = np.flatnonzero(flat.max(axis=0) >= 0)
    # semi-axes a = sqrt(3 A / pi) = 29.7, b = 9.9 elements: x extent 3x the y extent
    assert (cols.size / rows.size) == pytest.approx(3.0, rel=0.1)
    assert np.array_equal(flat >= 0, (tall >= 0).T)


# -- hexagonal lattice ---------------------------------------------------------------

def test_hexagonal_lattice_counts_and_pitch():
    """N = rows x columns nearest 2/sqrt(3); every nearest neighbour one pitch away."""
    assert hexagonal_lattice(64) == (8, 8)
    assert hexagonal_lattice(56) == (8, 7)
    assert hexagonal_lattice(4) == (2, 2) and hexagonal_lattice(1) == (1, 1)
    for n in (2, 7, 8, 13):
        assert hexagonal_lattice(n) is None
    c = hexagonal_centres(56, 1000.0)
    d = np.hypot(*(c[:, None] - c[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    pitch = d.min()
    nearest = np.sort(d, axis=1)[:, :6]
    inner = (nearest[:, 5] < 1.01 * pitch)  # pillars with a full ring of neighbours
    assert inner.sum() >= 20 and np.allclose(nearest[inner], pitch, rtol=1e-12)
    # centred: the lattice is symmetric under a half turn about the square's centre
    assert np.allclose(np.sort((1000.0 - c).round(9), axis=0), np.sort(c.round(9), axis=0))
    # 8 x 7: 7.5 pitches wide, 7 sqrt(3)/2 + 1 = 7.06 high -> the cells cover 86 %
    assert pitch == pytest.approx(1000.0 / 7.5)
    assert hexagonal_fill(56) == pytest.approx(56 * math.sqrt(3) / 2 / 7.5**2)
    # margin to the walls >= half the pillar gap (as in the regular lattice)
    assert c.min() >= 0.5 * pitch - 1e-9 and c.max() <= 1000.0 - 0.5 * pitch + 1e-9


@pytest.mark.parametrize("n_pillars", [64, 56])
def test_rigid_hexagonal_brush_is_at_the_phi_limit_of_the_area_it_covers(n_pillars):
    """Eq. 5's rigid limit phi^-1/4 taken with the filling factor of the
    lattice's footprint, phi / lattice_fill, the fill counted as N
    hexagonal cells of the pitch (the pitch that fits leaves part of the
    square bare: 77 % covered for 8 x 8, 86 % for 8 x 7).  Measured on
    256^2: 1.0005 and 1.0011 of it, against 0.936 and 0.965 of phi^-1/4
    itself, so the denser footprint, not the nominal phi, sets the force
    (the regular 8 x 8 brush sits at 1.010 of phi^-1/4, test_physics; with
    the lattice's bounding box as footprint the ratio would be about 0.985,
    a review helper's figure).  A fill 2 % off fails.
    """
    ds = simulate(BrushParams("hexagonal", n_pillars, math.inf, 256, phi=0.12))
    local_phi = ds.attrs["phi_actual"] / hexagonal_fill(n_pillars)
    ratio = float(ds.adhesive_force_normalized) / theory.rigid_limit(local_phi)
    assert ratio == pytest.approx(1.0, abs=0.005), f"F_ad / (phi/fill)^-1/4 = {ratio:.4f}"
    # the level Fig. 6 and the summary draw is this one (phi * fill passed: +14 % at N = 64)
    assert theory.hexagonal_rigid_limit(ds.attrs["phi_actual"], n_pillars) == pytest.approx(
        theory.rigid_limit(local_phi), rel=1e-12)


def test_hexagonal_count_that_does_not_fit_is_refused_with_alternatives():
    with pytest.raises(ParameterError, match=r"n_pillars=7 .*e\.g\. 6 or 9"):
        BrushParams("hexagonal", 7, 1.0, 256)


# -- soft plateau for any lattice ----------------------------------------------------

def _single_pillar_force(mask: np.ndarray) -> float:
    """F_ad of one rigid pillar with exactly this footprint, alone on a snug grid.

    The DC-FFT operator is translation invariant, so this is the force the
    pillar would hold with no neighbours.
    """
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    foot = mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    n = max(foot.shape) + 8
    labels = np.full((n, n), -1, dtype=np.int32)
    labels[4:4 + foot.shape[0], 4:4 + foot.shape[1]][foot] = 0
    p = BrushParams("regular", 1, math.inf, n, phi=foot.sum() / n**2, allow_coarse=True)
    _, curve, _ = run(p, labels=labels)
    return float(curve.force.max())


@pytest.mark.parametrize("layout, shape", [("hexagonal", SHAPES[0]), ("hexagonal", SHAPES[1]),
                                           ("regular", SHAPES[1]), ("regular", SHAPES[0])])
def test_soft_pillars_share_load_equally_on_any_lattice(layout, shape):
    """Eq. 3: very soft pillars carry equal loads, so F_ad = N x one pillar's force.

    4 pillars of equal-area radius 4 elements on 128^2: 64 elements (16
    radii) apart on the square lattice, 51.2 (12.8 radii) on the hexagonal
    one.  With unequal footprints the soft brush holds max_j (N - j) f_(j)
    (pillars let go weakest first at equal load; f sorted ascending), which
    is N min f for nearly equal f.  Tolerance 2 %, as for today's 4
    separated soft discs (test_physics): measured 0.8-1.2 % below, the far
    field of the neighbours (0.2-0.3 % at twice the spacing on 256^2).
    """
    n_pillars, radius, grid = 4, 4.0, 128
    p = _geometry(layout, n_pillars, 1e-6, grid, shape,
                  phi=n_pillars * math.pi * radius**2 / grid**2, allow_coarse=True)
    labels = build_labels(p)
    _, curve, _ = run(p, labels=labels)
    f = np.sort([_single_pillar_force(labels == q) for q in range(n_pillars)])
    soft = max((n_pillars - j) * f[j] for j in range(n_pillars))
    ratio = float(curve.force.max()) / soft
    assert abs(ratio - 1) < 0.02, f"{layout} {shape[0]}: F_ad / soft plateau = {ratio:.4f}"


# -- layouts from files --------------------------------------------------------------

def _ellipse_brush(**kw) -> BrushParams:
    return _geometry("random", 12, 0.05, 64, ("ellipse", 1.8, 25.0), phi=0.15, seed=3, **kw)


def _fad_and_work(params: BrushParams, labels=None) -> tuple[float, float]:
    # Double precision: invariance up to round-off (SolverOptions.precision).
    _, curve, _ = run(params, SolverOptions(precision="double"), labels=labels)
    return float(curve.force.max()), float(np.trapezoid(curve.force, curve.displacement))


def test_layout_read_back_from_its_label_map_gives_identical_results(tmp_path):
    """Same label map, same springs: the same floating-point operations, bit for bit."""
    params = _ellipse_brush()
    labels = build_labels(params)
    path = save_label_map(labels, tmp_path / "brush.npy")
    from_file = file_params(path, params.kbar)
    assert (from_file.n_pillars, from_file.grid) == (12, 64)
    assert np.array_equal(build_labels(from_file), labels)
    assert from_file.stiffness == params.stiffness
    assert _fad_and_work(from_file) == _fad_and_work(params)


@pytest.mark.parametrize("turns", [1, 3])
def test_rotating_a_file_layout_by_90_degrees_changes_nothing(tmp_path, turns):
    """The square grid and the half-space kernel are invariant under a quarter turn.

    Tolerance 1e-8 as the transposition tests: CG (rtol 1e-4) sees the
    same system in another element order, so it rounds differently.
    """
    labels = build_labels(_ellipse_brush())
    base = file_params(save_label_map(labels, tmp_path / "a.npy"), 0.05)
    turned = file_params(save_label_map(np.rot90(labels, turns), tmp_path / "b.npy"), 0.05)
    (f0, w0), (f1, w1) = _fad_and_work(base), _fad_and_work(turned)
    assert f1 == pytest.approx(f0, rel=1e-8) and w1 == pytest.approx(w0, rel=1e-8)


def test_image_layout_reads_connected_components_as_pillars(tmp_path):
    """A PNG of black pillars on white reads back as the same pillars, as drawn (y up)."""
    import matplotlib.pyplot as plt

    labels = build_labels(_geometry("hexagonal", 12, 1.0, 96, SHAPES[2], phi=0.15))
    path = tmp_path / "brush.png"
    plt.imsave(path, (labels >= 0)[::-1], cmap="gray_r", vmin=0, vmax=1)  # row 0 at the top
    read = read_label_map(path, 96)
    assert read.max() + 1 == 12 and np.array_equal(read >= 0, labels >= 0)
    # each pillar of the image is one pillar of the map
    pairs = {(int(a), int(b)) for a, b in zip(read[labels >= 0], labels[labels >= 0])}
    assert len(pairs) == 12


def test_image_corners_that_join_blobs_are_said(tmp_path):
    """Two squares meeting at a corner are one pillar in an image (8-connected),
    and the reader says so; a label map keeps them apart."""
    import matplotlib.pyplot as plt

    corner = np.full((32, 32), -1)
    corner[4:8, 4:8], corner[8:12, 8:12], corner[20:24, 20:24] = 0, 1, 2
    path = tmp_path / "corner.png"
    plt.imsave(path, (corner >= 0)[::-1], cmap="gray_r", vmin=0, vmax=1)
    with pytest.warns(UserWarning, match=r"corner\.png: corners join 3 edge-connected blobs "
                      r"into 2 pillars .*\.npy label map"):
        assert read_label_map(path, 32).max() + 1 == 2
    apart = tmp_path / "apart.png"
    plt.imsave(apart, (corner >= 1)[::-1], cmap="gray_r", vmin=0, vmax=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # separate blobs: nothing to say
        assert read_label_map(apart, 32).max() + 1 == 2


def _save(tmp_path, name, array):
    path = tmp_path / name
    np.save(path, array, allow_pickle=True)
    return path


def test_refused_label_maps_name_the_file_and_the_pillars(tmp_path):
    good = np.full((32, 32), -1, dtype=np.int64)
    good[4:8, 4:8] = 0
    good[4:8, 10:14] = 1
    assert read_label_map(_save(tmp_path, "good.npy", good), 32).max() == 1
    touch = good.copy()
    touch[4:8, 8:10] = 1  # pillar 1 reaches pillar 0
    with pytest.raises(ParameterError, match=r"touch\.npy.*pillars 0 and 1 at element"):
        read_label_map(_save(tmp_path, "touch.npy", touch), 32)
    corner = np.full((32, 32), -1)
    corner[4:8, 4:8], corner[8:12, 8:12] = 0, 1  # a shared corner only: allowed
    assert read_label_map(_save(tmp_path, "corner.npy", corner), 32).max() == 1
    gap = good.copy()
    gap[20:24, 20:24] = 3  # label 2 missing
    with pytest.raises(ParameterError, match=r"gap\.npy.*no element has label 2"):
        read_label_map(_save(tmp_path, "gap.npy", gap), 32)
    low = good.copy()
    low[0, 5] = -2
    with pytest.raises(ParameterError, match=r"low\.npy.*row 0, column 5\) holds -2"):
        read_label_map(_save(tmp_path, "low.npy", low), 32)
    with pytest.raises(ParameterError, match=r"good\.npy.*is 32 x 32 elements.*a 64 x 64 map"):
        read_label_map(tmp_path / "good.npy", 64)
    with pytest.raises(ParameterError, match=r"float\.npy.*integer label map"):
        read_label_map(_save(tmp_path, "float.npy", good.astype(float)), 32)
    with pytest.raises(ParameterError, match=r"pickle\.npy.*not readable as a plain .npy "
                                             r"array: it holds Python objects") as err:
        read_label_map(_save(tmp_path, "pickle.npy", np.array([{"a": 1}], dtype=object)))
    assert "allow_pickle" not in str(err.value)  # never advise loading pickles
    with pytest.raises(ParameterError, match=r"layout_file=.*missing\.npy.*no such file"):
        read_label_map(tmp_path / "missing.npy")
    background = np.where(good >= 0, good + 1, 0)  # scipy.ndimage.label's convention
    with pytest.raises(ParameterError, match=r"background\.npy.*label 0 covers 0\.969 of the "
                                             r"map: is 0 the background\?"):
        read_label_map(_save(tmp_path, "background.npy", background), 32)
    (tmp_path / "folder.npy").mkdir()
    with pytest.raises(ParameterError, match=r"folder\.npy.*\(a folder\)"):
        read_label_map(tmp_path / "folder.npy")
    (tmp_path / "maps").mkdir()  # no suffix: it was "unknown kind '(no suffix)'"
    with pytest.raises(ParameterError, match=r"maps.*\(a folder\)"):
        read_label_map(tmp_path / "maps")


def test_broken_images_are_refused_not_crashed_on(tmp_path):
    """A PNG cut short or another format under a .png name was a traceback
    from the decoder (only the header read was guarded)."""
    from PIL import Image

    pixels = np.full((32, 32), 255, dtype=np.uint8)
    pixels[4:10, 4:10] = 0
    Image.fromarray(pixels).save(tmp_path / "whole.png")
    data = (tmp_path / "whole.png").read_bytes()
    (tmp_path / "half.png").write_bytes(data[:len(data) // 2])
    Image.fromarray(pixels).save(tmp_path / "photo.jpg")
    (tmp_path / "jpeg.png").write_bytes((tmp_path / "photo.jpg").read_bytes())
    assert read_label_map(tmp_path / "whole.png").max() == 0
    for name in ("half.png", "jpeg.png"):
        with pytest.raises(ParameterError, match=rf"{name}.*not decodable as one.*a PNG image"):
            read_label_map(tmp_path / name)
    # white pillars on black, and no pixel dark enough: the message says how pixels are read
    Image.fromarray(255 - pixels).save(tmp_path / "inverted.png")
    Image.fromarray(np.full((32, 32), 200, dtype=np.uint8)).save(tmp_path / "grey.png")
    for name, reason in (("inverted.png", "one pillar covers 0.965 of it"),
                         ("grey.png", "no pillar element")):
        with pytest.raises(ParameterError, match=rf"{name}.*{reason}.*darker than 50 % grey"):
            read_label_map(tmp_path / name)


def test_image_over_the_pixel_limit_is_refused_before_decoding(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from brushcore.model import layout_file

    path = tmp_path / "big.png"
    plt.imsave(path, np.ones((40, 40)), cmap="gray")
    monkeypatch.setattr(layout_file, "MAX_IMAGE_PIXELS", 1000)
    with pytest.raises(ParameterError, match=r"big\.png.*is 40 x 40 pixels.*at most 1000 pixels"):
        read_label_map(path)


def test_file_params_refuse_counts_that_differ_from_the_file(tmp_path):
    labels = build_labels(_ellipse_brush())
    path = save_label_map(labels, tmp_path / "m.npy")
    with pytest.raises(ParameterError, match=r"n_pillars=11 .*allowed 12"):
        file_params(path, 0.1, n_pillars=11)
    with pytest.raises(ParameterError, match=r"grid=128 is invalid: allowed 64, the value of"):
        file_params(path, 0.1, grid=128)
    # a hand-made BrushParams that disagrees with its file is caught by build_labels
    p = BrushParams("file", 13, 0.1, 64, phi=0.15, layout_file=str(path), allow_coarse=True)
    with pytest.raises(ParameterError, match=r"n_pillars=13 .*allowed 12, the value of"):
        build_labels(p)


# -- square punch --------------------------------------------------------------------

def _square_punch(side: int) -> BrushParams:
    """One rigid square punch of `side` elements, centred on an element corner (exact area)."""
    n = 2 * math.ceil(0.8 * side)
    return BrushParams("regular", 1, math.inf, n, phi=side**2 / n**2, shape="square")


@pytest.fixture(scope="module")
def square_punches():
    return {s: simulate(_square_punch(s)) for s in (32, 48, 64)}


def test_square_punch_stiffness_converges_to_the_square_plates_capacitance(square_punches):
    """A grid-aligned square footprint is exact, so only the pressure's
    resolution at the edges and corners is left: the stiffness rises at
    first order in h / side to pi E* C s (`theory.square_punch_stiffness`,
    C the unit square plate's capacitance).  Measured: 1.14021, 1.14417,
    1.14617 s E* at sides 32, 48, 64, extrapolated to 1.15240 (order 0.97)
    against 1.15230, 9e-5 apart; the disc of equal area would give 1.12838
    (2 a0 E*), 2.1 % less.
    """
    from brushcore.data.extrapolation import extrapolate

    sides = sorted(square_punches)
    per_side = [full_contact_stiffness(square_punches[s]) / s for s in sides]
    assert per_side == sorted(per_side), per_side  # from below, grid by grid
    fit = extrapolate([1 / s for s in sides], per_side)
    assert fit.value == pytest.approx(theory.square_punch_stiffness(1.0, 1.0), rel=1e-3), fit
    assert 0.8 < fit.order < 1.2, fit


@pytest.mark.parametrize("orientation", [45.0, 30.0])
def test_rotated_square_punch_stiffness_is_the_square_plates(orientation):
    """Rotated, a square's edges are staircases (its area is no longer side^2),
    yet its stiffness per sqrt(area) tends to the same pi E* C, whatever the
    orientation.  Measured at 45 degrees: 1.14276, 1.14598, 1.14769 at
    sides 32, 48, 64, extrapolated to 1.15224 (order 1.04; 1.15225 with side
    96 added) against 1.15230; at 30 degrees the staircase is irregular
    (1.14612, 1.14861, 1.14924, and 1.15036 at 96: a fit over the four is
    flagged not asymptotic), so the finest grid is held to 3e-3."""
    from brushcore.data.extrapolation import extrapolate

    per_root_area, h = [], []
    for side in (32, 48, 64):
        n = 2 * math.ceil(0.8 * side)
        ds = simulate(BrushParams("regular", 1, math.inf, n, phi=side**2 / n**2,
                                  shape="square", orientation=orientation, allow_coarse=True))
        area = ds.attrs["real_contact_area"] / ds.attrs["h"] ** 2  # elements
        per_root_area.append(full_contact_stiffness(ds) / math.sqrt(area))
        h.append(1 / math.sqrt(area))
    exact = theory.square_punch_stiffness(1.0, 1.0)
    assert max(per_root_area) < exact
    if orientation == 45.0:
        fit = extrapolate(h, per_root_area)
        assert fit.value == pytest.approx(exact, rel=1e-3) and 0.8 < fit.order < 1.3, fit
    else:
        assert per_root_area[-1] == pytest.approx(exact, rel=3e-3), per_root_area


def test_square_punch_pull_off_against_fine_grid_and_equal_disc(square_punches):
    """A square flat punch lets go at about 0.88 of the Kendall force of the disc of equal area.

    No square-punch adhesion formula was found in the reference corpora
    searched (Popov, Pohrt & Li, Friction 5 (2017) 308 simulate square
    punches with this method, but no value of theirs was available), so the
    reference is a fine-grid run of this solver, F_ad / F_K(a0) for sides of
    32, 48, 64, 96, 128 and 192 elements (grids up to 308):
    0.9129, 0.8995, 0.9006, 0.8917, 0.8885, 0.8846; the equal-area disc
    gives 1.002-1.003 on the same grids.  The corners, where detachment
    starts, converge slowly (about first order in h: 64/128/192 extrapolate
    to ~0.877), so the 64-element run must lie within 2.5 % of the finest
    one (measured 1.8 %), and 5-15 % below the equal disc: corners
    concentrate the stress and start the detachment.
    """
    ratios = {}
    for s, ds in square_punches.items():
        assert ds.attrs["real_contact_area"] == s * s
        a0 = theory.equivalent_radius(s * s)
        ratios[s] = float(ds.adhesive_force) / theory.kendall_force(a0, 1.0, 1.0)
        assert float(ds.adhesive_force_normalized) == pytest.approx(ratios[s], rel=1e-12)
    assert abs(ratios[64] / 0.8846 - 1) < 0.025, ratios
    assert ratios[32] > ratios[64], f"no downward drift towards the fine grid: {ratios}"
    disc = simulate(punch_params(theory.equivalent_radius(64 * 64)))
    disc_ratio = float(disc.adhesive_force_normalized)
    assert 0.85 < ratios[64] / disc_ratio < 0.95, f"square / disc = {ratios[64] / disc_ratio:.4f}"


# -- elliptic punch ------------------------------------------------------------------

#: Semi-axes' geometric mean [elements] and grid of the elliptic punches.
_ELLIPSE_RADIUS, _ELLIPSE_GRID = 30, 136
_ELLIPSES = [(2.0, 0.0), (2.0, 30.0), (3.0, 0.0), (3.0, 30.0)]


@pytest.fixture(scope="module")
def elliptic_punches():
    """Rigid elliptic punches by (aspect, orientation), and the disc of the
    same radius on the same grid under the key None."""
    phi = math.pi * _ELLIPSE_RADIUS**2 / _ELLIPSE_GRID**2
    runs = {None: simulate(BrushParams("regular", 1, math.inf, _ELLIPSE_GRID, phi=phi))}
    for aspect, orientation in _ELLIPSES:
        runs[aspect, orientation] = simulate(BrushParams(
            "regular", 1, math.inf, _ELLIPSE_GRID, phi=phi, shape="ellipse", aspect=aspect,
            orientation=orientation))
    return runs


def _semi_axes(ds, aspect: float) -> tuple[float, float]:
    """Semi-axes [h] of the ellipse of the punch's realised area and its aspect."""
    a0 = theory.equivalent_radius(float(ds.attrs["real_contact_area"]))
    return a0 * math.sqrt(aspect), a0 / math.sqrt(aspect)


@pytest.mark.parametrize("aspect,orientation", _ELLIPSES)
def test_elliptic_punch_stiffness_is_galins(elliptic_punches, aspect, orientation):
    """A rigid elliptic punch has Galin's stiffness pi a E* / K(e)
    (`theory.elliptic_punch_stiffness`), for any orientation on the grid.

    The staircase footprint is softer at first order in h / a0, as the
    disc's (-0.3 to -0.6 % at a0 = 20-40 elements; measured -0.34 to -0.46 % here),
    so the sharp check is the ratio to a disc of the same radius on the same
    grid, where that error nearly cancels: each stiffness over sqrt(area)
    against Galin's ratio at equal area, 1.03011 for aspect 2 and 1.07596
    for 3.  Measured at a0 = 30 elements: within 6.7e-4 (4e-5 to 6.4e-4 at
    40); an aspect 10 % off moves the ratio by 8.6e-3 (2) and 1.3e-2 (3).
    """
    disc_run, ds = elliptic_punches[None], elliptic_punches[aspect, orientation]
    disc, disc_area = full_contact_stiffness(disc_run), float(disc_run.attrs["real_contact_area"])
    ellipse, area = full_contact_stiffness(ds), float(ds.attrs["real_contact_area"])
    galin = theory.elliptic_punch_stiffness(*_semi_axes(ds, aspect), 1.0)
    assert -0.01 < ellipse / galin - 1 < 0, f"stiffness / Galin's = {ellipse / galin:.5f}"
    measured = (ellipse / math.sqrt(area)) / (disc / math.sqrt(disc_area))
    expected = theory.elliptic_punch_stiffness(math.sqrt(aspect), 1 / math.sqrt(aspect), 1.0) / 2
    assert measured == pytest.approx(expected, rel=1.5e-3), (measured, expected)


@pytest.mark.parametrize("aspect,orientation", _ELLIPSES)
def test_elliptic_punch_lets_go_from_its_major_axis_ends(elliptic_punches, aspect,
                                                         orientation):
    """Galin's edge field puts the largest energy release rate at the ends
    of the major axis, where the punch starts to let go at
    `theory.elliptic_punch_initiation_force`, (b/a)^(1/4) of the equal-area
    Kendall force (0.841 for aspect 2, 0.760 for 3; the minor axis's ends
    would give (a/b)^(1/4), above Kendall's).  Then the contact shrinks
    from the ends and the force still rises to F_ad.

    Measured at a0 = 30 elements: the first elements to go lie within
    0.03 a of the major axis's ends (a the semi-major axis) and 0.08 a off
    it; the force then lies within 10 % of the formula: 2.8-8.5 % above
    it on this grid (1.0555, 1.0275, 1.0845, 1.0773), -3.5 to +6.3 % at
    a0 = 40 (a review helper's run): the element pattern at the tip, whose radius of
    curvature b^2/a is 10.6 elements for aspect 2 and 5.8 for 3 at a0 = 30,
    scatters it either way (aspect 2 unrotated: 0.8876, 0.8468, 0.8672 at
    a0 = 30, 40, 60 against 0.8409).  F_ad is 2.7-6.5 % above that force
    here (18 % for aspect 3 at 30 degrees on a0 = 40).
    """
    ds = elliptic_punches[aspect, orientation]
    step = ds.detachment_step.values
    rows, cols = np.nonzero(step >= 0)
    first = step[rows, cols] == step[rows, cols].min()
    a, b = _semi_axes(ds, aspect)
    turn = math.radians(orientation)
    dy, dx = rows - rows.mean(), cols - cols.mean()
    along = (dx * math.cos(turn) + dy * math.sin(turn))[first]
    across = (dy * math.cos(turn) - dx * math.sin(turn))[first]
    assert np.all(np.abs(along) > 0.95 * a), along / a
    assert np.all(np.abs(across) < 0.1 * a), across / a
    force = ds.force_normalized.values
    area = ds.contact_area.values
    at_first = force[int(np.argmax(area < area[0])) - 1]  # the last row in full contact
    # over Kendall's force of the disc of equal area, radius sqrt(a b)
    expected = theory.elliptic_punch_initiation_force(a, b, 1.0, 1.0) / theory.kendall_force(
        math.sqrt(a * b), 1.0, 1.0)
    assert expected == pytest.approx(aspect ** -0.25, rel=1e-12)
    assert 0.9 < at_first / expected < 1.1, (at_first, expected)
    assert float(ds.adhesive_force_normalized) > 1.01 * at_first


# -- command line and curve file -----------------------------------------------------

def test_cli_runs_shapes_and_file_layouts_and_records_them(tmp_path):
    from brushcore.cli import main
    from brushcore.data.io import read_curve

    out = tmp_path / "hex.nc"
    assert main(["simulate", "--layout", "hexagonal", "--pillars", "12", "--kbar", "0.1",
                 "--grid", "96", "--shape", "ellipse", "--aspect", "2", "--orientation", "30",
                 "--out", str(out), "--quiet"]) == 0
    ds = read_curve(out)
    assert (ds.attrs["shape"], ds.attrs["aspect"], ds.attrs["orientation"]) == ("ellipse", 2, 30)
    assert (ds.attrs["lattice_rows"], ds.attrs["lattice_columns"]) == (4, 3)
    # 4 x 3: 3.5 pitches wide, 3 sqrt(3)/2 + 1 = 3.60 high
    height = 1.5 * math.sqrt(3) + 1
    assert ds.attrs["lattice_fill"] == pytest.approx(12 * math.sqrt(3) / 2 / height**2)
    assert ds.attrs["n_pillars_realised"] == 12 and ds.attrs["layout_file"] == ""
    path = save_label_map(build_labels(_ellipse_brush()), tmp_path / "m.npy")
    out_file = tmp_path / "file.nc"
    assert main(["simulate", "--layout", "file", "--layout-file", str(path), "--kbar", "0.05",
                 "--out", str(out_file), "--quiet"]) == 0
    ds = read_curve(out_file)
    assert ds.attrs["layout"] == "file" and ds.attrs["n_pillars"] == 12
    assert ds.attrs["layout_file"] == str(path) and len(ds.attrs["layout_file_sha256"]) == 64


@pytest.mark.parametrize("extra, message", [
    (["--layout", "file"], "--layout-file is required for --layout file"),
    (["--layout", "file", "--layout-file", "LABELS", "--pillars", "11"],
     "--pillars 11 is invalid: allowed 12"),
    (["--layout", "file", "--layout-file", "TOUCH"], r"--layout-file .*t\.npy is invalid "
                                                     r"\(pillars 0 and 1 at element.*allowed pillars "
                                                     r"at least one element apart"),
    # the flag replaces a parameter's name, not the same word in prose
    (["--layout", "file", "--layout-file", "LABELS", "--shape", "square"],
     "--shape square is invalid: allowed the default 'disc' with --layout 'file'"),
    # the file's own size fails the grid rule: the file is blamed, not a --grid never typed
    (["--layout", "file", "--layout-file", "TINY"], r"--layout-file .*s\.npy is invalid \(it is "
                                                    r"32 x 32 elements: .*a map of side >= \d+"),
    (["--layout", "hexagonal", "--pillars", "7", "--grid", "128"], "--pillars 7 .*6 or 9"),
    (["--layout", "regular", "--pillars", "16", "--grid", "128", "--aspect", "2"],
     "--aspect 2.0 is invalid: allowed 1 unless --shape is 'ellipse'"),
    (["--layout", "regular", "--grid", "64"], "--pillars is required for --layout regular"),
    (["--layout", "random"], "--pillars and --grid are required for --layout random"),
])
def test_cli_refuses_bad_geometry_and_writes_nothing(tmp_path, capsys, extra, message):
    from brushcore.cli import main

    labels = build_labels(_ellipse_brush())
    touch = np.full((32, 32), -1)
    touch[2:6, 2:6], touch[6:9, 2:6] = 0, 1
    tiny = np.full((32, 32), -1)
    tiny[1::8, 1::8] = np.arange(16).reshape(4, 4)  # one-element pillars
    files = {"LABELS": str(save_label_map(labels, tmp_path / "m.npy")),
             "TOUCH": str(tmp_path / "t.npy"),  # np.save: save_label_map refuses it
             "TINY": str(save_label_map(tiny, tmp_path / "s.npy"))}
    np.save(files["TOUCH"], touch.astype(np.int32))
    out = tmp_path / "never.nc"
    argv = ["simulate", "--kbar", "0.1", "--out", str(out), "--quiet"]
    argv += [files.get(a, a) for a in extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert "Traceback" not in err and "n_pillars" not in err and not out.exists()
