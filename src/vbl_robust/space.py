"""Named, bounded parameter boxes: the search space Θ shared by the perturbations and the searches.

A :class:`ParameterBox` is an ordered mapping ``name -> (lower, upper)`` in *real units* (``roll_deg`` in
degrees, ``contrast`` as a dimensionless factor, …). Searches work in the unit cube ``[0, 1]^d`` and call
:meth:`ParameterBox.from_unit` only to evaluate; results are always reported in real units.

Convention: dimension ``i`` of a θ array of shape ``(N, d)`` is ``box.names[i]``; names are kept in the order
they were given.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np

#: Units of the parameters this package knows. Unknown names are allowed (unit "").
KNOWN_UNITS: dict[str, str] = {
    "roll_deg": "deg",
    "pitch_deg": "deg",
    "yaw_deg": "deg",
    "blur_px": "px",
    "motion_blur_px": "px",
    "haze": "fraction",
    "contrast": "factor",
    "brightness": "full scale",
    "gamma": "exponent",
    "noise_std": "full scale",
    "scale": "factor",
}

#: Smallest width of a parameter relative to the magnitude of its bounds: keeps the unit-cube resolution
#: ``ulp(max(|lower|, |upper|)) / width`` at or below 2**-20 (about 1e-6), so ``to_unit(from_unit(u))`` is ``u``
#: to that precision or better.
MIN_RELATIVE_WIDTH = 2.0**-32
#: Smallest absolute width (well above the subnormal range, where ``u * width`` would lose all precision).
MIN_WIDTH = 1e-290


def _pair(name: str, pair) -> tuple[float, float]:
    """``(lower, upper)`` as floats; ``ValueError`` naming the parameter for anything but two real numbers."""
    bad = ValueError(f"ParameterBox: bounds of {name!r} must be two numbers (lower, upper), got {pair!r}")
    if isinstance(pair, str | bytes | Mapping) or not hasattr(pair, "__iter__"):
        raise bad
    try:
        values = list(pair)
    except TypeError:
        raise bad from None
    if len(values) != 2 or any(isinstance(v, bool | np.bool_ | str | bytes) for v in values):
        raise bad
    try:
        a, b = (float(v) for v in values)
    except (TypeError, ValueError, OverflowError):
        raise bad from None
    return a, b


@dataclass(frozen=True, init=False)
class ParameterBox:
    """An axis-aligned box of named parameters.

    >>> box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    >>> box.names, box.dim
    (('roll_deg', 'contrast'), 2)
    >>> box.from_unit(np.array([[0.5, 0.0]])).tolist()
    [[0.0, 0.7]]
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    units: tuple[str, ...]

    def __init__(self, bounds: Mapping[str, tuple[float, float]], units: Mapping[str, str] | None = None):
        if not isinstance(bounds, Mapping) or len(bounds) == 0:
            raise ValueError(f"ParameterBox: bounds must be a non-empty mapping name -> (lower, upper), got {bounds!r}")
        names, lo, hi = [], [], []
        for name, pair in bounds.items():
            if not isinstance(name, str) or not name.strip():
                raise ValueError(f"ParameterBox: parameter name must be a non-empty string, got {name!r}")
            a, b = _pair(name, pair)
            if not (math.isfinite(a) and math.isfinite(b)):
                raise ValueError(f"ParameterBox: bounds of {name!r} must be finite, got ({a}, {b})")
            if not a < b:
                raise ValueError(f"ParameterBox: lower < upper required for {name!r}, got ({a}, {b})")
            # the unit-cube maps divide by the width: it must be finite and resolvable at the bounds' magnitude
            width = b - a
            if not math.isfinite(width) or width < max(MIN_RELATIVE_WIDTH * max(abs(a), abs(b)), MIN_WIDTH):
                raise ValueError(
                    f"ParameterBox: bounds of {name!r} = ({a!r}, {b!r}) have a width {width!r} that float64 cannot "
                    f"map to the unit cube (need a finite width >= {MIN_RELATIVE_WIDTH:.3g} x max(|lower|, |upper|) "
                    f"and >= {MIN_WIDTH:g})"
                )
            names.append(name)
            lo.append(a)
            hi.append(b)
        if units is not None and not isinstance(units, Mapping):
            raise ValueError(f"ParameterBox: units must be a mapping name -> unit string, got {units!r}")
        units = dict(units or {})
        for name, unit in units.items():
            if name not in bounds:
                raise ValueError(f"ParameterBox: unit given for {name!r}, which is not a parameter of {tuple(names)}")
            if not isinstance(unit, str):
                raise ValueError(f"ParameterBox: unit of {name!r} must be a string, got {unit!r}")
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "lower", np.asarray(lo, dtype=np.float64))
        object.__setattr__(self, "upper", np.asarray(hi, dtype=np.float64))
        object.__setattr__(self, "units", tuple(units.get(n, KNOWN_UNITS.get(n, "")) for n in names))
        self.lower.setflags(write=False)
        self.upper.setflags(write=False)

    # -- basic properties -------------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return len(self.names)

    @property
    def width(self) -> np.ndarray:
        return self.upper - self.lower

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)

    @property
    def volume(self) -> float:
        return float(np.prod(self.width))

    def __len__(self) -> int:
        return self.dim

    def __iter__(self) -> Iterator[str]:
        return iter(self.names)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ParameterBox):
            return NotImplemented
        return (
            self.names == other.names
            and np.array_equal(self.lower, other.lower)
            and np.array_equal(self.upper, other.upper)
            and self.units == other.units
        )

    def __hash__(self) -> int:
        return hash((self.names, tuple(self.lower), tuple(self.upper), self.units))

    def __repr__(self) -> str:
        inner = ", ".join(f"{n!r}: ({a:g}, {b:g})" for n, a, b in zip(self.names, self.lower, self.upper, strict=True))
        return f"ParameterBox({{{inner}}})"

    def bounds(self) -> dict[str, tuple[float, float]]:
        return {n: (float(a), float(b)) for n, a, b in zip(self.names, self.lower, self.upper, strict=True)}

    def to_dict(self) -> dict:
        """JSON-friendly form (used in provenance records)."""
        return {"bounds": {n: list(v) for n, v in self.bounds().items()}, "units": dict(zip(self.names, self.units, strict=True))}

    @classmethod
    def from_dict(cls, d: Mapping) -> ParameterBox:
        """Inverse of :meth:`to_dict`; ``ValueError`` (never ``KeyError``/``TypeError``) for a malformed dict."""
        if not isinstance(d, Mapping) or not isinstance(d.get("bounds"), Mapping):
            raise ValueError(f"ParameterBox.from_dict: expected {{'bounds': {{name: [lower, upper]}}, 'units': "
                             f"{{name: unit}}}}, got {d!r}")
        return cls(dict(d["bounds"]), units=d.get("units"))

    # -- mappings ---------------------------------------------------------------------------------------
    def _as_2d(self, x, what: str) -> np.ndarray:
        try:
            a = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"ParameterBox: {what} must be numbers of shape (N, {self.dim}) for {self.names}, "
                             f"got {x!r}") from None
        if a.ndim == 1:
            a = a[None, :]
        if a.ndim != 2 or a.shape[1] != self.dim:
            raise ValueError(f"ParameterBox: {what} must have shape (N, {self.dim}) for {self.names}, got {np.shape(x)}")
        return a

    def from_unit(self, u) -> np.ndarray:
        """Map points of the unit cube ``(N, d)`` to real units ``(N, d)`` (points of ``[0, 1]^d`` land in the box)."""
        a = self._as_2d(u, "unit-cube points")
        x = self.lower + a * self.width
        # lower + 1 * width can round past upper (or short of it): the cube's points land in the box, its
        # corners exactly on the bounds; the map stays monotone
        x = np.where(a <= 1.0, np.minimum(x, self.upper), x)
        x = np.where(a == 1.0, self.upper, x)
        return np.where(a >= 0.0, np.maximum(x, self.lower), x)

    def to_unit(self, x) -> np.ndarray:
        """Map real-unit points ``(N, d)`` to the unit cube ``(N, d)``."""
        a = self._as_2d(x, "points")
        return (a - self.lower) / self.width

    def contains(self, x, *, atol: float = 1e-12) -> np.ndarray:
        """Boolean ``(N,)``: which real-unit points lie in the box (inclusive, with tolerance)."""
        a = self._as_2d(x, "points")
        tol = atol * np.maximum(1.0, np.abs(self.width))
        with np.errstate(over="ignore"):  # bounds near the float64 limit: an infinite margin is still right
            return np.all((a >= self.lower - tol) & (a <= self.upper + tol), axis=1)

    def clip(self, x) -> np.ndarray:
        return np.clip(self._as_2d(x, "points"), self.lower, self.upper)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"ParameterBox: no parameter {name!r}; parameters are {self.names}") from None
