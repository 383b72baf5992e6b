"""Input validation shared by the public wrappers.

Every public function validates in Python before a kernel runs. Errors name the argument and
say what was wrong; they are ``TypeError`` for a wrong kind of object or dtype and ``ValueError``
for a wrong shape or value.
"""

from __future__ import annotations

import dataclasses
import numbers

import numpy as np

#: Largest image side accepted anywhere (a 65536² float32 buffer is already 16 GiB).
MAX_SIDE = 1 << 15
#: Largest number of pixels of one image (64 Mpx).
MAX_PIXELS = 1 << 26


def as_float_array(value, name, *, shape=None, dtype=np.float64, finite=True):
    """Convert ``value`` to a float array of ``dtype``, checking shape and finiteness.

    ``shape`` is a tuple whose entries are ints or ``None`` (any length on that axis).
    """
    if (type(value) is np.ndarray and value.dtype == dtype and value.ndim
            and value.flags.c_contiguous):   # already what the checks below would give
        arr = value
        if shape is not None:
            check_shape(arr, name, shape)
        if finite and arr.size and not np.isfinite(arr).all():
            bad = int(np.count_nonzero(~np.isfinite(arr)))
            raise ValueError(f"{name} contains {bad} non-finite value(s) (NaN or inf)")
        return arr
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be a numeric array, got {type(value).__name__}")
    arr = np.asarray(value)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise TypeError(f"{name} must be real, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=dtype)
    if shape is not None:
        check_shape(arr, name, shape)
    if finite and arr.size and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name} contains {bad} non-finite value(s) (NaN or inf)")
    return arr


def check_shape(arr, name, shape):
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")


def as_index_array(value, name, *, shape=None, upper=None):
    """Convert ``value`` to a contiguous int64 array; entries must lie in ``[0, upper)``."""
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be an integer array, got {type(value).__name__}")
    arr = np.asarray(value)
    if arr.size == 0 and arr.dtype == np.float64:
        arr = arr.astype(np.int64)
    if not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{name} must be an integer array, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.int64)
    if shape is not None:
        check_shape(arr, name, shape)
    if arr.size and upper is not None:
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0 or hi >= upper:
            raise ValueError(f"{name} has indices outside [0, {upper}): min {lo}, max {hi}")
    return arr


def as_size(value, name, *, maximum=MAX_SIDE):
    """A positive image side."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    value = int(value)
    if value <= 0:
        raise ValueError(f"{name} must be positive, got {value}")
    if value > maximum:
        raise ValueError(f"{name} = {value} exceeds the largest supported size {maximum}")
    return value


def as_image_size(width, height):
    width = as_size(width, "width")
    height = as_size(height, "height")
    if width * height > MAX_PIXELS:
        raise ValueError(
            f"width × height = {width * height} pixels exceeds the supported {MAX_PIXELS}")
    return width, height


def as_matrix(value, name):
    """A finite 4×4 float64 matrix."""
    return as_float_array(value, name, shape=(4, 4))


def as_choice(value, name, choices):
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a str, one of {sorted(choices)}, got {type(value).__name__}")
    key = value.lower()
    if key not in choices:
        raise ValueError(f"{name} must be one of {sorted(choices)}, got {value!r}")
    return choices[key] if isinstance(choices, dict) else key


def as_real(value, name, *, lo=None, hi=None, lo_open=False, hi_open=False):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise ValueError(f"{name} must be {'<' if hi_open else '<='} {hi}, got {value}")
    return value


def as_flag(value, name):
    """A bool (NumPy's too); anything else refused with one line naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {type(value).__name__}")
    return bool(value)


def as_colour(value, name):
    """A finite RGB triple as a tuple of three floats (so that option values compare and hash)."""
    return tuple(float(c) for c in as_float_array(value, name, shape=(3,)))


class OptionValue:
    """Base of the frozen option values of the techniques: ``replace`` gives a validated copy."""

    def replace(self, **changes):
        """A copy with some fields changed (validated like a new value)."""
        return dataclasses.replace(self, **changes)


def as_option(value, cls, name, *, optional=False):
    """``value`` if it is a ``cls``; ``None`` too with ``optional``; anything else refused.

    The message names the class by its public path (``refraster.cutaway.Cutaway``)."""
    if isinstance(value, cls) or (optional and value is None):
        return value
    package = cls.__module__.rsplit(".", 1)[0]
    none = " (or None)" if optional else ""
    raise TypeError(f"{name} must be a {package}.{cls.__name__}{none}, got "
                    f"{type(value).__name__}")
