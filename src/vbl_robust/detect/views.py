"""Square views of an image: letterbox and crops, resampled differentiably to a detector's input size.

A *view* is a square window ``(x0, y0, side)`` in **edge coordinates** of the image (0 at the left/top edge of
the image; an OpenCV pixel centre ``u`` is at ``u + 0.5``, see :mod:`vbl_robust.data.yolo`), resampled to
``size × size`` pixels. The whole image, letterboxed, is the window ``(−pad_x, −pad_y, max(H, W))``; a crop
around the runway is any other window. Parts of a window outside the image are filled with grey 114/255
(ultralytics' letterbox colour).

Mapping between a view pixel (edge coordinates ``p`` in ``[0, size]``) and the image::

    image_edge = (x0, y0) + p · side / size

Resampling: bilinear ``grid_sample`` (``align_corners=False``, which samples the exact view-pixel centres).
When a window shrinks the image by ``k = side / size ≥ 2``, the image is first average-pooled by ``⌊k⌋`` (an
anti-aliasing prefilter; pooled pixel ``j`` covers image edge coordinates ``[j·p, (j+1)·p)``, so the mapping
above still holds). Everything is differentiable with respect to the image and the window.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

PAD_VALUE = 114.0 / 255.0


def letterbox_window(height: int, width: int) -> tuple[float, float, float]:
    """Window ``(x0, y0, side)`` of the centred square letterbox of an ``height × width`` image."""
    side = float(max(height, width))
    return (-(side - width) / 2.0, -(side - height) / 2.0, side)


def box_window(
    box_xyxy: torch.Tensor, *, margin: float = 1.5, min_side: float = 64.0, max_side: float | None = None
) -> torch.Tensor:
    """Square crop windows around boxes.

    Args:
        box_xyxy: (B, 4) boxes in edge coordinates (e.g. the bounding box of the four corners).
        margin: side = ``margin · max(w, h)`` …
        min_side: … but at least this many image pixels (a far runway is a few pixels; the crop keeps context);
        max_side: … and at most this (None: unbounded).

    Returns:
        (B, 3) windows ``(x0, y0, side)`` centred on the boxes.
    """
    c = (box_xyxy[:, :2] + box_xyxy[:, 2:]) / 2
    wh = (box_xyxy[:, 2:] - box_xyxy[:, :2]).abs()
    side = (margin * wh.max(dim=1).values).clamp(min=min_side)
    if max_side is not None:
        side = side.clamp(max=max_side)
    return torch.cat([c - side[:, None] / 2, side[:, None]], dim=1)


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


def _pool_groups(windows: torch.Tensor, size: int):
    """``(p, rows)`` for each pooling factor ``p`` among the windows (B, 3), rows as an index tensor."""
    factors = [pool_factor(float(s), size) for s in windows[:, 2].detach().cpu().tolist()]
    for p in sorted(set(factors)):
        yield p, torch.tensor([i for i, f in enumerate(factors) if f == p], device=windows.device)


def pooled_source(image: torch.Tensor, p: int, cache: dict[int, torch.Tensor]) -> torch.Tensor:
    """``avg_pool(image, p)`` (``image`` itself for p = 1), computed once per factor in ``cache``."""
    if p not in cache:
        cache[p] = F.avg_pool2d(image, p, stride=p) if p > 1 else image
    return cache[p]


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


# -- views of a perturbed image, sampled from the unperturbed one ------------------------------------------------
def _reflect101(u: torch.Tensor, n: int) -> torch.Tensor:
    """Reflect OpenCV pixel coordinates into ``[0, n − 1]`` without repeating the border (``BORDER_REFLECT_101``).

    Bilinear interpolation at a reflected coordinate equals OpenCV's bilinear interpolation with that border.
    """
    if n < 2:
        return torch.zeros_like(u)
    period = 2.0 * (n - 1)
    return (n - 1) - (torch.remainder(u, period) - (n - 1)).abs()


def _rolled_samples(src: torch.Tensor, xs: torch.Tensor, ys: torch.Tensor, p: int, height: int, width: int,
                    angle_deg: torch.Tensor, center: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Sample the *rolled* image at edge coordinates ``xs (B, nx)`` × ``ys (B, ny)``, reading the unrolled source.

    Args:
        src: (1 or B, C, Hp, Wp) source, already average-pooled by ``p`` from the ``height × width`` image.
        angle_deg, center: the roll (see :mod:`vbl_robust.perturb.geometric`); center (2,) OpenCV pixels.

    Returns:
        ``(values (B, C, ny, nx), mask (B, 1, ny, nx))``: mask is the fraction of each sample inside the image
        frame (bilinear weights of in-frame pixels, as :func:`resample` computes it).
    """
    b = xs.shape[0]
    hp, wp = src.shape[-2:]
    qu = (xs - 0.5)[:, None, :].expand(b, ys.shape[1], xs.shape[1])  # OpenCV coordinates of the rolled image
    qv = (ys - 0.5)[:, :, None].expand(b, ys.shape[1], xs.shape[1])
    # in-frame fraction, in the pooled domain (what resample's ones channel gives)
    mu, mv = (qu + 0.5) / p - 0.5, (qv + 0.5) / p - 0.5
    mask = ((1.0 + mu).clamp(0, 1) * (wp - mu).clamp(0, 1) * (1.0 + mv).clamp(0, 1) * (hp - mv).clamp(0, 1))
    # inverse roll: the rolled pixel q shows the source pixel c + Rᵀ (q − c)
    a = torch.deg2rad(angle_deg.to(xs.dtype))[:, None, None]
    co, si = torch.cos(a), torch.sin(a)
    du, dv = qu - center[0], qv - center[1]
    su = _reflect101(center[0] + co * du - si * dv, width)
    sv = _reflect101(center[1] + si * du + co * dv, height)
    gx = 2.0 * ((su + 0.5) / p) / wp - 1.0
    gy = 2.0 * ((sv + 0.5) / p) / hp - 1.0
    grid = torch.stack([gx, gy], dim=-1).to(src.dtype)  # (B, ny, nx, 2)
    if src.shape[0] == 1 and b > 1:  # one source for the whole batch: stack the grids instead of copying it
        ny, nx = grid.shape[1:3]
        out = F.grid_sample(src, grid.reshape(1, b * ny, nx, 2), mode="bilinear", padding_mode="border",
                            align_corners=False)
        out = out.reshape(src.shape[1], b, ny, nx).transpose(0, 1)
    else:
        out = F.grid_sample(src.expand(b, -1, -1, -1), grid, mode="bilinear", padding_mode="border",
                            align_corners=False)
    return out, mask[:, None].to(src.dtype)


