"""Checks of a dataset before a run: can every image be read as the run will read it, and do the labels agree
with the camera?

A missing or broken image used to be found by the job that needed it (the job then failed: *not measured*). These
checks find it first, cheaply: per image file, no full decode unless the header is sound.

Image checks (:func:`check_image`, :func:`check_images`, in this order; the first one that fails is the problem)
    1. A sample whose pixels are in memory or rendered on demand (no ``image_path``) passes.
    2. The file exists, is a regular file, lies inside the dataset root (when ``root`` is given; the LARD reader
       has already confined it to its root) and is at most :data:`MAX_IMAGE_FILE_BYTES`.
    3. Its **header** (PIL's lazy ``Image.open``: the header only) gives a size of at most
       :data:`~vbl_robust.constants.MAX_IMAGE_SIDE` px a side — refused before any pixel is decoded — and equal
       to the ``width`` × ``height`` the sample's intrinsics assume (the CSV's columns).
    4. It carries no EXIF orientation other than 1: OpenCV, which reads the pixels during a run, would rotate the
       image, and the corner labels would no longer match it.
    5. It **decodes completely** (PIL ``load()`` with ``ImageFile.LOAD_TRUNCATED_IMAGES`` off: a truncated JPEG is
       refused, where OpenCV would warn and fill the missing rows with grey) and OpenCV has a decoder for its
       format. A format PIL does not know is decoded by OpenCV alone (in full: no header-only size check).

    While :func:`check_images` runs, two PIL settings are process-wide: ``ImageFile.LOAD_TRUNCATED_IMAGES`` is
    False and ``Image.MAX_IMAGE_PIXELS`` is None (so that an over-large header can be named with its size; the
    stricter bound of step 3 applies before any decode). Both are restored afterwards.

    With ``sha256=True`` the file is read once into memory, hashed (the digest :func:`vbl_robust.digest.file_sha256`
    gives) and decoded from those bytes, so that a caller that also records image digests (the results store's
    ``check_contents``) need not read and hash every file again: :func:`image_digests`.

Label checks (:func:`check_labels`)
    The sample's ground-truth corner pixels (``corners_2d``: the CSV's ``x_TR_exact…`` columns when present, else
    the truncated ``x_TR…`` labels) against the runway DB corners reprojected with the row's camera (``K`` from the
    width, height and horizontal field of view; ``R`` and the position from the CSV's attitude and location:
    :mod:`vbl_robust.geometry.camera`): the largest distance in pixels. Whether that is too far is the LARD
    reader's verdict (``meta["lard_check"]``, tolerances in :mod:`.lard_read`), not decided twice.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import re
import warnings
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..constants import MAX_IMAGE_SIDE
from ..geometry.camera import project
from .lard import CORNER_COLUMNS, EXACT_CORNER_COLUMNS

__all__ = ["IMAGE_PROBLEMS", "MAX_IMAGE_FILE_BYTES", "ImageCheck", "LabelCheck", "check_image", "check_images",
           "check_labels", "describe_problems", "first_problem", "image_digests"]

#: Largest image file accepted, bytes: an uncompressed 16-bit RGBA image of ``MAX_IMAGE_SIDE`` px a side, plus
#: 1 MiB of headers. A larger file holds more than any accepted image (it is refused before it is read).
MAX_IMAGE_FILE_BYTES = MAX_IMAGE_SIDE**2 * 8 + (1 << 20)
#: The kinds of image problem (:attr:`ImageCheck.kind`), each with the words a summary counts it in.
IMAGE_PROBLEMS: dict[str, str] = {
    "missing": "image missing",
    "outside": "outside the dataset root",
    "unreadable": "unreadable file",
    "too_large": "too large",
    "size": "another size than stated",
    "orientation": "EXIF-rotated",
    "undecodable": "undecodable",
    "format": "a format OpenCV cannot read",
}
#: EXIF tag of the orientation.
_ORIENTATION = 0x0112
#: Threads decoding images at once (decoders release the GIL).
_MAX_THREADS = 8


@dataclass(frozen=True)
class ImageCheck:
    """Whether a run can read one sample's image as its metadata describes it.

    Attributes:
        sample_id: the sample's id.
        path: the image file relative to the dataset root (the CSV's ``image`` value), or None when the pixels are
            in memory or rendered (no file).
        ok: True when a run can read the image at the stated size.
        problem: why not, one short sentence ("" when ``ok``).
        size: ``(width, height)`` of the file's header, or None when no header was read.
        sha256: hex SHA-256 of the file's bytes, when asked for and the file was read; else None.
        kind: what kind of problem, a key of :data:`IMAGE_PROBLEMS` ("" when ``ok``).
    """

    sample_id: str
    path: str | None
    ok: bool
    problem: str = ""
    size: tuple[int, int] | None = None
    sha256: str | None = None
    kind: str = ""


@dataclass(frozen=True)
class LabelCheck:
    """The ground-truth corner labels of one sample against the reprojection of its 3-D corners.

    Attributes:
        sample_id: the sample's id.
        max_px: largest distance between a corner label and the projected corner, pixels (NaN when no corner
            projects: every corner behind the camera, or no camera rotation known).
        behind: corners behind the camera (not compared: a LARD label of such a corner is not a projection).
        off: the label columns the LARD reader found farther from the projection than its tolerance
            (``meta["lard_check"]``); empty when they agree or the sample is not a LARD row.
        exact: True when the labels are the exact ``x_TR_exact…`` columns, False for truncated ``x_TR…`` labels
            (None: not a LARD row).
    """

    sample_id: str
    max_px: float
    behind: int = 0
    off: tuple[str, ...] = ()
    exact: bool | None = None

    @property
    def ok(self) -> bool:
        """True unless the reader found a label off the projection."""
        return not self.off


def check_labels(sample: Any) -> LabelCheck:
    """:class:`LabelCheck` of ``sample`` (a :class:`~vbl_robust.data.sample.Sample`): its ``corners_2d`` against
    ``project(corners_3d, R, position, K)``, in pixels."""
    meta = getattr(sample, "meta", None) or {}
    if sample.R is None:
        return LabelCheck(sample.id, math.nan)
    with np.errstate(all="ignore"):
        projected = project(sample.corners_3d, sample.R, sample.position, sample.K)
        dist = np.linalg.norm(np.asarray(sample.corners_2d, dtype=np.float64) - projected, axis=1)
    seen = np.isfinite(projected).all(axis=1)
    max_px = float(np.nanmax(dist[seen])) if seen.any() else math.nan
    columns = (*CORNER_COLUMNS, *EXACT_CORNER_COLUMNS)
    off = tuple(c for c in columns if c in (meta.get("lard_check") or {}))
    exact = meta.get("corners_exact")
    return LabelCheck(sample.id, max_px, int((~seen).sum()), off, None if exact is None else bool(exact))


def check_image(sample: Any, *, root: str | Path | None = None, sha256: bool = False) -> ImageCheck:
    """:class:`ImageCheck` of one sample (the module docstring's checks, in order).

    Args:
        sample: a :class:`~vbl_robust.data.sample.Sample` (``image_path``, ``width``, ``height``, ``id``, ``meta``).
        root: the dataset root: the file must lie inside it (following symlinks), and paths are shown relative to
            it. Default: no containment check here (the reader's), paths as the CSV gives them.
        sha256: also hash the file's bytes (read once, decoded from memory).

    Call it through :func:`check_images` for many samples: that sets PIL up for the checks (strict decoding, the
    header bound checked here) and decodes on several threads.
    """
    with _strict_pil():
        return _check_one(sample, None if root is None else Path(root).resolve(), sha256)


def check_images(samples: Iterable[Any], *, root: str | Path | None = None, sha256: bool = False,
                 progress: Callable[[int, int], None] | None = None, threads: int | None = None,
                 ) -> list[ImageCheck]:
    """:class:`ImageCheck` of every sample's image, in order; an approach sequence (anything with ``samples``)
    counts as its frames. A file shared by several samples at the same stated size is read once.

    Args:
        samples: samples, or approach sequences.
        root, sha256: as :func:`check_image`.
        progress: called as ``progress(done, total)`` after each image (from the calling thread).
        threads: images decoded at once (default: the CPU count, at most 8).

    Returns:
        One check per sample (per frame of a sequence), in order.
    """
    frames = list(_frames(samples))
    base = None if root is None else Path(root).resolve()
    n_threads = threads if threads is not None else min(_MAX_THREADS, os.cpu_count() or 1)
    if isinstance(n_threads, bool) or not isinstance(n_threads, int) or n_threads < 1:
        raise ValueError(f"check_images: threads must be an integer >= 1, got {threads!r}")
    keys = [_key(s) for s in frames]
    unique = {k: s for k, s in zip(keys, frames, strict=True)}
    uses = Counter(keys)
    results: dict[tuple, ImageCheck] = {}
    with _strict_pil(), ThreadPoolExecutor(max_workers=n_threads) as pool:
        done = 0
        for key, check in zip(unique, pool.map(lambda s: _check_one(s, base, sha256), unique.values()), strict=True):
            results[key] = check
            done += uses[key]
            if progress is not None:
                progress(done, len(frames))
    out = []
    for s, key in zip(frames, keys, strict=True):
        c = results[key]
        out.append(c if c.sample_id == s.id else replace(c, sample_id=s.id))
    return out


def describe_problems(checks: Sequence[ImageCheck]) -> str | None:
    """One line for the images of ``checks`` that cannot be used (the first named, the others counted), or None
    when every image can be."""
    bad = [c for c in checks if not c.ok]
    if not bad:
        return None
    first = bad[0]
    where = first.path if first.path is not None else f"sample {first.sample_id}"
    more = f" (and {len(bad) - 1} more: vbl-robust check DATA lists them)" if len(bad) > 1 else ""
    return f"{len(bad)} of {len(checks)} image(s) cannot be used: {where}: {first.problem}{more}"


def first_problem(samples: Iterable[Any], *, root: str | Path | None = None) -> str | None:
    """The pre-run check: :func:`describe_problems` of :func:`check_images` — one line naming the first image a
    run could not read at its stated size (and how many more), or None when every image can be read."""
    return describe_problems(check_images(samples, root=root))


def image_digests(checks: Iterable[ImageCheck]) -> dict[str, str]:
    """``{sample_id: sha256}`` of the checks that hashed their file (:func:`check_images` with ``sha256=True``)."""
    return {c.sample_id: c.sha256 for c in checks if c.sha256 is not None}


# -- internals ----------------------------------------------------------------------------------------------------


def _frames(samples: Iterable[Any]) -> Iterator[Any]:
    for s in samples:
        frames = getattr(s, "samples", None)
        yield from (frames if frames is not None else (s,))


def _key(s: Any) -> tuple:
    path = getattr(s, "image_path", None)
    if path is None:
        return ("memory", id(s))
    return (str(path), int(s.width), int(s.height))


def _shown(s: Any, root: Path | None) -> str:
    """The image path as the user wrote it: relative to ``root`` when it lies inside, else the CSV's text."""
    path = Path(s.image_path)
    if root is not None:
        try:
            return path.resolve().relative_to(root).as_posix()
        except (ValueError, OSError, RuntimeError):
            pass
    text = str((getattr(s, "meta", None) or {}).get("image", "")).strip()
    return text.replace("\\", "/") if text else path.as_posix()


#: The camera the intrinsics assume, said where an image of another size is refused (the labels and K hold for the
#: stated size only).
CAMERA_CONVENTION = ("(the camera model assumes that size: focal length from the horizontal field of view over the "
                     "width, square pixels, principal point at the image centre)")


def _stated(s: Any) -> str:
    return "the CSV says" if "csv" in (getattr(s, "meta", None) or {}) else "the sample says"


@contextmanager
def _strict_pil() -> Iterator[None]:
    """PIL set up for the checks (module docstring), restored afterwards."""
    from PIL import Image, ImageFile

    truncated, pixels = ImageFile.LOAD_TRUNCATED_IMAGES, Image.MAX_IMAGE_PIXELS
    ImageFile.LOAD_TRUNCATED_IMAGES = False
    Image.MAX_IMAGE_PIXELS = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            yield
    finally:
        ImageFile.LOAD_TRUNCATED_IMAGES, Image.MAX_IMAGE_PIXELS = truncated, pixels


def _check_one(s: Any, root: Path | None, sha256: bool) -> ImageCheck:
    path = getattr(s, "image_path", None)
    if path is None:
        return ImageCheck(s.id, None, True)
    path = Path(path)
    shown = _shown(s, root)

    def refuse(kind: str, problem: str) -> ImageCheck:
        return ImageCheck(s.id, shown, False, problem, kind=kind)

    try:
        if root is not None:
            resolved = path.resolve()
            if resolved == root or not resolved.is_relative_to(root):
                return refuse("outside", f"the image file lies outside the dataset root (it resolves to {resolved})")
        if not path.exists():
            return refuse("missing", "image file not found")
        if not path.is_file():
            return refuse("missing", "not a regular file (a directory?)")
        n_bytes = path.stat().st_size
        if n_bytes > MAX_IMAGE_FILE_BYTES:
            return refuse("too_large", f"the file is {n_bytes / 2**20:.0f} MiB, more than any image of at most "
                          f"{MAX_IMAGE_SIDE} px a side needs ({MAX_IMAGE_FILE_BYTES / 2**20:.0f} MiB)")
        if n_bytes == 0:
            return refuse("undecodable", "the image file is empty")
        with open(path, "rb") as fh:
            return _check_file(s, fh, shown, sha256)
    except OSError as exc:
        return refuse("unreadable", f"cannot be read ({exc.strerror or _one_line(exc)})")


def _check_file(s: Any, fh: Any, shown: str, sha256: bool) -> ImageCheck:
    from PIL import Image, UnidentifiedImageError

    stated = (int(s.width), int(s.height))
    try:
        im = Image.open(fh)
    except (UnidentifiedImageError, ImportError):  # ImportError: a third-party opener another library registered
        fh.seek(0)  # (e.g. one that needs pi_heif) tried the file and lacked its own module: not PIL's format
        return _check_with_opencv(s, shown, sha256)
    except Exception as exc:  # noqa: BLE001 - a malformed header can raise anything inside PIL's parsers
        return ImageCheck(s.id, shown, False, f"unreadable image header ({_one_line(exc)})", kind="undecodable")
    with im:
        size = (int(im.size[0]), int(im.size[1]))

        def refuse(kind: str, problem: str, digest: str | None = None) -> ImageCheck:
            return ImageCheck(s.id, shown, False, problem, size, digest, kind)

        if max(size) > MAX_IMAGE_SIDE:
            return refuse("too_large", f"the header says {size[0]}x{size[1]} px, more than {MAX_IMAGE_SIDE} px a side "
                          "(not decoded)")
        if size != stated:
            return refuse("size", f"the image is {size[0]}x{size[1]} px, {_stated(s)} {stated[0]}x{stated[1]} "
                          f"{CAMERA_CONVENTION}")
        try:
            orientation = im.getexif().get(_ORIENTATION)
        except Exception:  # noqa: BLE001 - a malformed EXIF block: OpenCV ignores what it cannot parse too
            orientation = None
        if orientation not in (None, 1):
            return refuse("orientation", f"EXIF orientation {orientation}: OpenCV would rotate the image when a run "
                          "reads it, away from its labels (save it without the orientation tag)")
        digest = None
        if sha256:
            fh.seek(0)
            data = fh.read()
            digest = hashlib.sha256(data).hexdigest()
            with Image.open(io.BytesIO(data)) as copy:
                problem = _decode(copy)
        else:
            problem = _decode(im)
        if problem:
            return refuse("undecodable", f"cannot be decoded: {problem}", digest)
    import cv2

    if not cv2.haveImageReader(str(s.image_path)):
        return refuse("format", "OpenCV, which reads the images during a run, has no decoder for this format", digest)
    return ImageCheck(s.id, shown, True, "", size, digest)


def _decode(im: Any) -> str:
    """"" when ``im`` decodes completely, else why not."""
    try:
        im.load()
    except Exception as exc:  # noqa: BLE001 - decoders raise OSError, SyntaxError, ValueError, zlib/struct errors …
        return _one_line(exc)
    return ""


def _check_with_opencv(s: Any, shown: str, sha256: bool) -> ImageCheck:
    """A file PIL cannot identify: what OpenCV (the run's reader) makes of it, decoded in full."""
    import cv2

    path = str(s.image_path)
    if not cv2.haveImageReader(path):
        return ImageCheck(s.id, shown, False, "not an image file (neither PIL nor OpenCV knows its format)",
                          kind="undecodable")
    data = Path(path).read_bytes()
    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        return ImageCheck(s.id, shown, False, "cannot be decoded (OpenCV cannot read it)", kind="undecodable")
    size = (int(img.shape[1]), int(img.shape[0]))
    digest = hashlib.sha256(data).hexdigest() if sha256 else None
    if max(size) > MAX_IMAGE_SIDE:
        return ImageCheck(s.id, shown, False, f"the image is {size[0]}x{size[1]} px, more than {MAX_IMAGE_SIDE} px a "
                          "side", size, digest, "too_large")
    if size != (int(s.width), int(s.height)):
        return ImageCheck(s.id, shown, False, f"the image is {size[0]}x{size[1]} px, {_stated(s)} "
                          f"{int(s.width)}x{int(s.height)} {CAMERA_CONVENTION}", size, digest, "size")
    return ImageCheck(s.id, shown, True, "", size, digest)


_FILE_IN_MESSAGE = re.compile(r"\s*'[^']*'\s*$")


def _one_line(exc: BaseException) -> str:
    """An exception as a short phrase: its message on one line (no file name quoted by PIL), else its kind."""
    text = " ".join(str(exc).split())
    text = _FILE_IN_MESSAGE.sub("", text) if text.startswith("cannot identify") else text
    return text or type(exc).__name__.replace("Error", " error").strip().lower()
