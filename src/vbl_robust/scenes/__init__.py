"""Synthetic LARD-V2-like approach scenes: pose sampling from the LARD V2 envelopes (rendering to come)."""

from .envelopes import ENVELOPES, Approach, Envelope, corners_visible, sample_approach, sample_approaches

__all__ = ["ENVELOPES", "Approach", "Envelope", "corners_visible", "sample_approach", "sample_approaches"]
