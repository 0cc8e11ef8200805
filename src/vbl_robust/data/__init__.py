"""Samples and datasets (LARD V2 reader and writer)."""

from .check import ImageCheck, LabelCheck, check_images, check_labels, first_problem, image_digests
from .lard import LARD_COLUMNS, SEQUENCE_COLUMNS, approach_metrics, load_runway_db, normalize_runway
from .lard_read import read_lard
from .lard_write import write_lard
from .paths import resolve_within
from .sample import Sample, load_rgb
from .sequence import ApproachSequence, group_sequences, read_lard_sequences
from .yolo import pose_label, write_data_yaml, write_pose_images

__all__ = [
    "LARD_COLUMNS",
    "SEQUENCE_COLUMNS",
    "ApproachSequence",
    "ImageCheck",
    "LabelCheck",
    "Sample",
    "approach_metrics",
    "check_images",
    "check_labels",
    "first_problem",
    "group_sequences",
    "image_digests",
    "load_rgb",
    "load_runway_db",
    "normalize_runway",
    "pose_label",
    "read_lard",
    "read_lard_sequences",
    "resolve_within",
    "write_data_yaml",
    "write_lard",
    "write_pose_images",
]
