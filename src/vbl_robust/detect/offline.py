"""Run ultralytics without any network access.

Ultralytics tries the network in three places: an online check at import, a font download (``Arial.ttf``) on
every dataset check, and settings sync/telemetry. :func:`setup_offline` closes all three: it sets
``YOLO_OFFLINE=1``, points ``YOLO_CONFIG_DIR`` at a local directory (default ``~/.cache/vbl_robust/ultralytics``
unless the variable is already set), copies matplotlib's DejaVuSans to ``$YOLO_CONFIG_DIR/Ultralytics/Arial.ttf``
and turns settings sync off. Call it before the first ``import ultralytics``; every module of this package that
uses ultralytics goes through :func:`import_ultralytics`, which does so.
"""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path

logger = logging.getLogger(__name__)

_DONE = False


def config_dir() -> Path:
    """The ultralytics configuration directory in use (``$YOLO_CONFIG_DIR``, set by :func:`setup_offline`)."""
    return Path(os.environ.get("YOLO_CONFIG_DIR", Path.home() / ".cache" / "vbl_robust" / "ultralytics"))


def setup_offline() -> Path:
    """Make ultralytics fully offline; idempotent. Returns the ``Ultralytics`` settings directory."""
    global _DONE
    os.environ["YOLO_OFFLINE"] = "1"
    os.environ.setdefault("YOLO_VERBOSE", "False")
    os.environ.setdefault("YOLO_CONFIG_DIR", str(config_dir()))
    settings_dir = config_dir() / "Ultralytics"
    if _DONE:
        return settings_dir
    settings_dir.mkdir(parents=True, exist_ok=True)
    font = settings_dir / "Arial.ttf"
    if not font.exists():
        import matplotlib

        src = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"
        shutil.copyfile(src, font)
        logger.debug("copied %s to %s", src, font)
    from ultralytics import settings

    if settings.get("sync", True):
        settings.update({"sync": False})
    _DONE = True
    return settings_dir


def import_ultralytics():
    """``setup_offline()`` then ``import ultralytics``; returns the module."""
    setup_offline()
    import ultralytics

    return ultralytics
