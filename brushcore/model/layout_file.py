"""Layouts read from a file: an integer label map (.npy) or an image (.png),
which fit one grid, or a table of disc and ellipse pillars (.csv,
`pillar_table`), drawn on any grid.

Files come from other people's tools, so they are read as data, never as
code, and refused with the file named when they do not fit:

- ``.npy``: an n x n integer array, -1 = no pillar, 0 ... N-1 = pillar
  index; read with ``np.load(allow_pickle=False)``.  Every index 0 ... N-1
  must cover at least one element; any other negative value is refused.
  A pillar may be any set of elements (it moves as one body on its
  spring).
- ``.png``: an n x n image, at most MAX_IMAGE_PIXELS pixels (checked from
  the header before decoding), read with matplotlib's reader.  A pixel is
  pillar when it is darker than 50 % grey and not transparent (alpha >=
  0.5): black pillars on white, as a thresholded micrograph or a drawn
  mask.  Pillars are the 8-connected components of pillar pixels
  (`scipy.ndimage.label`), numbered in raster order of the grid.  The
  image is read as it is shown: its top row is the grid's last row (the
  snapshots are drawn with y up), so a file layout looks like its image.

In both, pillars must not touch: two different pillars sharing an element
edge (4-neighbour adjacency) are refused, naming the pillars and the
element.  A shared corner is allowed in a label map (its labels say which
pillar is which); in an image a corner joins two blobs into one pillar, as
8-connected labelling does, so an image never has touching pillars, and a
warning says how many blobs corners joined (brushcore's own random layouts
have corner contacts: saved as an image, random 64 on 256^2 reads back as
61 pillars).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from brushcore.model.params import MAX_GRID, MAX_PHI, BrushParams

from brushcore.model.labelmap import check_not_touching, pillar_element_counts
from brushcore.model.inputs import npy_problem
from brushcore.model.pillar_table import is_table, read_pillar_table
from brushcore.validation import ParameterError

#: Largest image accepted (the largest grid, 8192^2), checked before decoding.
MAX_IMAGE_PIXELS = MAX_GRID**2
SUFFIXES = (".npy", ".png")
#: A phi given with a file must be the file's to this relative tolerance.
FILE_PHI_RTOL = 1e-9
_NAME = "layout_file"


#: What an image's refusal adds where the pixels' reading may be the cause.
IMAGE_RULE = ("an image pixel is pillar when darker than 50 % grey and at least half "
              "opaque: black pillars on white")


def _refuse(path: Path, allowed: str, reason: str, image_rule: bool = False) -> ParameterError:
    """The refusal of a layout file; ``image_rule`` adds how an image's pixels are
    read, for refusals (no pillar, too much pillar) that a misread image causes."""
    if image_rule and path.suffix.lower() == ".png":
        reason = f"{reason}; {IMAGE_RULE}"
    return ParameterError(_NAME, str(path), allowed, reason)


def _read_npy(path: Path) -> np.ndarray:
    size = path.stat().st_size
    if size > 8 * MAX_IMAGE_PIXELS + 65536:  # int64 at the largest grid, plus the header
        raise _refuse(path, f"a label map of at most {MAX_IMAGE_PIXELS} elements",
                      f"the file has {size} bytes")
    try:
        data = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise _refuse(path, "a .npy file of an n x n integer array",
                      f"not readable as a plain .npy array: {npy_problem(exc)}") from None
    if not isinstance(data, np.ndarray) or data.dtype.kind not in "iu":
        kind = getattr(data, "dtype", type(data).__name__)
        raise _refuse(path, "an integer label map (-1 = no pillar, 0 ... N-1 = pillar)",
                      f"holds {kind} values")
    if data.ndim != 2:
        raise _refuse(path, "a two-dimensional n x n label map",
                      f"has shape {data.shape}")
    bad = np.argwhere(data < -1)
    if bad.size:
        r, c = (int(v) for v in bad[0])
        raise _refuse(path, "labels -1 (no pillar) or 0 ... N-1",
                      f"element (row {r}, column {c}) holds {int(data[r, c])}"
                      + (f" and {len(bad) - 1} more elements hold values < -1"
                         if len(bad) > 1 else ""))
    if data.size and int(data.max()) >= 2**31 - 1:
        raise _refuse(path, "labels 0 ... N-1 with N < 2^31 - 1", "a label is too large")
    return data.astype(np.int32)


def _read_png(path: Path) -> np.ndarray:
    from matplotlib import image as mpimg  # noqa: PLC0415 - only for images
    from PIL import Image  # matplotlib's own image dependency
    from scipy import ndimage

    try:
        with Image.open(path) as im:  # header only: size before decoding
            width, height = im.size
    except Image.DecompressionBombError:
        raise _refuse(path, f"an image of at most {MAX_IMAGE_PIXELS} pixels",
                      "larger than Pillow's decompression-bomb limit") from None
    except OSError as exc:
        raise _refuse(path, "a PNG image", f"not readable as an image: {exc}") from None
    if width * height > MAX_IMAGE_PIXELS:
        raise _refuse(path, f"an image of at most {MAX_IMAGE_PIXELS} pixels",
                      f"is {width} x {height} pixels")
    try:
        pixels = np.asarray(mpimg.imread(path), dtype=float)
    except (OSError, SyntaxError, ValueError) as exc:  # truncated, or another format
        raise _refuse(path, "a PNG image", f"not decodable as one: {exc}") from None
    if pixels.ndim == 3:
        alpha = pixels[..., 3] if pixels.shape[2] == 4 else np.ones(pixels.shape[:2])
        grey = pixels[..., :3].mean(axis=2) if pixels.shape[2] >= 3 else pixels[..., 0]
    else:
        alpha, grey = np.ones_like(pixels), pixels
    if grey.max() > 1.0:  # integer-valued image from Pillow: 8 or 16 bit
        grey = grey / (65535.0 if grey.max() > 255 else 255.0)
    pillar = (grey < 0.5) & (alpha >= 0.5)
    # Top image row = largest y; 8-connected: a corner contact is one pillar.
    blobs, count = ndimage.label(pillar[::-1], structure=np.ones((3, 3), dtype=int))
    _, pieces = ndimage.label(pillar)  # 4-connected
    if pieces > count:  # said, not silent: a label map keeps such pillars apart
        warnings.warn(f"{path}: corners join {pieces} edge-connected blobs into {count} "
                      f"pillar{'s' * (count != 1)} (pixels that touch only at a corner are "
                      "one pillar in an image); give the layout as a .npy label map if they "
                      "are separate pillars", stacklevel=2)  # one location: said once a run
    return (blobs - 1).astype(np.int32)


def read_label_map(path: str | Path, grid: int | None = None) -> np.ndarray:
    """The checked label map of a layout file, shape (n, n), int32, -1 outside pillars.

    Parameters
    ----------
    path : a ``.npy`` label map or a ``.png`` image (see the module notes)
    grid : required n (elements per side); None accepts any square map

    Raises
    ------
    ParameterError
        For ``layout_file``, naming the file and what does not fit: a
        missing or unreadable file, other suffixes, non-integer data,
        labels that are not -1 or 0 ... N-1 (the missing indices named), a
        shape other than grid x grid, no pillar at all, pillars that touch
        (pillar indices and element named).
    """
    path = Path(path)
    if path.is_dir():  # before the suffix, which a folder's name need not have
        raise _refuse(path, "an existing, readable file", "a folder")
    if path.suffix.lower() not in SUFFIXES:
        raise _refuse(path, f"a file ending in {' or '.join(SUFFIXES)}",
                      f"unknown kind {path.suffix or '(no suffix)'!r}")
    if not path.is_file():
        raise _refuse(path, "an existing, readable file", "no such file")
    labels = _read_npy(path) if path.suffix.lower() == ".npy" else _read_png(path)
    unit = "elements" if path.suffix.lower() == ".npy" else "pixels"
    if labels.ndim != 2 or labels.shape[0] != labels.shape[1]:
        raise _refuse(path, "a square n x n map", f"is {labels.shape[0]} x "
                      f"{labels.shape[1]} {unit} (rows x columns)")
    if grid is not None and labels.shape[0] != grid:
        raise _refuse(path, f"a {grid} x {grid} map (the grid)",
                      f"is {labels.shape[0]} x {labels.shape[1]} {unit}")
    present = np.unique(labels[labels >= 0])
    if present.size == 0:
        raise _refuse(path, "a map with at least one pillar", "no pillar element",
                      image_rule=True)
    counts = pillar_element_counts(labels)
    if counts.max() > labels.size * MAX_PHI:  # no pillar covers more than phi may
        big = int(counts.argmax())
        share = f"{counts[big] / labels.size:.3g}"
        if path.suffix.lower() == ".png":
            raise _refuse(path, "pillars covering at most half the image",
                          f"one pillar covers {share} of it (white pillars on black?)",
                          image_rule=True)
        raise _refuse(path, "-1 for no pillar and 0 ... N-1 for the pillars",
                      f"label {big} covers {share} of the map: is {big} the background?"
                      + (" (scipy.ndimage.label and scikit-image write 0)" if big == 0 else ""))
    n_pillars = int(present[-1]) + 1
    if present.size != n_pillars:
        missing = np.setdiff1d(np.arange(n_pillars), present)
        shown = ", ".join(str(int(m)) for m in missing[:10])
        raise _refuse(path, "pillar labels 0 ... N-1 each on at least one element",
                      f"labels up to {n_pillars - 1}, but no element has label {shown}"
                      + (f" and {missing.size - 10} more" if missing.size > 10 else ""))
    check_not_touching(labels, _NAME, str(path))
    # once a file version: a run reads its map several times (0.6 s at 2048^2);
    # an image's pillars are its 8-connected blobs, whose corners `_read_png` says
    said = (str(path.resolve()), path.stat().st_mtime_ns)
    if unit == "elements" and said not in _SPLIT_CHECKED:
        _SPLIT_CHECKED.add(said)
        _warn_split(path, split_pillars(labels))
    return labels


def _warn_split(path: Path, split: np.ndarray) -> None:
    """Say which labels of a map cover separate pieces (one spring on two
    footprints: meant, perhaps, but likely not)."""
    if not split.size:
        return
    shown = ", ".join(map(str, split[:5])) + " ..." * (split.size > 5)
    warnings.warn(f"{path}: " + (f"label {shown} covers" if split.size == 1 else
                                 f"{split.size} labels ({shown}) each cover")
                  + " pieces that share no element edge; such a label runs as one pillar, "
                  "one spring on all its pieces: give each piece its own label otherwise",
                  stacklevel=3)


#: Label maps checked for split pillars, by (path, mtime).
_SPLIT_CHECKED: set[tuple[str, int]] = set()


def split_pillars(labels: np.ndarray) -> np.ndarray:
    """Pillar labels whose elements form more than one edge-connected piece."""
    from scipy.sparse import coo_matrix  # noqa: PLC0415 - label maps only
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    index = np.full(labels.shape, -1, dtype=np.int64)
    inside = labels >= 0
    index[inside] = np.arange(int(inside.sum()))
    # edges between edge neighbours of one label: (index left/up, right/down, same)
    edges = [(index[:, :-1], index[:, 1:], labels[:, :-1] == labels[:, 1:]),
             (index[:-1], index[1:], labels[:-1] == labels[1:])]
    rows = np.concatenate([a[same & (a >= 0)] for a, _, same in edges])
    cols = np.concatenate([b[same & (a >= 0)] for a, b, same in edges])
    size = int(inside.sum())
    graph = coo_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), shape=(size, size))
    count, piece = connected_components(graph, directed=False)
    n_pillars = int(labels.max()) + 1
    if count == np.unique(labels[inside]).size:  # a piece a label
        return np.zeros(0, dtype=np.int64)
    # distinct (label, piece) pairs, counted per label
    pieces = np.bincount(np.unique(labels[inside].astype(np.int64) * count + piece) // count,
                         minlength=n_pillars)
    return np.flatnonzero(pieces > 1)


def save_label_map(labels: np.ndarray, path: str | Path) -> Path:
    """Write a label map as ``.npy`` (int32), readable by `read_label_map`.

    Returns
    -------
    The path written (``.npy`` appended when missing, as numpy does).

    Raises
    ------
    ParameterError
        For ``labels`` whose pillars share an element edge, which
        `read_label_map` would refuse (a random layout drawn on a grid
        coarser than 512 can part two discs by less than an element).
    """
    try:
        check_not_touching(labels, "labels", "the map")
    except ParameterError as exc:
        raise ParameterError("labels", "the map", exc.allowed + ", as read_label_map reads "
                             "maps (a random layout drawn on a grid coarser than 512 can put "
                             "two pillars closer than an element: draw it on a finer grid)",
                             exc.reason) from None
    path = Path(path)
    if path.suffix != ".npy":
        path = path.with_name(path.name + ".npy")
    np.save(path, np.ascontiguousarray(labels, dtype=np.int32), allow_pickle=False)
    return path


def describe(labels: np.ndarray, h: float = 1.0) -> dict[str, float | int]:
    """Pillar count, realised filling factor and mean equal-area radius of a label map.

    Returns
    -------
    dict with n_pillars, grid, phi (pillar area / L^2) and
    equivalent_radius (sqrt(mean pillar area / pi)) [length].
    """
    n_pillars = int(labels.max()) + 1
    area = int(np.count_nonzero(labels >= 0))
    return {"n_pillars": n_pillars, "grid": int(labels.shape[0]),
            "phi": area / labels.size,
            "equivalent_radius": float(np.sqrt(area / n_pillars / np.pi)) * h}


#: What a file brush's layout name starts with (`file_layout`).
FILE_LAYOUT_PREFIX = "file_"


def file_layout(path: str | Path) -> str:
    """A file brush's name in sweep.nc and the workflow's curve names: "file_" +
    the file's name without its suffix ("file_my_array" for arrays/my_array.npy)."""
    return FILE_LAYOUT_PREFIX + Path(path).stem


