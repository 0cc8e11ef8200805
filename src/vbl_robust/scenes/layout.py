"""Airport layouts on the ground plane as runway-aligned rectangles, painted with exact area coverage.

A layout is an array of rectangles in the runway frame (metres), painted in order. Each row is
``[x0, x1, px, dx, y0, y1, py, dy, r, g, b, alpha]``: the rectangle ``[x0, x1] × [y0, y1]``, optionally dashed
along x (period ``px``, dash length ``dx``, first dash starting at ``x0``; ``px = 0`` = solid) and along y; an
albedo colour in [0, 1] and an opacity. Because every shape is an axis-aligned (dashed) rectangle, the fraction of
a texel it covers is separable and computed exactly (:func:`paint`), at any texel size: painting is a perfect box
filter, so a tile painted at the pixel footprint needs no further anti-aliasing, and the runway edge lands where
its corners project.

Markings follow ICAO Annex 14 in spirit (sizes in metres): piano-key threshold stripes (30 × 1.8), designation
(9 m tall blocky glyphs), centreline dashes (30 on / 20 off, 0.9 wide), edge lines, aiming-point marks
(45–60 × 6–10) and touchdown-zone stripe pairs, mirrored at the far end for the reciprocal runway.
"""

from __future__ import annotations

import numpy as np

from .airports import Airport, designation

GLYPHS = {
    "0": ("111", "101", "101", "101", "111"),
    "1": ("010", "110", "010", "010", "111"),
    "2": ("111", "001", "111", "100", "111"),
    "3": ("111", "001", "111", "001", "111"),
    "4": ("101", "101", "111", "001", "001"),
    "5": ("111", "100", "111", "001", "111"),
    "6": ("111", "100", "111", "101", "111"),
    "7": ("111", "001", "001", "001", "001"),
    "8": ("111", "101", "111", "101", "111"),
    "9": ("111", "101", "111", "001", "111"),
    "L": ("100", "100", "100", "100", "111"),
    "R": ("110", "101", "110", "101", "101"),
    "C": ("111", "100", "100", "100", "111"),
}

#: Colour of the runway surface in the flat debug layout.
DEBUG_RUNWAY_RGB = (1.0, 1.0, 1.0)


def rect(x0, x1, y0, y1, rgb, alpha=1.0, px=0.0, dx=0.0, py=0.0, dy=0.0) -> list[float]:
    """One layout row (see the module docstring)."""
    return [x0, x1, px, dx, y0, y1, py, dy, *rgb, alpha]


def dashes_x(x0, n, period, dash, y0, y1, rgb, alpha=1.0) -> list[float]:
    """``n`` dashes along x starting at ``x0`` (the extent ends exactly at the last dash)."""
    return rect(x0, x0 + (n - 1) * period + dash, y0, y1, rgb, alpha, px=period, dx=dash)


def dashes_y(y0, n, period, dash, x0, x1, rgb, alpha=1.0) -> list[float]:
    """``n`` stripes along y starting at ``y0`` (the extent ends exactly at the last stripe)."""
    return rect(x0, x1, y0, y0 + (n - 1) * period + dash, rgb, alpha, py=period, dy=dash)


def mirror(rows: list[list[float]], length: float) -> list[list[float]]:
    """The same shapes seen from the other runway end: ``x → L − x``, ``y → −y`` (dash phases preserved)."""
    out = []
    for r in rows:
        x0, x1, px, dx, y0, y1, py, dy, *rest = r
        out.append([length - x1, length - x0, px, dx, -y1, -y0, py, dy, *rest])
    return out


