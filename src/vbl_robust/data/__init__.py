"""Samples and datasets (LARD V2 reader and writer)."""

from .check import check_images, check_labels, first_problem, image_digests
from .lard import LARD_COLUMNS, SEQUENCE_COLUMNS, normalize_runway
from .lard_read import read_lard
from .lard_write import write_lard
from .paths import resolve_within
from .sample import Sample
from .sequence import ApproachSequence, group_sequences, read_lard_sequences

__all__ = [
    "LARD_COLUMNS",
    "SEQUENCE_COLUMNS",
    "ApproachSequence",
    "Sample",
    "check_images",
    "check_labels",
    "first_problem",
    "group_sequences",
    "image_digests",
    "normalize_runway",
    "read_lard",
    "read_lard_sequences",
    "resolve_within",
    "write_lard",
]