def pillar_shapes(path: str | Path) -> str:
    """What a file brush's pillars are, in words, for its curve (whose
    ``shape`` parameter stays "disc", the file's own shapes aside): "discs",
    "ellipses" or "discs and ellipses" for a table, "as drawn" for a label
    map or image."""
    if not is_table(path):
        return "as drawn"
    table = read_pillar_table(path)
    if not table.has_ellipses:
        return "discs"
    return "ellipses" if bool(np.all(table.aspects != 1.0)) else "discs and ellipses"


def curve_layout(attrs: Mapping[str, object]) -> str:
    """The layout a curve's attributes name, a file's brush by its file
    (`file_layout`), as sweep.nc and the workflow name it."""
    layout = str(attrs["layout"])
    return file_layout(str(attrs.get("layout_file", ""))) if layout == "file" else layout


def file_params(path: str | Path, kbar: float, **kwargs) -> BrushParams:
    """Parameters of a file layout: N, grid and phi taken from the file.

    Parameters
    ----------
    path : the ``.npy`` label map or ``.png`` image, or a ``.csv`` pillar
        table (`brushcore.model.pillar_table`), which needs ``grid``
    kbar : normalised spring stiffness k / (E* L)
    **kwargs : any other `BrushParams` field (e_star, dgamma, h, ...);
        n_pillars, grid or phi, if given, must equal the file's (a table
        fits every grid; its phi is pi sum r^2)

    Raises
    ------
    ParameterError
        If the file is refused (see `read_label_map`, `read_pillar_table`),
        a given n_pillars, grid or phi differs from the file's, or a table
        comes without a grid.
    """
    if "layout" in kwargs:  # it is "file": a keyword twice, said in Python's words
        raise ParameterError("layout", kwargs["layout"], "none beside file_params, which "
                             "makes the file's layout")
    if is_table(path):
        return _table_params(path, kbar, kwargs)
    if not Path(path).is_dir() and Path(path).suffix.lower() not in SUFFIXES:
        raise _refuse(Path(path), f"a label map ({' or '.join(SUFFIXES)}) or a pillar table "
                      "(.csv)", f"unknown kind {Path(path).suffix or '(no suffix)'!r}")
    labels = read_label_map(path)  # a grid that differs is the grid's error, named below
    found = describe(labels)
    check_file_values(path, kwargs, found)
    typed = {name for name in ("n_pillars", "grid", "phi") if name in kwargs}
    kwargs.update(n_pillars=found["n_pillars"], grid=found["grid"], phi=found["phi"])
    try:
        return BrushParams(layout="file", kbar=kbar, layout_file=str(path), **kwargs)
    except ParameterError as exc:
        if exc.name not in ("n_pillars", "grid", "phi") or exc.name in typed:
            raise
        # The file's own N, grid or phi fails a check: the file is what to
        # change, in words that are not flags the user did not type.
        found_as = {"n_pillars": f"it holds {exc.value} pillars",
                    "grid": f"it is {exc.value} x {exc.value} elements",
                    "phi": f"its pillars cover {exc.value:.4g} of it"}[exc.name]
        # A larger map helps only if its pillars grow with it: say so (a
        # one-pixel pillar padded into a larger map stays one pixel).
        allowed = (exc.allowed.replace("grid >=", "the layout drawn finer, its pillars scaled "
                                       "with it: a map of side >=") if exc.name == "grid"
                   else f"a filling factor in (0, {MAX_PHI:g}]" if exc.name == "phi"
                   else exc.allowed)
        raise _refuse(path, allowed, found_as + (f": {exc.reason}" if exc.reason else ""),
                      image_rule=exc.name == "phi") from None