def glyph_rects(text: str, x_bottom: float, y_left: float, cell_x: float, cell_y: float, gap_y: float,
                rgb, alpha) -> list[list[float]]:
    """Blocky glyphs read from the approach (top toward +x, reading direction toward −y)."""
    rows = []
    for k, ch in enumerate(text):
        bitmap = GLYPHS[ch]
        yl = y_left - k * (3 * cell_y + gap_y)
        for r, line in enumerate(bitmap):
            xa = x_bottom + (4 - r) * cell_x
            c = 0
            while c < 3:
                if line[c] == "1":
                    c2 = c
                    while c2 + 1 < 3 and line[c2 + 1] == "1":
                        c2 += 1
                    rows.append(rect(xa, xa + cell_x, yl - (c2 + 1) * cell_y, yl - c * cell_y, rgb, alpha))
                    c = c2 + 1
                else:
                    c += 1
    return rows


def designation_rects(text: str, rgb, alpha: float) -> list[list[float]]:
    """Designation at the near end: optional letter nearer the threshold (from 48 m), then the two digits."""
    digits, letter = text[:2], text[2:]
    cx, cy, gy = 1.8, 1.0, 1.5
    x_text = 48.0
    rows = []
    if letter:
        rows += glyph_rects(letter, x_text, 1.5 * cy, cx, cy, gy, rgb, alpha)
        x_text += 12.0
    rows += glyph_rects(digits, x_text, (6 * cy + gy) / 2, cx, cy, gy, rgb, alpha)
    return rows


