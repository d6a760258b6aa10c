"""Curve files: atomic netCDF writing and validated reading."""

from __future__ import annotations

import errno
import hashlib
import math
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np
import xarray as xr

from brushcore.model.curve_format import FILL_DTYPES, FILL_VALUES, fill_value
from brushcore.validation import ParameterError

#: Variables and attributes a curve file must have to be aggregated.
REQUIRED_VARS = ("displacement", "force", "contact_area", "attached_pillars",
                 "adhesive_force", "adhesive_force_normalized", "work_of_separation",
                 "work_of_separation_normalized")
REQUIRED_ATTRS = ("layout", "n_pillars", "kbar", "grid", "phi", "seed",
                  "operator_applications", "brushcore_version", "parameter_hash")
#: Results of a pull-off: NaN in a protocol's file that never retracts
#: (its `retraction` flag 0 on every step) or never pulls in tension,
#: finite everywhere else.
PULL_OFF_VARS = REQUIRED_VARS[4:]
#: Attribute holding the SHA-256 of the file's values and attributes (see `content_digest`).
DIGEST_ATTR = "content_sha256"


class CurveFileError(ValueError):
    """A curve file is missing, truncated, corrupt or not a brushcore curve.

    ``not_a_curve`` is True where the file never was one (a sweep, a table,
    another netCDF file, a folder): running its simulation again cannot
    bring it back, so advice differs from a damaged curve's.
    """

    def __init__(self, message: str, not_a_curve: bool = False) -> None:
        super().__init__(message)
        self.not_a_curve = not_a_curve


def _encoding(ds: xr.Dataset) -> dict:
    enc: dict[str, dict] = {name: {"_FillValue": None} for name in ds.coords}  # CF: none
    for name, v in ds.data_vars.items():
        if name in FILL_VALUES:  # "none" as its fill (`brushcore.model.curve_format.FILL_VALUES`)
            enc[name] = {"_FillValue": fill_value(name, v.dtype)}
        if v.ndim >= 2:  # maps and snapshots compress ~50x
            enc[name] = {**enc.get(name, {}), "zlib": True, "complevel": 4}
    return enc


def content_digest(ds: xr.Dataset) -> str:
    """SHA-256 of every variable's values and every attribute but the digest itself.

    netCDF/HDF5 keep no checksum of contiguous data, so a flipped byte in a
    curve reads back as a different number without any error; `write_curve`
    stores this digest and `read_curve` recomputes it.  Values are hashed as
    written and read back (strings by their text, attributes as flat lists),
    so the digest survives the netCDF round trip exactly.
    """
    h = hashlib.sha256()
    for name in sorted(map(str, ds.variables)):
        values = np.asarray(ds[name].values)
        h.update(f"{name}|{values.shape}|{values.dtype.kind}|".encode())
        if values.dtype.kind in "OUS":
            h.update("\x00".join(map(str, values.ravel().tolist())).encode())
        else:
            h.update(np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).tobytes())
    for key in sorted(k for k in ds.attrs if k != DIGEST_ATTR):
        h.update(f"{key}={np.ravel(np.asarray(ds.attrs[key])).tolist()!r}|".encode())
    return h.hexdigest()


