"""Synthetic LARD-V2-like approach scenes: poses from the LARD V2 envelopes, rendered with exact labels.

>>> import vbl_robust as vr
>>> samples = vr.scenes.generate(4, seed=0, width=256, height=256)
>>> samples[0].image.shape
(256, 256, 3)
"""

from .airports import REFERENCE_LAT_LON_ALT, Airport, designation, make_airports
from .envelopes import ENVELOPES, Approach, Envelope, corners_visible, sample_approach, sample_approaches
from .export import write_dataset
from .generate import generate, render_sample
from .render import Look, debug_look, ground_homography, render_scene, sample_look
from .sequences import envelope_of, generate_sequences, write_sequences

__all__ = [
    "ENVELOPES",
    "REFERENCE_LAT_LON_ALT",
    "Airport",
    "Approach",
    "Envelope",
    "Look",
    "corners_visible",
    "debug_look",
    "designation",
    "envelope_of",
    "generate",
    "generate_sequences",
    "ground_homography",
    "make_airports",
    "render_sample",
    "render_scene",
    "sample_approach",
    "sample_approaches",
    "sample_look",
    "write_dataset",
    "write_sequences",
]
