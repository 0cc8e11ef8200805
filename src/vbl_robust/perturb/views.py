"""Square views of an image, and of a perturbed image ``T(x; θ)`` sampled straight from the unperturbed ``x``.

A *view* is a square window ``(x0, y0, side)`` in **edge coordinates** of the image (0 at the left/top edge of
the image; an OpenCV pixel centre ``u`` is at ``u + 0.5``, see :mod:`vbl_robust.data.yolo`), resampled to
``size × size`` pixels. Parts of a window outside the image are filled with grey 114/255 (ultralytics' letterbox
colour). Which windows a detector needs (the letterbox, crops around corners) is the detector's business
(:mod:`vbl_robust.detect.windows`); how the pixels of a window are produced lives here.

Mapping between a view pixel (edge coordinates ``p`` in ``[0, size]``) and the image::

    image_edge = (x0, y0) + p · side / size

Resampling: bilinear ``grid_sample`` (``align_corners=False``, which samples the exact view-pixel centres).
When a window shrinks the image by ``k = side / size ≥ 2``, the image is first average-pooled by ``⌊k⌋`` (an
anti-aliasing prefilter; pooled pixel ``j`` covers image edge coordinates ``[j·p, (j+1)·p)``, so the mapping
above still holds). Everything is differentiable with respect to the image and the window. The black box on
the CPU (a NumPy θ) samples the same views with OpenCV instead (:mod:`.warp`: bilinear at the exact map, no
gradient, a small fraction of the cost).

:class:`ViewSampler` is the one boundary between a perturbation and a detector: built from the unperturbed image,
a :class:`~vbl_robust.perturb.compose.Perturbation` and a batch θ, it gives the views of ``T(x; θ)`` a detector asks for
and moves points as the perturbation moves the image content.
"""

from __future__ import annotations

import weakref

import numpy as np
import torch
import torch.nn.functional as F

from .warp import PooledSource, empty_output, grid_matrix, warp_view

PAD_VALUE = 114.0 / 255.0


def pool_factor(side: float, size: int) -> int:
    """Average-pooling factor applied before resampling a window of ``side`` image pixels to ``size``."""
    k = side / size
    return int(k) if k >= 2.0 else 1


def resample(images: torch.Tensor, windows: torch.Tensor, size: int) -> torch.Tensor:
    """Resample square windows of images to ``size × size``.

    Args:
        images: (B, 3, H, W) float in [0, 1] (RGB).
        windows: (B, 3) ``(x0, y0, side)`` in image edge coordinates, or (3,) broadcast to the batch.
        size: output side in pixels.

    Returns:
        (B, 3, size, size) float; outside the image: grey 114/255. Differentiable w.r.t. images and windows.
    """
    if images.ndim != 4:
        raise ValueError(f"resample: images must be (B, 3, H, W), got {tuple(images.shape)}")
    b, _, h, w = images.shape
    windows = torch.as_tensor(windows, dtype=images.dtype, device=images.device)
    if windows.ndim == 1:
        windows = windows.expand(b, 3)
    shifted = _integer_shift(images, windows, size)
    if shifted is not None:
        return shifted
    out = torch.empty(b, images.shape[1], size, size, dtype=images.dtype, device=images.device)
    t = (torch.arange(size, dtype=images.dtype, device=images.device) + 0.5) / size  # view-pixel centres in [0, 1]
    for p, idx in _pool_groups(windows, size):
        src = images[idx]
        if p > 1:
            src = F.avg_pool2d(src, p, stride=p)
        hp, wp = src.shape[-2:]
        win = windows[idx]
        # image edge coordinate of each view pixel centre, then normalised by the (pooled) source extent
        xs = win[:, 0:1] + t[None, :] * win[:, 2:3]  # (n, size)
        ys = win[:, 1:2] + t[None, :] * win[:, 2:3]
        gx = 2.0 * xs / (wp * p) - 1.0
        gy = 2.0 * ys / (hp * p) - 1.0
        grid = torch.stack(torch.broadcast_tensors(gx[:, None, :], gy[:, :, None]), dim=-1)  # (n, size, size, 2)
        ones = torch.ones_like(src[:, :1])
        sampled = F.grid_sample(torch.cat([src, ones], 1), grid, mode="bilinear", padding_mode="zeros",
                                align_corners=False)
        mask = sampled[:, -1:]
        out[idx] = sampled[:, :-1] + PAD_VALUE * (1.0 - mask)
    return out