def check_file_values(path: str | Path, given: Mapping[str, object],
                      found: Mapping[str, object], phi_meaning: str = "") -> None:
    """The N, grid and phi ``given`` (those of ``found``'s names among them)
    must be the file's ``found`` ones, phi within `FILE_PHI_RTOL`.

    Raises
    ------
    ParameterError
        Naming the parameter and the file's value (and ``phi_meaning``, how
        the file's phi is reckoned, where given).
    """
    for name in ("n_pillars", "grid", "phi"):
        if given.get(name) is None or name not in found:
            continue  # not given (None: as not given; BrushParams names a None it gets)
        value, own = given[name], found[name]
        differs = abs(value / own - 1.0) > FILE_PHI_RTOL if name == "phi" else value != own
        if differs:
            raise ParameterError(name, value, f"{own!r}, the value of {path}" + (
                f" ({phi_meaning})" if name == "phi" and phi_meaning else ""))


def _table_params(path: str | Path, kbar: float, kwargs: dict) -> BrushParams:
    """`file_params` of a pillar table: N and phi from the table, the grid given."""
    table = read_pillar_table(path)
    if kwargs.get("grid") is None:
        raise ParameterError("grid", None, "the grid to draw the table on (elements per "
                             "side: a pillar table fits any grid)", f"{path} is a pillar table")
    check_file_values(path, kwargs, {"n_pillars": table.n_pillars, "phi": table.phi},
                      "pi sum r^2")
    # a phi given (the workflow's, from the plan) is kept: a job on another
    # machine, whose sum might round otherwise, then names the plan's case
    kwargs.update(n_pillars=table.n_pillars, phi=kwargs.get("phi", table.phi))
    return BrushParams(layout="file", kbar=kbar, layout_file=str(path), **kwargs)