def runway_markings(length: float, width: float, text: str, rgb, alpha: float, rng: np.random.Generator,
                    text_far: str) -> list[list[float]]:
    """Painted markings of a runway ``[0, L] × [−W/2, W/2]`` for both ends."""
    h = width / 2.0
    near: list[list[float]] = []
    # piano keys: 1.8 m stripes every 3.6 m, symmetric around a central gap
    per_side = 4 if width < 36 else (6 if width < 52 else 8)
    span = per_side * 3.6 - 1.8
    gap = min(2.0 * (h - 1.5 - span), 6.0)
    near.append(dashes_y(gap / 2, per_side, 3.6, 1.8, 6.0, 36.0, rgb, alpha))
    near.append(dashes_y(-gap / 2 - span, per_side, 3.6, 1.8, 6.0, 36.0, rgb, alpha))
    if rng.random() < 0.3:  # transverse threshold bar
        near.append(rect(0.5, 2.3, -h + 1.0, h - 1.0, rgb, alpha))
    # aiming point and touchdown zone (within the first half of the runway)
    inner = float(rng.uniform(9.0, 11.0)) if width >= 40 else float(rng.uniform(6.0, 8.0))
    aim_w = min(float(rng.uniform(6.0, 10.0)), h - inner - 1.0)
    aim_x = 400.0 if length >= 2400 else 300.0
    aim_len = float(rng.uniform(45.0, 60.0))
    if aim_x + aim_len < length / 2 and aim_w > 1.0:
        for s in (1.0, -1.0):
            near.append(rect(aim_x, aim_x + aim_len, *sorted((s * inner, s * (inner + aim_w))), rgb, alpha))
    n_tdz = min(3, max(1, int((h - inner - 1.0) // 3.3)))
    for x_tdz, n in ((150.0, 3), (450.0, 2), (600.0, 2), (750.0, 1), (900.0, 1)):
        if x_tdz + 22.5 > length / 2 or abs(x_tdz - aim_x) < 70:
            continue
        k = min(n, n_tdz)
        span_t = (k - 1) * 3.3 + 1.8
        near.append(dashes_y(inner, k, 3.3, 1.8, x_tdz, x_tdz + 22.5, rgb, alpha))
        near.append(dashes_y(-inner - span_t, k, 3.3, 1.8, x_tdz, x_tdz + 22.5, rgb, alpha))
    far = mirror(near + designation_rects(text_far, rgb, alpha), length)
    near += designation_rects(text, rgb, alpha)
    # centreline dashes between the designations, edge lines
    n_dash = int((length - 2 * 80.0 - 30.0) // 50.0) + 1
    start = (length - ((n_dash - 1) * 50.0 + 30.0)) / 2
    common = [dashes_x(start, n_dash, 50.0, 30.0, -0.45, 0.45, rgb, alpha)] if n_dash > 0 else []
    ew = 0.9 if width >= 30 else 0.45
    common += [rect(0.0, length, h - ew - 0.3, h - 0.3, rgb, alpha), rect(0.0, length, -h + 0.3, -h + ew + 0.3, rgb, alpha)]
    return near + far + common


def _jitter(rng, rgb, s=0.03):
    return tuple(float(np.clip(c + rng.normal(0, s), 0.0, 1.0)) for c in rgb)


def runway_rows(length: float, width: float, text: str, text_far: str, rng: np.random.Generator,
                y_shift: float = 0.0, x_shift: float = 0.0) -> list[list[float]]:
    """Surface, wear and markings of one runway, shifted by ``(x_shift, y_shift)``."""
    h = width / 2.0
    concrete = rng.random() < 0.25
    base = float(rng.uniform(0.42, 0.58)) if concrete else float(rng.uniform(0.14, 0.30))
    surf = _jitter(rng, (base, base, base * float(rng.uniform(0.97, 1.05))), 0.01)
    rows = []
    if rng.random() < 0.5:  # shoulders
        sw = float(rng.uniform(3.0, 10.0))
        sh = _jitter(rng, tuple(c * float(rng.uniform(0.8, 1.4)) for c in surf), 0.01)
        rows.append(rect(0.0, length, -h - sw, h + sw, sh))
    if rng.random() < 0.35:  # paved area before the threshold (blast pad / stopway)
        pre = float(rng.uniform(30.0, 120.0))
        pc = _jitter(rng, tuple(c * float(rng.uniform(0.8, 1.3)) for c in surf), 0.01)
        rows.append(rect(-pre, 0.0, -h, h, pc))
    rows.append(rect(0.0, length, -h, h, surf))
    for _ in range(int(rng.integers(1, 6))):  # resurfaced patches
        x0 = float(rng.uniform(0.0, length * 0.9))
        rows.append(rect(x0, min(length, x0 + float(rng.uniform(50, 600))), -h, h,
                         tuple(c * float(rng.uniform(0.85, 1.15)) for c in surf)))
    dark = (0.06, 0.06, 0.06)
    for x_start in (250.0, length - 1000.0):  # tyre marks in both touchdown zones (faint, overlapping)
        if x_start < 200.0:
            continue
        for _ in range(4):
            w = float(rng.uniform(0.15, 0.35)) * width
            x0 = x_start + float(rng.uniform(-50, 100))
            rows.append(rect(x0, x0 + float(rng.uniform(300, 700)), -w / 2, w / 2, dark, float(rng.uniform(0.1, 0.25))))
    white = _jitter(rng, (0.9, 0.9, 0.9), 0.02)
    alpha = float(rng.uniform(0.7, 0.97))
    rows += runway_markings(length, width, text, white, alpha, rng, text_far)
    for r in rows:
        r[0] += x_shift
        r[1] += x_shift
        r[4] += y_shift
        r[5] += y_shift
    return rows


def airport_layout(airport: Airport) -> np.ndarray:
    """The layout (N, 12) of ``airport`` in its target runway's frame (fixed per airport)."""
    rng = np.random.default_rng(airport.seed)
    L, W = airport.length_m, airport.width_m
    h = W / 2.0
    rows: list[list[float]] = []
    grass = _jitter(rng, (0.28, 0.36, 0.18) if rng.random() < 0.7 else (0.45, 0.42, 0.28), 0.03)
    ext_l, ext_r = float(rng.uniform(200, 500)), float(rng.uniform(200, 500))
    par = None
    if airport.parallel_side != 0:
        off = float(rng.uniform(250.0, 1000.0)) * airport.parallel_side
        L2, W2 = L * float(rng.uniform(0.6, 1.0)), float(rng.uniform(30.0, 60.0))
        par = (off, L2, W2, float(rng.uniform(-300.0, 500.0)))
        if off > 0:
            ext_l = max(ext_l, off + W2 / 2 + 150)
        else:
            ext_r = max(ext_r, -off + W2 / 2 + 150)
    rows.append(rect(-350.0, L + 350.0, -h - ext_r, h + ext_l, grass, 0.85))
    # parallel taxiway, connectors, apron and buildings on the side without the distractor runway
    side = -airport.parallel_side if airport.parallel_side else (1 if rng.random() < 0.5 else -1)
    ty = side * (h + float(rng.uniform(90.0, 180.0)))
    tw = float(rng.uniform(15.0, 25.0))
    tcol = _jitter(rng, (0.3, 0.3, 0.3) if rng.random() < 0.6 else (0.55, 0.55, 0.53), 0.03)
    rows.append(rect(-60.0, L + 60.0, ty - tw / 2, ty + tw / 2, tcol))
    for xc in np.sort(rng.uniform(0.0, L, int(rng.integers(3, 7)))):
        rows.append(rect(xc - 12.0, xc + 12.0, *sorted((side * h, ty)), tcol))
    yellow = (0.75, 0.62, 0.15)
    rows.append(rect(-60.0, L + 60.0, ty - 0.15, ty + 0.15, yellow, 0.8))
    ax0 = float(rng.uniform(0.0, max(1.0, L - 700.0)))
    ax1 = ax0 + float(rng.uniform(200.0, 700.0))
    a_in = ty + side * (tw / 2 + 20.0)
    a_out = a_in + side * float(rng.uniform(100.0, 250.0))
    acol = _jitter(rng, (0.55, 0.55, 0.53), 0.04)
    rows.append(rect(ax0, ax1, *sorted((a_in, a_out)), acol))
    b_in = a_out + side * 15.0
    for _ in range(int(rng.integers(2, 6))):
        bx = float(rng.uniform(ax0 - 200.0, ax1 + 200.0))
        bl, bw = float(rng.uniform(30.0, 150.0)), float(rng.uniform(20.0, 80.0))
        roof = _jitter(rng, [(0.6, 0.6, 0.62), (0.75, 0.75, 0.78), (0.35, 0.45, 0.55), (0.5, 0.3, 0.25)][int(rng.integers(4))])
        y_far = b_in + side * bw
        rows.append(rect(bx, bx + bl, *sorted((b_in, y_far)), roof))
    if rng.random() < 0.6:  # approach light barrettes and a cross bar
        lc = (0.5, 0.5, 0.5)
        rows.append(dashes_x(-900.0, 30, 30.0, 0.8, -2.0, 2.0, lc, 0.6))
        rows.append(rect(-300.8, -300.0, -15.0, 15.0, lc, 0.6))
    if par is not None:
        off, L2, W2, xs = par
        az2 = airport.azimuth_deg
        letter2 = "L" if airport.parallel_side > 0 else "R"
        rows += runway_rows(L2, W2, designation(az2, letter2), designation(az2 + 180.0, {"L": "R", "R": "L"}[letter2]),
                            rng, y_shift=off, x_shift=xs)
    letter = airport.runway[2:]
    rows += runway_rows(L, W, airport.runway, designation(airport.azimuth_deg + 180.0, {"L": "R", "R": "L", "": ""}[letter]), rng)
    return np.asarray(rows, dtype=np.float64)


def debug_layout(length: float, width: float) -> np.ndarray:
    """Only the runway surface ``[0, L] × [−W/2, W/2]`` in :data:`DEBUG_RUNWAY_RGB` (pixel-exactness checks)."""
    return np.asarray([rect(0.0, length, -width / 2, width / 2, DEBUG_RUNWAY_RGB)], dtype=np.float64)


def _measure(t: np.ndarray, lo: float, hi: float, period: float, dash: float) -> np.ndarray:
    """Length of ``(−∞, t] ∩ [lo, hi] ∩ dashes`` (dashes of ``dash`` every ``period`` from ``lo``; 0 = solid)."""
    t = np.clip(t, lo, hi) - lo
    if period <= 0.0:
        return t
    return np.floor(t / period) * dash + np.minimum(np.mod(t, period), dash)


def _ends(origin: float, step: float, n: int, lo: np.ndarray, hi: np.ndarray):
    """For intervals ``[lo, hi]`` (arrays): first and past-the-last texel they touch (texel ``k`` is centred at
    ``origin + k·step``, clipped to ``[0, n)``) and the covered fractions of those two end texels."""
    k0 = np.maximum(np.floor((lo - origin) / step + 0.5), 0.0)
    k1 = np.minimum(np.ceil((hi - origin) / step + 0.5), n)
    e0 = origin + (k0 - 0.5) * step  # lower edges of the end texels
    e1 = origin + (k1 - 1.5) * step
    c0 = np.clip((np.minimum(e0 + step, hi) - np.maximum(e0, lo)) / step, 0.0, 1.0)
    c1 = np.clip((np.minimum(e1 + step, hi) - np.maximum(e1, lo)) / step, 0.0, 1.0)
    return k0.astype(np.int64).tolist(), k1.astype(np.int64).tolist(), c0.tolist(), c1.tolist()


def _coverage(k0: int, k1: int, c0: float, c1: float, origin: float, step: float, lo: float, hi: float,
              period: float, dash: float) -> np.ndarray:
    """Exact covered fraction (k1 − k0,) of texels ``k0 … k1 − 1`` by the 1-D pattern (see :func:`_ends`)."""
    if period <= 0.0:  # solid: only the end texels are partly covered
        cov = np.ones(k1 - k0, np.float32)
        cov[-1] = c1
        cov[0] = c0
        return cov
    edges = origin + (np.arange(k0, k1 + 1) - 0.5) * step
    m = _measure(edges, lo, hi, period, dash)
    return (np.diff(m) / step).astype(np.float32)


#: Rectangles with more texels than this get their fully covered interior painted without a coverage array.
_BIG = 4096


def _blend(sub: np.ndarray, colour: np.ndarray, cy: np.ndarray, cx: np.ndarray) -> None:
    """``sub ← sub + (colour − sub)·(cy ⊗ cx)`` in place (cy already holds the row's opacity).

    Works on the (rows, columns·channels) view of ``sub``: numpy is slow on broadcasts whose inner loop is a
    single pixel's channels.
    """
    ch = colour.size
    flat = sub.reshape(sub.shape[0], -1)
    d = np.tile(colour, sub.shape[1]) - flat
    d *= np.multiply.outer(cy, np.repeat(cx, ch))
    flat += d


#: A run of same-paint rows is painted as one shape when its box has at most this many texels per row.
_GROUP_TEXELS_PER_ROW = 2048


def paint(tile: np.ndarray, origin_x: float, origin_y: float, sx: float, sy: float, rows: np.ndarray,
          gain=(1.0, 1.0, 1.0), blank: bool = False) -> None:
    """Paint layout rows into ``tile`` (ny, nx, 3 or 4) float32 in place, with exact area coverage.

    Texel ``(i, j)`` is the ground cell centred at ``(origin_x + j·sx, origin_y + i·sy)`` of size ``sx × sy``.
    A 4-channel tile is premultiplied RGBA (painting over a transparent tile gives each texel's coverage in A).
    Colours are multiplied by ``gain`` (RGB; the light of the frame), opacities are not.

    Consecutive rows of the same colour and opacity (the markings of a runway, say) are one shape: they are meant
    to be disjoint, so their coverages add (clipped at 1) before the shape is laid over the tile once.
    ``blank=True`` promises that ``tile`` is all zeros (the first shape is then written rather than blended).
    """
    ny, nx = tile.shape[:2]
    ch = tile.shape[2]
    xa, xb = origin_x - sx / 2, origin_x + (nx - 0.5) * sx
    ya, yb = origin_y - sy / 2, origin_y + (ny - 0.5) * sy
    rows = rows[(rows[:, 1] > xa) & (rows[:, 0] < xb) & (rows[:, 5] > ya) & (rows[:, 4] < yb)]
    if not len(rows):
        return
    j0s, j1s, cx0s, cx1s = _ends(origin_x, sx, nx, rows[:, 0], rows[:, 1])
    i0s, i1s, cy0s, cy1s = _ends(origin_y, sy, ny, rows[:, 4], rows[:, 5])
    colours = np.ones((len(rows), 4), np.float32)
    colours[:, :3] = rows[:, 8:11] * np.asarray(gain, np.float64)
    colours = colours[:, :ch]
    live = [n for n in range(len(rows)) if j1s[n] > j0s[n] and i1s[n] > i0s[n]]
    paints = rows[:, 8:12].tolist()
    items = rows.tolist()

    def cov(n):
        x0, x1, px, dx, y0, y1, py, dy = items[n][:8]
        return (_coverage(i0s[n], i1s[n], cy0s[n], cy1s[n], origin_y, sy, y0, y1, py, dy),
                _coverage(j0s[n], j1s[n], cx0s[n], cx1s[n], origin_x, sx, x0, x1, px, dx))

    start = 0
    while start < len(live):
        end = start + 1
        while end < len(live) and paints[live[end]] == paints[live[start]]:
            end += 1
        run = live[start:end]
        start = end
        a = paints[run[0]][3]
        colour = colours[run[0]]
        if len(run) > 1:
            i0, i1 = min(i0s[n] for n in run), max(i1s[n] for n in run)
            j0, j1 = min(j0s[n] for n in run), max(j1s[n] for n in run)
            if (i1 - i0) * (j1 - j0) <= _GROUP_TEXELS_PER_ROW * len(run):
                acc = np.zeros((i1 - i0, j1 - j0), np.float32)
                for n in run:
                    cy, cx = cov(n)
                    acc[i0s[n] - i0:i1s[n] - i0, j0s[n] - j0:j1s[n] - j0] += np.multiply.outer(cy, cx)
                np.minimum(acc, 1.0, out=acc)
                acc *= np.float32(a)
                flat = tile[i0:i1, j0:j1].reshape(i1 - i0, -1)  # (rows, columns·channels), see _blend
                d = np.tile(colour, j1 - j0) - flat
                d *= np.repeat(acc, ch, axis=1)
                flat += d
                blank = False
                continue
        for n in run:
            _paint_row(tile, colour, a, i0s[n], i1s[n], j0s[n], j1s[n], *cov(n), items[n][2] > 0 or items[n][6] > 0,
                       blank)
            blank = False


def _paint_row(tile, colour, a, i0, i1, j0, j1, cy, cx, dashed: bool, blank: bool = False) -> None:
    """Lay one row's shape (coverage ``cy ⊗ cx`` on texels ``[i0, i1) × [j0, j1)``, opacity ``a``) over ``tile``."""
    cy *= np.float32(a)
    if dashed or (i1 - i0) * (j1 - j0) < _BIG or min(i1 - i0, j1 - j0) < 3:
        _blend(tile[i0:i1, j0:j1], colour, cy, cx)
        return
    # solid and large: the interior (all but the end rows and columns) is covered with opacity a exactly
    fi0, fi1, fj0, fj1 = i0 + 1, i1 - 1, j0 + 1, j1 - 1
    inner = tile[fi0:fi1, fj0:fj1].reshape(fi1 - fi0, -1)  # (rows, columns·channels) view, see _blend
    if a >= 1.0 or blank:  # (over a blank tile, blending is writing)
        inner[:] = np.tile(colour * np.float32(min(a, 1.0)), fj1 - fj0)
    else:
        inner *= np.float32(1.0 - a)
        inner += np.tile(colour * np.float32(a), fj1 - fj0)
    for ra, rb, ca, cb in ((i0, fi0, j0, j1), (fi1, i1, j0, j1), (fi0, fi1, j0, fj0), (fi0, fi1, fj1, j1)):
        _blend(tile[ra:rb, ca:cb], colour, cy[ra - i0:rb - i0], cx[ca - j0:cb - j0])