def _integer_shift(images: torch.Tensor, windows: torch.Tensor, size: int) -> torch.Tensor | None:
    """The views as a pixel copy when one window of side ``size`` at integer offsets serves every image, else None.

    Then each view pixel centre lands on an image pixel centre and bilinear sampling is a copy: this is the
    letterbox of an image already at the detector's input size (the single-pass objective perturbs at that
    size), where ``grid_sample`` would cost as much as a tenth of the detector's forward pass. Not taken when the
    windows need a gradient (the copy has none with respect to the window).
    """
    if windows.requires_grad or windows.shape[0] == 0:
        return None
    w0 = windows[0]
    if not bool((windows == w0).all()) or float(w0[2]) != size:
        return None
    x0, y0 = float(w0[0]), float(w0[1])
    if x0 != int(x0) or y0 != int(y0):
        return None
    x0, y0 = int(x0), int(y0)
    h, w = images.shape[-2:]
    if x0 == 0 and y0 == 0 and h == w == size:
        return images  # the view is the image (read only downstream)
    out = images.new_full((images.shape[0], images.shape[1], size, size), PAD_VALUE)
    # view rows/cols [a, b) ← image rows/cols [a + offset, b + offset), clipped to the image
    r0, r1 = max(0, -y0), min(size, h - y0)
    c0, c1 = max(0, -x0), min(size, w - x0)
    if r1 > r0 and c1 > c0:
        out[:, :, r0:r1, c0:c1] = images[:, :, r0 + y0:r1 + y0, c0 + x0:c1 + x0]
    return out


def _pool_groups(windows: torch.Tensor, size: int, device=None):
    """``(p, rows)`` for each pooling factor ``p`` among the windows (B, 3), rows as an index tensor on ``device``
    (default: the windows')."""
    factors = [pool_factor(float(s), size) for s in windows[:, 2].detach().cpu().tolist()]
    for p in sorted(set(factors)):
        yield p, torch.tensor([i for i, f in enumerate(factors) if f == p], device=device or windows.device)


def pooled_source(image: torch.Tensor, p: int, cache: dict[int, torch.Tensor]) -> torch.Tensor:
    """``avg_pool(image, p)`` (``image`` itself for p = 1), computed once per factor in ``cache``."""
    if p not in cache:
        cache[p] = F.avg_pool2d(image, p, stride=p) if p > 1 else image
    return cache[p]


#: id(source) -> (a weak reference to it, its version counter when cached, its pooled copies)
_POOLED: dict[int, tuple[weakref.ref, int, dict]] = {}


def source_cache(image: torch.Tensor) -> dict:
    """The pooled copies of ``image`` (by factor: tensors; by ``("planes", factor)``: contiguous NumPy planes), kept while ``image`` lives and is not written to (its version
    counter): the objective makes a sampler per chunk of θ from one source tensor, and pooling a full-resolution
    frame costs as much as sampling a few views. Keyed by the tensor object the caller holds (a reshaped view of
    it is a new object). A source that requires a gradient gets a fresh dict (no graph is
    kept across calls)."""
    if image.requires_grad:
        return {}
    key = id(image)
    hit = _POOLED.get(key)
    if hit is None or hit[0]() is not image or hit[1] != image._version:
        hit = (weakref.ref(image, lambda ref, k=key, cache=_POOLED: _forget(cache, k, ref)), image._version, {})
        _POOLED[key] = hit
    return hit[2]


def _forget(cache: dict, key: int, ref: weakref.ref) -> None:
    if cache.get(key, (None,))[0] is ref:
        del cache[key]