def _umask() -> int:
    """The process umask, read without changing it where the OS allows."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)  # elsewhere: set and restore (not thread-safe, done once a file)
    os.umask(mask)
    return mask


def check_output_path(path: str | os.PathLike) -> Path:
    """Check, before any work, that a file can be written at ``path``.

    The path must not be a folder, and its nearest existing ancestor must be
    a folder in which a file can actually be created (a test file is
    created and removed there; nothing else is left behind, missing
    folders are not created yet).

    Raises
    ------
    ParameterError
        Named ``out``, saying what is wrong with the path.
    """
    text = os.fspath(path)
    path = Path(path)

    def refuse(reason: str) -> ParameterError:
        return ParameterError("out", text, "a file path in a writable folder "
                              "(missing folders are created)", reason)

    if path.is_dir():
        raise refuse("it is a folder")
    if path.exists() and not path.is_file():  # a device or a pipe: the rename would replace it
        raise refuse("it exists and is not a regular file")
    if text.endswith((os.sep, "/")):  # Path() would drop the slash and write a file there
        raise refuse("it names a folder (ends with a separator)")
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise refuse(f"{ancestor} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=ancestor):
            pass
    except OSError as exc:
        raise refuse(f"cannot create a file in {ancestor}: {exc.strerror}") from None
    return path


def publish(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """Give a finished temporary file the umask's mode, flush it and rename it to ``path``.

    Temporary files are created owner-only (0600); the published file gets
    0666 & ~umask like any file a tool writes.
    """
    os.chmod(tmp, 0o666 & ~_umask())
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)


#: Seconds a temporary must lie untouched before a later writer of the same
#: output removes it: a live writer writes a sweep in seconds.
STALE_AFTER_S = 600.0


def write_atomic(path: str | os.PathLike, write: Callable[[str], None],
                 nbytes: int = 0) -> Path:
    """``write(tmp)`` a file under a unique temporary name, then `publish` it as ``path``.

    The temporary file lies in the same directory and is flushed before the
    rename: a killed writer leaves the old file (or none) and at most a
    ``.{name}.*.tmp``, never half a file; a later write of ``path`` removes
    such leftovers untouched for STALE_AFTER_S (`remove_stale_temporaries`;
    one touched since may belong to a writer still at work).  ``nbytes``
    (what is written, about) names a full disk as such.
    """
    path = Path(path)
    started = time.time()
    if path.is_dir():  # else a rename error naming the temporary, after the writing
        raise IsADirectoryError(errno.EISDIR, "a folder, not a file name: give a file "
                                f"in it, {path / 'NAME'}", str(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:  # name the path asked for, not the temporary beside it
        raise type(exc)(exc.errno, f"{exc.strerror}: no file can be written in "
                                   f"{path.parent}", str(path)) from None
    os.close(fd)
    try:
        write(tmp)
        publish(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, (OSError, RuntimeError)):  # not Ctrl-C, SIGTERM or a bug
            try:
                free = shutil.disk_usage(path.parent).free
            except OSError:
                raise exc from None
            if free < nbytes:  # netCDF says only "HDF error" when the disk is full
                raise OSError(errno.ENOSPC, f"{free} bytes free on its disk, the data take "
                                            f"up to {nbytes}", str(path)) from exc
        raise
    remove_stale_temporaries(path, older_than=started - STALE_AFTER_S)
    return path


def write_dataset_atomic(ds: xr.Dataset, path: str | os.PathLike, encoding: dict) -> Path:
    """Write a Dataset to netCDF4 atomically (`write_atomic`)."""
    return write_atomic(path, lambda tmp: ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4",
                                                       encoding=encoding), ds.nbytes)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write a text file (a table) atomically (`write_atomic`)."""
    # UTF-8 and the text's own line ends (a CSV's \r\n stays so on any system)
    return write_atomic(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8",
                                                               newline=""),
                        len(text.encode()))


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A GitHub-flavoured Markdown table of text cells, one line a row (a cell's
    own '|' escaped)."""
    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"

    lines = [line(header), "|" + "---|" * len(header), *map(line, rows)]
    return "\n".join(lines) + "\n"


def as_simulated(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with the `FILL_VALUES` variables as `simulate` makes them: numbers
    of their `FILL_DTYPES`, the fill in the encoding.  `xr.open_dataset` reads
    them as floats with NaN at the fill; ``mask_and_scale=False`` keeps the
    numbers but puts _FillValue among the attributes (which netCDF's writer
    refuses beside the encoding's); an operation that drops the encoding
    leaves contact maps int32.  Each is undone, so that a curve so read is
    written and aggregated as the one `simulate` returned, digest included.
    Changes ``ds`` in place; give a shallow copy to keep the caller's."""
    for name, fill in FILL_VALUES.items():
        var = ds.variables.get(name)
        if var is None:
            continue
        dtype = np.dtype(FILL_DTYPES[name])
        values = var.values
        if values.dtype.kind == "f":
            values = np.where(np.isnan(values), fill, values)
        attrs = {k: v for k, v in var.attrs.items() if k != "_FillValue"}
        ds[name] = xr.Variable(var.dims, values.astype(dtype), attrs,
                               {"_FillValue": fill_value(name, dtype)})
    return ds


