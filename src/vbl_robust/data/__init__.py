"""Samples and datasets (LARD V2 reader and writer)."""

from .check import check_images
from .lard_read import read_lard
from .sequence import read_lard_sequences

__all__ = ["check_images", "read_lard", "read_lard_sequences"]
