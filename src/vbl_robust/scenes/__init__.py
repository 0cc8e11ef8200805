"""Synthetic LARD-V2-like approach scenes: poses from the LARD V2 envelopes, rendered with exact labels.

>>> import vbl_robust as vr
>>> samples = vr.scenes.generate(4, seed=0, width=256, height=256)
>>> samples[0].image.shape
(256, 256, 3)
"""

from .airports import REFERENCE_LAT_LON_ALT, designation, make_airports
from .envelopes import ENVELOPES, corners_visible, sample_approaches
from .export import write_dataset
from .generate import generate
from .render import ground_homography
from .sequences import envelope_of, generate_sequences, write_sequences

__all__ = [
    "ENVELOPES",
    "REFERENCE_LAT_LON_ALT",
    "corners_visible",
    "designation",
    "envelope_of",
    "generate",
    "generate_sequences",
    "ground_homography",
    "make_airports",
    "sample_approaches",
    "write_dataset",
    "write_sequences",
]
