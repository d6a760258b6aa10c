"""Checking parameters at the edge: one error type and the checks every layer shares.

`ParameterError` names the parameter and the allowed range; the helpers
turn NumPy scalars into Python numbers and raise it.  Nothing here knows
the physics: `brushcore.model.params` and `brushcore.numerics.options`
hold the rules.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import inspect
import math
import numbers
import pickle
import re
from collections.abc import Mapping
from typing import TypeVar

import numpy as np


T = TypeVar("T")


class ParameterError(ValueError):
    """A parameter is outside its allowed range; the message names both.

    Attributes
    ----------
    name : the parameter's name in the Python API (``n_pillars``)
    value : the value given
    allowed : what would be accepted
    reason : why the value fails, where more than "out of range" (may be "")

    `in_terms_of` renders the same error in another vocabulary (the CLI's
    flags, the workflow's config keys), so that users read the name they
    typed.
    """

    def __init__(self, name: str, value: object, allowed: str, reason: str = "") -> None:
        self.name, self.value, self.allowed, self.reason = name, value, allowed, reason
        super().__init__(self.in_terms_of({}))

    def __reduce__(self) -> tuple:
        """Pickle by the constructor's arguments (ValueError's pickles the
        message alone, which ``__init__`` cannot take: a worker's refusal
        broke a ProcessPoolExecutor and hung multiprocessing.Pool.map), and
        the instance's other attributes as its state, as BaseException's
        own pickling does: ``add_note``'s ``__notes__`` (dropped before
        2026-12-07) and any set after construction.  A value that does not
        pickle travels as its repr."""
        value = self.value
        try:
            pickle.dumps(value)
        except Exception:  # noqa: BLE001 - whatever pickle refuses (a generator, a lock)
            value = repr(value)
        state = {**vars(self), "value": value}
        return type(self), (self.name, value, self.allowed, self.reason), state

    def in_terms_of(self, names: Mapping[str, str], sep: str = "=") -> str:
        """The message with ``name`` replaced by ``names[name]`` (if present)."""
        label = names.get(self.name, self.name)

        def translate(text: str) -> str:
            # A name with an underscore is always a parameter; a plain word
            # ("layout", "shape", "grid") only where a value or a verb
            # follows it, so that "an array of shape (5,)" stays prose.  A
            # quoted word is the user's own text (a table's column 'kbar').
            for api, user in names.items():
                after = "" if "_" in api else _REFERENCE
                text = re.sub(rf"(?<![\w'\"-]){re.escape(api)}(?![\w-]){after}", user, text)
            return text

        reason = f" ({translate(self.reason)})" if self.reason else ""
        value = self.value if isinstance(self.value, str) and sep != "=" else repr(self.value)
        return f"{label}{sep}{value} is invalid{reason}: allowed {translate(self.allowed)}"


#: What follows a plain-word parameter name where the text refers to the
#: parameter: a comparison, a quoted or numeric value, or "is"/"are"/"must".
_REFERENCE = r"(?=\s*(?:[=<>'\"]|\d|-\d|\b(?:is|are|must)\b))"


#: Keywords users try where they are set another way (`suggest_keywords`).
ELSEWHERE = {"threads": "threads are set for the process: "
                        "brushcore.numerics.platform.threads.pin_threads(n) (FFTW and BLAS), "
                        "or the BRUSHCORE_THREADS environment variable (FFTW's)"}


def suggest_keywords(target: T) -> T:
    """A function or class whose unknown keyword arguments are refused with
    the closest known one ("did you mean 'kbar'?"), as the command line
    names the closest flag; Python's own TypeError names none."""
    call = target.__init__ if isinstance(target, type) else target
    parameters = inspect.signature(call).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return target  # takes any keyword: nothing to refuse
    known = [name for name, p in parameters.items()
             if name != "self" and p.kind is not inspect.Parameter.POSITIONAL_ONLY]

    @functools.wraps(call)
    def checked(*args, **kwargs):
        for name in kwargs:
            if name not in known:
                close = difflib.get_close_matches(name, known, n=1)
                hint = (f"; did you mean {close[0]!r}?" if close else
                        f"; {ELSEWHERE[name]}" if name in ELSEWHERE else "")
                raise TypeError(f"{target.__qualname__}() got an unexpected keyword argument "
                                f"{name!r}{hint}")
        return call(*args, **kwargs)

    if isinstance(target, type):
        target.__init__ = checked
        return target
    return checked  # type: ignore[return-value]