def view_to_image(points: torch.Tensor, windows: torch.Tensor, size: int) -> torch.Tensor:
    """View-pixel edge coordinates (B, N, 2) → image **OpenCV** pixel coordinates (B, N, 2)."""
    windows = torch.as_tensor(windows, dtype=points.dtype, device=points.device)
    if windows.ndim == 1:
        windows = windows.expand(points.shape[0], 3)
    return windows[:, None, :2] + points * (windows[:, None, 2:3] / size) - 0.5


def image_to_view(uv: np.ndarray, window: tuple[float, float, float], size: int) -> np.ndarray:
    """Image OpenCV pixel coordinates (N, 2) → view-pixel **OpenCV** coordinates (N, 2) (for label export)."""
    x0, y0, side = window
    return (np.asarray(uv, dtype=np.float64) + 0.5 - [x0, y0]) * (size / side) - 0.5


def to_tensor(images: np.ndarray | torch.Tensor) -> torch.Tensor:
    """(H, W, 3) or (B, H, W, 3) uint8 RGB, or a float (B, 3, H, W) tensor → float32 (B, 3, H, W) in [0, 1]."""
    if isinstance(images, torch.Tensor) and images.is_floating_point():
        return images if images.ndim == 4 else images[None]
    a = torch.as_tensor(np.asarray(images))
    if a.ndim == 3:
        a = a[None]
    if a.ndim != 4 or a.shape[-1] != 3:
        raise ValueError(f"to_tensor: expected (H, W, 3) or (B, H, W, 3) RGB, got {tuple(a.shape)}")
    return a.permute(0, 3, 1, 2).float().div_(255.0)


# -- views of a perturbed image -----------------------------------------------------------------------------------
def reflect101(u: torch.Tensor, n: int) -> torch.Tensor:
    """Reflect OpenCV pixel coordinates into ``[0, n − 1]`` without repeating the border (``BORDER_REFLECT_101``).

    Bilinear interpolation at a reflected coordinate equals OpenCV's bilinear interpolation with that border.
    """
    if n < 2:
        return torch.zeros_like(u)
    period = 2.0 * (n - 1)
    return (n - 1) - (torch.remainder(u, period) - (n - 1)).abs()


#: Photometric statistics of a perturbed frame (the grey mean of the contrast) are estimated on a
#: ``STATS_GRID × STATS_GRID`` grid of view-pixel centres over the frame, sampled from the source average-pooled
#: as for a view of side :data:`STATS_VIEW_SIDE` (anti-aliasing; the first-pass view of the shipped detector).
STATS_GRID = 128
STATS_VIEW_SIDE = 320


