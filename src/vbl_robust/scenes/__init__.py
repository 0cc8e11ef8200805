"""Synthetic LARD-V2-like approach scenes: poses from the LARD V2 envelopes, rendered with exact labels.

>>> import vbl_robust as vr
>>> samples = vr.scenes.generate(4, seed=0, width=256, height=256)
>>> samples[0].image.shape
(256, 256, 3)
"""

from .envelopes import sample_approaches
from .generate import generate

__all__ = ["generate", "sample_approaches"]
