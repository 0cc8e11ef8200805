"""Detector plug-ins for the tests (``--detector-plugin tests/cli/plugin_helpers.py:FACTORY``)."""

from __future__ import annotations

from vbl_robust.detect.oracle import OracleDetector


class NoisyCorners(OracleDetector):
    """A differentiable plug-in: the projected corners with 2 px of fixed noise (so breaches exist)."""


def noisy_corners():
    return NoisyCorners(noise_px=2.0)


class Exploding(OracleDetector):
    def detect(self, context):
        raise RuntimeError("the plug-in's model exploded")


def exploding():
    return Exploding()


class NotADetector:
    input_size = None


def not_a_detector():
    return NotADetector()


def raising_factory():
    raise OSError("weights not found: /models/mine.bin")
