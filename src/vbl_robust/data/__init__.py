"""Samples and datasets (LARD V2 reader and writer)."""

from .sample import Sample, load_rgb

__all__ = ["Sample", "load_rgb"]