def write_curve(ds: xr.Dataset, path: str | os.PathLike) -> Path:
    """Write a curve Dataset to netCDF4 atomically, with its content digest.

    See `write_dataset_atomic`: a killed job leaves either no file or a
    complete one, never half of one.

    Parameters
    ----------
    ds : a curve as `brushcore.simulate` returns it (or as read back with
        xarray: fills and map dtypes are made the simulated ones first).
    path : the file to write [.nc]; a missing folder is made.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    if not isinstance(ds, xr.Dataset):
        raise ParameterError("ds", type(ds).__name__, "a curve Dataset (brushcore.simulate's)")
    ds = as_simulated(ds.copy(deep=False))  # the caller's attrs stay as they were
    ds.attrs[DIGEST_ATTR] = content_digest(ds)
    return write_dataset_atomic(ds, path, _encoding(ds))


def remove_stale_temporaries(path: str | os.PathLike, older_than: float | None = None) -> int:
    """Delete temporary files that a killed `write_curve` left for ``path``.

    Safe when one writer owns ``path`` (one Snakemake job per output).
    ``older_than`` (seconds since the epoch) spares temporaries last written
    at or after it, which a writer started since may still own (the command
    line, where nothing guarantees one writer). Returns the number removed.
    """
    path = Path(path)
    stale = [tmp for tmp in path.parent.glob(f".{path.name}.*.tmp")
             if older_than is None or _mtime(tmp) < older_than]
    for tmp in stale:
        tmp.unlink(missing_ok=True)
    return len(stale)


def _mtime(path: Path) -> float:
    """Last modification time [s since the epoch], +inf for a file gone meanwhile."""
    try:
        return path.stat().st_mtime
    except FileNotFoundError:
        return math.inf


def read_curve(path: str | os.PathLike) -> xr.Dataset:
    """Load a curve file fully into memory and check that it is a complete curve.

    Parameters
    ----------
    path : a curve file written by `write_curve` or the workflow.

    Returns
    -------
    xarray.Dataset
        The curve, detached from the file (which may be moved or rewritten).

    Raises
    ------
    CurveFileError
        Naming the file, when it cannot be opened, lacks a variable or
        attribute of a curve, holds non-finite values, or its values differ
        from the digest `write_curve` stored (files without one are older
        and are accepted unchecked).
    """
    path = Path(path)
    if not path.exists():
        raise CurveFileError(f"{path}: no such file")
    if path.is_dir():
        raise CurveFileError(f"{path}: a folder, not a curve file", not_a_curve=True)
    try:
        # The "none" of FILL_VALUES stays a number, as in memory (xarray's
        # default reads it as NaN, and the values as floats).
        with xr.open_dataset(path, engine="netcdf4",
                             mask_and_scale={name: False for name in FILL_VALUES}) as ds:
            ds = ds.load()
    except Exception as exc:  # netCDF4 raises OSError, RuntimeError, ValueError...
        # a table or image given by mistake was never a curve; a .nc that does not
        # open may be one cut short
        raise CurveFileError(f"{path}: cannot be read as a netCDF curve file ({exc})",
                             not_a_curve=path.suffix.lower() != ".nc") from exc
    for name in FILL_VALUES:  # as written: the fill an encoding, not an attribute
        if name in ds.variables and "_FillValue" in ds[name].attrs:
            ds[name].encoding["_FillValue"] = ds[name].attrs.pop("_FillValue")
    check_curve(ds, str(path))
    return ds


def check_curve(ds: xr.Dataset, label: str, digest: bool = True) -> None:
    """Check that ``ds`` (a file's, or a curve in memory, called ``label``) is
    a complete curve: `read_curve`'s checks but the opening; ``digest``
    False leaves out the stored digest (a curve in memory may have been
    changed on purpose since it was read).

    Raises
    ------
    CurveFileError
        Naming it, as `read_curve`.
    """
    missing = [v for v in REQUIRED_VARS if v not in ds.variables]
    missing += [f"attribute {a}" for a in REQUIRED_ATTRS if a not in ds.attrs]
    if missing:
        title = str(ds.attrs.get("title", ""))
        if title.startswith("brushcore"):  # a sweep or a study: what it is, and how to read it
            raise CurveFileError(f"{label}: a {title.split(':')[0]} file, not a curve file (open "
                                 "it with xarray.open_dataset)", not_a_curve=True)
        # one with a curve's parameter hash is a curve damaged (an attribute lost)
        raise CurveFileError(f"{label}: not a brushcore curve file, missing {', '.join(missing)}",
                             not_a_curve="parameter_hash" not in ds.attrs)
    stored = ds.attrs.get(DIGEST_ATTR) if digest else None
    if stored is not None and str(stored) != content_digest(ds):
        raise CurveFileError(f"{label}: changed since brushcore wrote it (edited, or corrupt): "
                             f"its values and attributes do not match the {DIGEST_ATTR} written "
                             "with them (xarray.open_dataset still reads it)")
    # A protocol that never retracts, or whose retraction stays compressive,
    # has no adhesive force (NaN) and may carry NaN in the other results.
    never_pulled = "retraction" in ds.variables and not (
        ds["force"].values[ds["retraction"].values.astype(bool)] > 0).any()
    for name in REQUIRED_VARS:
        if never_pulled and name in PULL_OFF_VARS:
            continue
        if not np.all(np.isfinite(ds[name].values)):
            raise CurveFileError(f"{label}: variable {name} holds NaN or inf")