class ViewSampler:
    """Views of the perturbed images ``T(x; θ_i)``, one per row of θ, sampled from the unperturbed image.

    Args:
        perturbation: the :class:`~vbl_robust.perturb.compose.Perturbation` (parameter names of the box).
        image: ``(1, 3, H, W)`` or ``(3, H, W)`` unperturbed image, float in [0, 1] (the *source*: the sample's
            image, possibly resized to the detector's input size — see ``scale``).
        theta: ``(N, d)`` parameters in real units, NumPy (black box) or a tensor (differentiable w.r.t. θ).
        center: ``(2,)`` principal point in source pixels (the centre of camera rotations); ``None``: ``K``'s,
            else ``(W/2, H/2)``.
        K: ``(3, 3)`` pinhole matrix in source pixels (the sample's ``K`` through
            :meth:`PixelScale.intrinsics <vbl_robust.perturb.resample.PixelScale.intrinsics>`); required by the attitude
            homography (``pitch_deg``, ``yaw_deg``).
        scale: the :class:`~vbl_robust.perturb.resample.PixelScale` from the sample's pixels to the source's (blur lengths
            and the noise grid are in the sample's pixels); ``None`` = identity.
        frame: optionally the source as an ``(H, W, 3)`` float32 NumPy array (the OpenCV path reads it).

    Two ways to make a view, chosen by the windows asked for and the families, never by the caller:

    - **frame first** — every window has the side of the view (no scaling: e.g. the letterbox of a source that
      is already at the detector's input size), *or* the box has an optical or noise family: ``T(x; θ)`` is
      rendered once at the source resolution (OpenCV for a NumPy θ, kornia for a tensor θ) and the views are
      copied/resampled from it;
    - **direct** — otherwise (a downsampling letterbox, crops): every view pixel reads the source at the
      perturbation's inverse map (geometric families), then the pointwise photometric families apply — one
      interpolation, no full-resolution warp (the views agree with frame first to interpolation smoothing;
      tested for every family).

    Why the optical and noise families force frame first: a blur is a convolution of the *perturbed* frame at
    the source resolution — it needs each pixel's neighbourhood there, which a view sample does not have (a
    blurred source would be wrong as soon as the geometry rotates the motion-blur direction, and a blur in view
    pixels after the anti-aliasing pool is a different kernel); it costs one full-resolution pass per row anyway,
    so rendering the frame first costs about as much as any alternative. The noise pattern lives on the sensor's
    pixel grid and is clamped there; resampling commutes with the addition but not with the clamp. Rendering
    frames first keeps every view exactly a crop of ``T(x; θ)``; ``strategy="direct"`` is refused for them.

    Both are differentiable for a tensor θ. ``views`` is all a detector needs; :meth:`points` moves
    points like the image content (for the oracle and for crop geometry).

    Kernels of the direct strategy: torch (``grid_sample``) for a tensor θ and on an accelerator; for a NumPy θ on
    the CPU (the black box), one OpenCV warp per view plane at the exact map (:mod:`.warp`) when the geometry is one
    homography per θ — the same views up to the torch kernel's float32 rounding, at a small fraction of its cost.
    """

    #: the black-box path on the CPU samples with OpenCV (:mod:`.warp`); False: with torch, like the differentiable
    #: path (for comparisons)
    opencv: bool = True

    def __init__(self, perturbation, image, theta, center=None, *, K=None, scale=None,
                 frame: np.ndarray | None = None) -> None:
        x = to_tensor(image)
        if x.shape[0] != 1:
            raise ValueError(f"ViewSampler: one source image expected, got a batch of {x.shape[0]}")
        self.perturbation = perturbation
        self.source = x  # its device is where the views are made (``Objective(device=...)``)
        self.theta = perturbation.check_theta(theta)
        self._theta_t: torch.Tensor | None = None
        self.K = None if K is None else np.asarray(K, dtype=np.float64)
        if center is None:
            center = self.K[:2, 2] if self.K is not None else (x.shape[-1] / 2.0, x.shape[-2] / 2.0)
        self.center = np.asarray(center, dtype=np.float64)
        perturbation._camera(self.center, self.K)  # ValueError now, not at the first view
        self.scale = scale
        self._frame_np = frame
        self._frames: torch.Tensor | None = None
        self._pooled = source_cache(image) if isinstance(image, torch.Tensor) else {}
        self._stats = None
        self._matrices: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.theta.shape[0])

    @property
    def differentiable(self) -> bool:
        return isinstance(self.theta, torch.Tensor)

    @property
    def height(self) -> int:
        return int(self.source.shape[-2])

    @property
    def width(self) -> int:
        return int(self.source.shape[-1])

    @property
    def device(self) -> torch.device:
        return self.source.device

    def theta_tensor(self, dtype=torch.float64) -> torch.Tensor:
        t = self.theta
        return t if isinstance(t, torch.Tensor) else torch.as_tensor(t, dtype=dtype)

    def _theta_on_device(self) -> torch.Tensor:
        """θ as a tensor on the source's device (differentiable w.r.t. a tensor θ; float64 for a NumPy θ)."""
        if self._theta_t is None:
            self._theta_t = self.theta_tensor().to(self.device)
        return self._theta_t

    # -- what detectors call -----------------------------------------------------------------------------------
    def frames(self) -> torch.Tensor:
        """``(N, 3, H, W)`` the whole perturbed images at the source resolution (rendered once)."""
        if self._frames is None:
            if self.differentiable:
                self._frames = self.perturbation.images_torch(self.source, self.theta, center=self.center, K=self.K,
                                                              scale=self.scale)
            else:
                base = self._frame_np
                if base is None:
                    base = self.source[0].permute(1, 2, 0).contiguous().cpu().numpy()
                imgs = self.perturbation.images_numpy(base, self.theta, center=self.center, K=self.K,
                                                      scale=self.scale, channels_first=True)
                self._frames = torch.from_numpy(imgs).to(self.device)  # one transfer to an accelerator
        return self._frames

    def views(self, windows, size: int, *, strategy: str = "auto") -> torch.Tensor:
        """``(N, 3, size, size)`` views of the perturbed images; ``windows`` ``(N, 3)`` or ``(3,)`` edge coordinates
        of the source (see the module docstring). Differentiable w.r.t. θ and the windows.

        ``strategy``: ``"auto"`` (frame first when every window has side ``size`` or the box has an optical or
        noise family, else direct), ``"frame"`` or ``"direct"`` (for comparisons; refused for optical and noise
        families, see the class docstring).
        """
        if strategy not in ("auto", "frame", "direct"):
            raise ValueError(f"ViewSampler.views: strategy must be 'auto', 'frame' or 'direct', got {strategy!r}")
        framed = self.perturbation.needs_frame
        if strategy == "direct" and framed:
            raise ValueError(f"ViewSampler.views: strategy 'direct' cannot apply {self.perturbation!r}: its optical "
                             "or noise families act on whole frames (use 'auto' or 'frame')")
        n = len(self)
        w = torch.as_tensor(windows, dtype=self.source.dtype)
        if w.ndim == 1:
            w = w.expand(n, 3)
        if w.shape != (n, 3):
            raise ValueError(f"ViewSampler.views: windows must be (3,) or ({n}, 3), got {tuple(w.shape)}")
        host = w.detach().cpu()  # the choices below read the window sizes: on the host, once
        w = w.to(self.device)
        if strategy == "frame" or (strategy == "auto" and (framed or (n and bool((host[:, 2] == size).all())))):
            return resample(self.frames(), w, size)
        return self._direct(w, size, host)

    def points(self, points):
        """Source pixels ``(P, 2)`` → where the perturbation moves them, ``(N, P, 2)`` source pixels (a tensor θ
        gives a tensor differentiable w.r.t. θ)."""
        return self.perturbation.points(points, self.theta, center=self.center, K=self.K)

    # -- direct sampling ---------------------------------------------------------------------------------------
    def _pooled_source(self, p: int) -> torch.Tensor:
        return pooled_source(self.source, p, self._pooled)

    def _sample(self, xs: torch.Tensor, ys: torch.Tensor, p: int, rows: torch.Tensor):
        """Geometric families only: the perturbed images at edge coordinates ``xs (b, nx)`` × ``ys (b, ny)`` for θ
        rows ``rows``, read from the source pooled by ``p``. Returns ``(values (b, 3, ny, nx), mask (b, 1, ny,
        nx))``; mask = the fraction of each sample inside the frame (as :func:`resample`'s ones channel)."""
        src = self._pooled_source(p)
        b = xs.shape[0]
        hp, wp = src.shape[-2:]
        qu = (xs - 0.5)[:, None, :].expand(b, ys.shape[1], xs.shape[1])  # OpenCV coordinates, perturbed image
        qv = (ys - 0.5)[:, :, None].expand(b, ys.shape[1], xs.shape[1])
        mu, mv = (qu + 0.5) / p - 0.5, (qv + 0.5) / p - 0.5
        mask = (1.0 + mu).clamp(0, 1) * (wp - mu).clamp(0, 1) * (1.0 + mv).clamp(0, 1) * (hp - mv).clamp(0, 1)
        theta = self._theta_on_device()
        theta = theta[rows] if len(rows) != len(self) else theta
        center = torch.as_tensor(self.center, dtype=xs.dtype, device=xs.device)
        K = None if self.K is None else torch.as_tensor(self.K, dtype=xs.dtype, device=xs.device)
        su, sv = self.perturbation.source_coords(qu, qv, theta, center, K)
        su, sv = reflect101(su, self.width), reflect101(sv, self.height)
        grid = torch.stack([2.0 * ((su + 0.5) / p) / wp - 1.0, 2.0 * ((sv + 0.5) / p) / hp - 1.0], dim=-1)
        grid = grid.to(src.dtype)
        ny, nx = grid.shape[1:3]
        # one source for the whole batch: stack the grids instead of copying the source
        out = F.grid_sample(src, grid.reshape(1, b * ny, nx, 2), mode="bilinear", padding_mode="border",
                            align_corners=False)
        out = out.reshape(src.shape[1], b, ny, nx).transpose(0, 1)
        return out, mask[:, None].to(src.dtype)

    def stats(self):
        """Photometric statistics of the geometrically perturbed frames (see :data:`STATS_GRID`)."""
        if self._stats is None:
            n, dtype = len(self), self.source.dtype
            p = pool_factor(float(max(self.height, self.width)), STATS_VIEW_SIDE)
            values = None
            if self._opencv():
                zero = np.zeros(n)
                values = self._warp(grid_matrix(zero, zero, self.width / STATS_GRID, self.height / STATS_GRID),
                                    [p] * n, (STATS_GRID, STATS_GRID))
            if values is None:
                t = (torch.arange(STATS_GRID, dtype=dtype, device=self.device) + 0.5) / STATS_GRID
                xs, ys = (t * self.width).expand(n, STATS_GRID), (t * self.height).expand(n, STATS_GRID)
                values, _ = self._sample(xs, ys, p, torch.arange(n, device=self.device))
            self._stats = self.perturbation.photometric_stats(values)
        return self._stats

    # -- the OpenCV kernel (:mod:`.warp`) ------------------------------------------------------------------------
    def _opencv(self) -> bool:
        """True when views are warped with OpenCV: a NumPy θ, a float32 source on the CPU, a homography per θ."""
        if not (self.opencv and not self.differentiable and self.device.type == "cpu"
                and self.source.dtype == torch.float32):
            return False
        if self._matrices is None:
            m = self.perturbation.source_matrices(self.theta, self.center, self.K)
            self._matrices = np.zeros(0) if m is None else m
        return self._matrices.size > 0

    def _pooled_cv(self, p: int) -> PooledSource:
        """The source pooled by ``p`` as OpenCV reads it (cached with the source)."""
        key = ("opencv", p)
        if key not in self._pooled:
            planes = np.ascontiguousarray(self._pooled_source(p)[0].numpy())
            self._pooled[key] = PooledSource(planes, p, self.width, self.height)
        return self._pooled[key]

    def _warp(self, q: np.ndarray, pools: list[int], size: tuple[int, int], finish=None) -> torch.Tensor | None:
        """``(N, C, ny, nx)`` samples of the geometrically perturbed frames on the grids ``q`` (N, 3, 3) (view pixel →
        frame, :func:`~vbl_robust.perturb.warp.grid_matrix`) of ``size = (nx, ny)`` pixels, row ``b`` from the source
        pooled by ``pools[b]`` and then handed to ``finish(b, view (1, C, ny, nx))`` (in place, while the view is in
        the cache); None when some sample lies behind the camera (the torch path then takes the request)."""
        h = self._matrices @ q
        nx, ny = size
        out = empty_output(len(self), self.source.shape[1], ny, nx, dtype=self.source.dtype)
        o, scratch = out.numpy(), np.empty((ny, nx, 4), np.float32)
        for b, p in enumerate(pools):
            if not warp_view(self._pooled_cv(p), h[b], o[b], scratch):
                return None
            if finish is not None:
                finish(b, out[b:b + 1])
        return out

    def _photometric_(self, b: int, view: torch.Tensor, stats) -> None:
        """The photometric families on row ``b``'s view ``(1, C, …)`` with its statistics ``(1,)``, in place."""
        if self.perturbation.has_photometric:
            self.perturbation.photometric_torch(view, self._theta_on_device()[b:b + 1], stats, inplace=True)

    def _direct_opencv(self, host: torch.Tensor, size: int) -> torch.Tensor | None:
        win = host.to(torch.float64).numpy()
        step = win[:, 2] / size
        pools = [pool_factor(float(s), size) for s in win[:, 2]]
        stats = self.stats() if self.perturbation.needs_stats else None
        p = np.array(pools, dtype=np.float64)  # the part of each view outside the frame: grey (separable in x, y)
        fx = _inside_fraction(win[:, 0], step, size, p, self.width // p)
        fy = _inside_fraction(win[:, 1], step, size, p, self.height // p)
        padded = (fx < 1.0).any(axis=1) | (fy < 1.0).any(axis=1)

        def finish(b: int, view: torch.Tensor) -> None:
            self._photometric_(b, view, None if stats is None else stats[b:b + 1])
            if padded[b]:
                _pad_outside(view[0].numpy(), fx[b], fy[b])

        return self._warp(grid_matrix(win[:, 0], win[:, 1], step, step), pools, (size, size), finish)

    def _direct(self, windows: torch.Tensor, size: int, host: torch.Tensor) -> torch.Tensor:
        if self._opencv():
            out = self._direct_opencv(host, size)
            if out is not None:
                return out
        n, dtype = len(self), self.source.dtype
        out = torch.empty(n, self.source.shape[1], size, size, dtype=dtype, device=self.device)
        t = (torch.arange(size, dtype=dtype, device=self.device) + 0.5) / size
        photometric, needs_stats = self.perturbation.has_photometric, self.perturbation.needs_stats
        for p, idx in _pool_groups(host, size, self.device):
            win = windows[idx]
            xs = win[:, 0:1] + t[None, :] * win[:, 2:3]
            ys = win[:, 1:2] + t[None, :] * win[:, 2:3]
            v, mask = self._sample(xs, ys, p, idx)
            if photometric:
                theta = self._theta_on_device()
                v = self.perturbation.photometric_torch(v, theta[idx] if len(idx) != n else theta,
                                                        self.stats()[idx] if needs_stats else None)
            out[idx] = v * mask + PAD_VALUE * (1.0 - mask)
        return out


def _inside_fraction(x0: np.ndarray, step: np.ndarray, size: int, p: np.ndarray, pooled: np.ndarray) -> np.ndarray:
    """``(N, size)`` float32: the fraction of each view pixel's sample inside the frame along one axis, for views
    starting at edge coordinates ``x0`` ``(N,)`` with pixel steps ``step``, read from sources pooled by ``p`` to
    ``pooled`` pixels (the ``mask`` of :meth:`ViewSampler._sample`, which is separable): 1 inside, falling to 0
    over one pooled pixel outside."""
    m = (x0[:, None] + (np.arange(size) + 0.5) * step[:, None]) / p[:, None] - 0.5  # pooled OpenCV coordinates
    return (np.clip(1.0 + m, 0.0, 1.0) * np.clip(pooled[:, None] - m, 0.0, 1.0)).astype(np.float32)


def _pad_outside(view: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> None:
    """Blend a view ``(C, ny, nx)`` with the grey pad where its samples lie (partly) outside the frame, in place:
    ``v · f + PAD · (1 − f)`` with ``f = fy ⊗ fx``, computed only on the rows and columns where ``f < 1``."""
    rows, cols = np.flatnonzero(fy < 1.0), np.flatnonzero(fx < 1.0)
    if rows.size:
        f = fy[rows, None] * fx[None, :]
        view[:, rows, :] = view[:, rows, :] * f + np.float32(PAD_VALUE) * (1.0 - f)
    if cols.size:
        keep = np.flatnonzero(fy >= 1.0)[:, None]
        f = fx[None, cols]
        view[:, keep, cols] = view[:, keep, cols] * f + np.float32(PAD_VALUE) * (1.0 - f)
