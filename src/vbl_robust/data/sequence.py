"""Approach sequences: the frames of one approach, in order, with their times.

An :class:`ApproachSequence` is a list of :class:`~vbl_robust.data.sample.Sample` (one per frame, far to close as
flown), the frame indices and the times. Synthetic sequences come from
:func:`vbl_robust.scenes.sequences.generate_sequences`; a LARD V2 dataset is grouped into sequences by
:func:`group_sequences` / :func:`read_lard_sequences`.

How frames are grouped (first rule that applies to the whole dataset)
    1. **Sequence columns** (:data:`.lard.SEQUENCE_COLUMNS`, written by this package): ``sequence_id`` (free
       text), ``frame_index`` (integer ≥ 0, unique within a sequence), ``time_s`` (seconds since the sequence's
       first frame; optional: an empty column falls back to rule 3's times).
    2. **Image names** (no ``sequence_id`` column): the image path's stem is ``<sequence>_<frame>`` with
       ``<frame>`` the trailing digits (``CYEG-20_000.jpg`` → sequence ``CYEG-20``, frame 0, LARD's own scenario
       naming), or the stem is all digits and the folder is the sequence (``approach7/0012.png`` → sequence
       ``approach7``, frame 12). The sequence id keeps the folder (``seqs/A_003.png`` → ``seqs/A``). A name that
       fits neither is an error naming the file and row.
    3. **Times**, when no ``time_s`` is given: ``time_to_landing`` (LARD, seconds) when it is a number on every
       frame (time = its first value minus its value), else ``frame_index / rate_hz`` when ``rate_hz`` is given,
       else NaN (sustained errors count frames, not seconds; only the reported durations need times).

Frames are sorted by ``frame_index``; the windows of a sustained error run over the frames as kept (a frame
dropped by a reader filter leaves a gap: it is listed in ``meta["gaps"]``). Sequences keep the order of their
first frame in the input.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from .lard_read import read_lard
from .sample import Sample

__all__ = ["NAME_PATTERN", "ApproachSequence", "flatten", "group_sequences", "read_lard_sequences"]

#: Image stems ``<sequence>_<frame>`` (rule 2 of the module docstring).
NAME_PATTERN = re.compile(r"^(?P<sequence>.+)_(?P<frame>\d+)$")
_DIGITS = re.compile(r"^\d+$")


@dataclass(eq=False)
class ApproachSequence:
    """The frames of one approach, in flight order.

    Attributes:
        id: sequence identifier (unique within a dataset).
        samples: ``F`` samples, one per frame.
        times: ``(F,)`` seconds since the first frame (strictly increasing), or all NaN when unknown.
        frame_index: ``(F,)`` integer frame indices (strictly increasing; gaps allowed).
        meta: free-form fields (generator parameters, ``gaps``, the source CSV).
    """

    id: str
    samples: list[Sample]
    times: np.ndarray
    frame_index: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.samples = list(self.samples)
        n = len(self.samples)
        if n == 0:
            raise ValueError(f"sequence {self.id!r}: no frames")
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.frame_index = np.asarray(self.frame_index).reshape(-1)
        if self.times.shape != (n,) or self.frame_index.shape != (n,):
            raise ValueError(f"sequence {self.id!r}: {n} frames but {self.times.size} times and "
                             f"{self.frame_index.size} frame indices")
        if not np.issubdtype(self.frame_index.dtype, np.integer) or np.any(np.diff(self.frame_index) <= 0):
            raise ValueError(f"sequence {self.id!r}: frame_index must be strictly increasing integers, got "
                             f"{self.frame_index.tolist()}")
        known = np.isfinite(self.times)
        if known.any() and not (known.all() and np.all(np.diff(self.times) > 0)):
            raise ValueError(f"sequence {self.id!r}: times must be finite and strictly increasing (or all NaN), got "
                             f"{self.times.tolist()}")

    def __len__(self) -> int:
        return len(self.samples)

    def __iter__(self) -> Iterator[Sample]:
        return iter(self.samples)

    def __getitem__(self, i: int) -> Sample:
        return self.samples[i]

    @property
    def distances_m(self) -> np.ndarray:
        """``(F,)`` horizontal distance from the landing threshold point (LTP) to each true camera position, metres
        (``‖(x, y)‖`` in the runway frame: the LARD envelopes' ``distance_m``)."""
        return np.array([math.hypot(s.position[0], s.position[1]) for s in self.samples])

    @property
    def rate_hz(self) -> float:
        """Frames per second (median spacing of ``times``); NaN when the times are unknown or there is one frame."""
        if len(self) < 2 or not np.isfinite(self.times).all():
            return math.nan
        return float(1.0 / np.median(np.diff(self.times)))

    @property
    def slant_distance_m(self) -> float:
        """Slant distance of the first frame (where the approach starts): a campaign's sample record."""
        return self.samples[0].slant_distance_m

    @property
    def width(self) -> int:
        """Image width of the first frame."""
        return int(self.samples[0].width)

    @property
    def height(self) -> int:
        """Image height of the first frame."""
        return int(self.samples[0].height)

    def drop_pixels(self) -> None:
        """Forget the cached pixels of every frame (:meth:`Sample.drop_pixels`)."""
        for s in self.samples:
            s.drop_pixels()


def _where(s: Sample) -> str:
    meta = s.meta or {}
    if "csv" in meta and "row" in meta:
        return f"{meta['csv']}: row {meta['row']} (image {s.id!r})"
    return f"sample {s.id!r}"


def _frame_of_name(s: Sample) -> tuple[str, int]:
    path = PurePosixPath(str(s.id).split("#", 1)[0])
    stem, folder = path.stem, path.parent.as_posix()
    if _DIGITS.match(stem) and folder not in ("", "."):
        return folder, int(stem)
    m = NAME_PATTERN.match(stem)
    if m is None:
        raise ValueError(f"{_where(s)}: image name {path.name!r} does not name a sequence frame: expected "
                         f"'<sequence>_<frame>.<ext>' or '<sequence folder>/<frame>.<ext>' (no 'sequence_id' column)")
    seq = m.group("sequence") if folder in ("", ".") else f"{folder}/{m.group('sequence')}"
    return seq, int(m.group("frame"))


def _frame_of_columns(s: Sample) -> tuple[str, int]:
    meta = s.meta
    seq = str(meta.get("sequence_id", "")).strip()
    if not seq:
        raise ValueError(f"{_where(s)}: field 'sequence_id' is empty while other rows have one")
    text = str(meta.get("frame_index", "")).strip()
    try:
        frame = int(text)
    except ValueError:
        frame = -1
    if frame < 0:
        raise ValueError(f"{_where(s)}: field 'frame_index' = {meta.get('frame_index')!r} is not an integer >= 0")
    return seq, frame


def _optional_number(s: Sample, name: str) -> float | None:
    value = (s.meta or {}).get(name, "")
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{_where(s)}: field {name!r} = {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ValueError(f"{_where(s)}: field {name!r} = {value!r} is not a finite number")
    return number


def _times(frames: list[tuple[int, Sample]], rate_hz: float | None) -> tuple[np.ndarray, str]:
    given = [_optional_number(s, "time_s") for _, s in frames]
    if all(t is not None for t in given):
        times, source = np.array(given), "time_s"
    else:
        ttl = [_optional_number(s, "time_to_landing") for _, s in frames]
        if all(t is not None for t in ttl):
            times, source = ttl[0] - np.array(ttl), "time_to_landing"
        elif rate_hz is not None:
            times, source = np.array([f for f, _ in frames], dtype=np.float64) / rate_hz, "rate_hz"
        else:
            return np.full(len(frames), np.nan), "unknown"
    bad = np.nonzero(np.diff(times) <= 0)[0]
    if bad.size:
        f, s = frames[bad[0] + 1]
        raise ValueError(f"{_where(s)}: frame {f} has time {times[bad[0] + 1]:g} s (from {source}), not after the "
                         f"previous frame's {times[bad[0]]:g} s")
    return times, source


def group_sequences(samples: Iterable[Sample], *, rate_hz: float | None = None) -> list[ApproachSequence]:
    """Group samples (e.g. :func:`~vbl_robust.data.read_lard` rows) into approach sequences.

    Args:
        samples: frames of one or more sequences, in any order.
        rate_hz: frame rate used for the times when the data give none (see the module docstring).

    Returns:
        One :class:`ApproachSequence` per sequence, frames sorted by index, in order of first appearance; each
        ``meta`` has ``time_source`` (``"time_s"``, ``"time_to_landing"``, ``"rate_hz"`` or ``"unknown"``),
        ``grouped_by`` (``"columns"`` or ``"names"``) and ``gaps`` (missing frame indices).

    Raises:
        ValueError: one line naming the file, row and field: some rows with a ``sequence_id`` and some without, a
            sequence whose frames show different runways (airport/runway), a bad ``frame_index``, an image name that does not name a frame, the same frame twice, times that do not
            increase with the frame index, or a bad ``rate_hz``.
    """
    if rate_hz is not None and (isinstance(rate_hz, bool) or not isinstance(rate_hz, int | float | np.number)
                                or not (math.isfinite(rate_hz) and rate_hz > 0)):
        raise ValueError(f"group_sequences: rate_hz must be a finite number > 0, got {rate_hz!r}")
    items = list(samples)
    if not items:
        return []
    with_id = [bool(str((s.meta or {}).get("sequence_id", "")).strip()) for s in items]
    by_columns = any(with_id)
    groups: dict[str, dict[int, Sample]] = {}
    for s in items:
        seq, frame = _frame_of_columns(s) if by_columns else _frame_of_name(s)
        frames = groups.setdefault(seq, {})
        if frame in frames:
            raise ValueError(f"{_where(s)}: sequence {seq!r} frame {frame} appears twice (also {_where(frames[frame])})")
        frames[frame] = s
    out = []
    for seq, frames in groups.items():
        ordered = sorted(frames.items())
        runways = {((f.meta or {}).get("airport"), (f.meta or {}).get("runway")) for _, f in ordered}
        if len(runways) > 1:  # frames grouped by their names alone must still be one approach
            names = ", ".join(f"{a}/{r}" for a, r in sorted(runways, key=str)[:4])
            raise ValueError(f"{_where(ordered[0][1])}: sequence {seq!r} (grouped by "
                             f"{'columns' if by_columns else 'image names'}) mixes runways {names}; give each "
                             "approach its own sequence_id")
        times, source = _times(ordered, rate_hz)
        index = np.array([f for f, _ in ordered], dtype=np.int64)
        gaps = sorted(set(range(int(index[0]), int(index[-1]) + 1)) - set(index.tolist()))
        out.append(ApproachSequence(seq, [s for _, s in ordered], times, index, meta={
            "time_source": source, "grouped_by": "columns" if by_columns else "names", "gaps": gaps}))
    return out


def read_lard_sequences(csv_path: str | Path, runway_db_path: str | Path, *, rate_hz: float | None = None,
                        **read_options) -> list[ApproachSequence]:
    """Read a LARD V2 dataset (:func:`~vbl_robust.data.read_lard`, same options) and group it into sequences
    (:func:`group_sequences`)."""
    return group_sequences(read_lard(csv_path, runway_db_path, **read_options), rate_hz=rate_hz)


def flatten(sequences: Sequence[ApproachSequence]) -> list[Sample]:
    """All frames of ``sequences``, sequence after sequence."""
    return [s for seq in sequences for s in seq.samples]