def rolled_gray_mean(pooled: torch.Tensor, p: int, height: int, width: int, angle_deg: torch.Tensor,
                     center: torch.Tensor, n: int = 128) -> torch.Tensor:
    """(B,) grayscale mean of the rolled image (ITU-R 601 luma, what the contrast perturbation uses), estimated
    on an ``n × n`` grid of the frame sampled from the (pooled) unrolled source."""
    from vbl_robust.perturb.photometric import gray_mean

    b = angle_deg.shape[0]
    t = (torch.arange(n, dtype=pooled.dtype, device=pooled.device) + 0.5) / n
    xs, ys = (t * width).expand(b, n), (t * height).expand(b, n)
    return gray_mean(_rolled_samples(pooled, xs, ys, p, height, width, angle_deg, center)[0])


def perturbed_resample(
    image: torch.Tensor, windows: torch.Tensor, size: int, *, angle_deg: torch.Tensor, center,
    contrast: torch.Tensor, gray_mean: torch.Tensor, pooled: dict[int, torch.Tensor] | None = None,
) -> torch.Tensor:
    """Views of the *perturbed* image ``T(x; θ)`` (roll about ``center``, then contrast), sampled directly from
    the unperturbed ``x`` — the same views as ``resample(perturb(x), windows, size)`` without making the
    perturbed full-resolution image (one interpolation instead of two, so the values differ by interpolation
    smoothing only; tested).

    Args:
        image: (1, 3, H, W) unperturbed image in [0, 1] (or (B, 3, H, W), one per row).
        windows: (B, 3) view windows (edge coordinates of the image).
        size: output side.
        angle_deg, contrast: (B,) roll (degrees) and contrast factor per view.
        center: (2,) roll centre, OpenCV pixels (the principal point).
        gray_mean: (B,) grayscale mean of each rolled image (:func:`rolled_gray_mean`), for the contrast.
        pooled: cache ``{p: avg_pool(image, p)}`` shared between calls on the same image (filled as needed).

    Returns:
        (B, 3, size, size); outside the image frame: grey 114/255 as in :func:`resample`. Differentiable w.r.t.
        the image, the windows, the angles and the contrast factors.
    """
    b = windows.shape[0]
    h, w = image.shape[-2:]
    dtype = image.dtype
    windows = torch.as_tensor(windows, dtype=dtype, device=image.device)
    center = torch.as_tensor(np.asarray(center, dtype=np.float64), dtype=dtype, device=image.device)
    pooled = {} if pooled is None else pooled
    out = torch.empty(b, image.shape[1], size, size, dtype=dtype, device=image.device)
    t = (torch.arange(size, dtype=dtype, device=image.device) + 0.5) / size
    for p, idx in _pool_groups(windows, size):
        src = pooled_source(image, p, pooled)
        src = src if src.shape[0] == 1 else src[idx]
        win = windows[idx]
        xs = win[:, 0:1] + t[None, :] * win[:, 2:3]
        ys = win[:, 1:2] + t[None, :] * win[:, 2:3]
        v, mask = _rolled_samples(src, xs, ys, p, h, w, angle_deg[idx], center)
        f = contrast[idx].to(dtype)[:, None, None, None]
        v = (f * v + (1.0 - f) * gray_mean[idx].to(dtype)[:, None, None, None]).clamp(0.0, 1.0)
        out[idx] = v * mask + PAD_VALUE * (1.0 - mask)
    return out