def require(ok: bool, name: str, value: object, allowed: str, reason: str = "") -> None:
    """Raise `ParameterError(name, value, allowed, reason)` unless ``ok``.

    Every layer checks its inputs with it, so that each refusal reads
    "``name``=``value`` is invalid (``reason``): allowed ``allowed``" and
    the CLI and the workflow can translate ``name`` into the flag or config
    key the user typed (`ParameterError.in_terms_of`).
    """
    if not ok:
        raise ParameterError(name, value, allowed, reason)


def is_real(value: object) -> bool:
    """Python and NumPy reals (np.float32, np.int64, ...), not booleans."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_integer(value: object) -> bool:
    """Python and NumPy integers, not booleans."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def is_one_of(value: object, choices: tuple[str, ...] | frozenset[str]) -> bool:
    """Whether ``value`` is one of the text ``choices`` (an array holding one
    is not: ``np.array(["regular"]) in LAYOUTS`` compares element-wise)."""
    return isinstance(value, str) and value in choices


def overflows(text: str) -> bool:
    """Whether a numeral reads as an infinite float without spelling "inf"
    (1e400, 1.0e+400): a typo that would pass for rigid pillars."""
    try:
        value = float(text)
    except ValueError:
        return False
    return math.isinf(value) and "inf" not in text.lower()


def require_switches(obj: object, names: tuple[str, ...], allowed: str) -> None:
    """Check on/off fields of a frozen dataclass (Python or NumPy bools) and
    store them as Python bools; ``allowed`` as the caller's users write it."""
    for name in names:
        value = getattr(obj, name)
        require(isinstance(value, (bool, np.bool_)), name, value, allowed)
        object.__setattr__(obj, name, bool(value))


def _scalar(value: object) -> object:
    """The element of a 0-d NumPy array or xarray DataArray (duck-typed: its
    ``values`` a 0-d array), else ``value`` itself."""
    if not isinstance(value, np.ndarray) and getattr(value, "ndim", None) == 0 and isinstance(
            getattr(value, "values", None), np.ndarray):
        value = value.values
    return value[()] if isinstance(value, np.ndarray) and value.ndim == 0 else value


def normalise(obj: object, integers: tuple[str, ...], reals: tuple[str, ...],
              texts: tuple[str, ...] = ()) -> None:
    """Turn NumPy scalars of a frozen dataclass into Python int / float / str in place.

    Users loop over ``np.array([64, 128])``, take ``DataArray.values`` (a 0-d
    array: ``sweep.layout[0].values`` for a text field) or ``np.linspace``
    grids (64.0, as the workflow's config may write it); the checks, hashes
    and the netCDF attributes want plain Python values (a 0-d text array
    kept made a brush unhashable and gave it another ``parameter_hash``).
    A 0-d xarray DataArray (``sweep.kbar[0]``) counts as its value (its
    repr, coordinates and all, made a refusal's message).  Anything else
    (64.5, arrays of several values) is left for the range checks to refuse
    (`is_one_of` for text).
    """
    for name in texts:
        value = _scalar(getattr(obj, name))
        if isinstance(value, str):  # np.str_ and str-mixin Enums too: their text,
            object.__setattr__(obj, name, str.__str__(value))  # not "Enum.member"
    for name in (*integers, *reals):
        value = getattr(obj, name)
        scalar = _scalar(value)
        if scalar is not value:
            object.__setattr__(obj, name, scalar)
    for name in integers:
        value = getattr(obj, name)
        if (is_real(value) and not is_integer(value) and float(value).is_integer()
                and abs(value) < 2.0**63):  # 1e20 stays as typed, for the range check to name
            value = int(value)  # 64.0, as JSON Schema and the config take it
        if is_integer(value):
            object.__setattr__(obj, name, int(value))
    for name in reals:
        value = getattr(obj, name)
        if is_real(value):
            object.__setattr__(obj, name, float(value))


def brief(obj: object) -> str:
    """A frozen dataclass as its fields that differ from their defaults
    (``layout='regular', n_pillars=16, kbar=0.001, grid=64``): the part of
    a parameter set that a failure message needs, without the twenty
    defaults around it."""
    parts = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.default is dataclasses.MISSING or value != f.default:
            parts.append(f"{f.name}={value!r}")
    return ", ".join(parts) or "defaults"
