"""The review record: per-frame flags, activity ranges, notes, who and when.

Independent of :mod:`solver` and :mod:`addb_viewer` (the app imports this package and
turns the record into the masks the solver takes). Only the standard library and numpy.

Main entry points
-----------------
:class:`AnnotationStore`
    ``AnnotationStore.open(subject_folder, reviewer="ana")``: durable, multi-writer store.
:func:`frames_to_ranges`, :func:`ranges_to_mask`
    Frame indices -> half-open frame ranges -> boolean ``(T,)`` masks (the store's
    ``mask``/``set_mask`` give and take masks; runs, resampling and joining of masks are
    :mod:`solver.masks`' and the app's, :mod:`addb_viewer.review_masks`).
:func:`export_addb_review`
    Export to AddBiomechanics ``review.json`` files (the reader is the solver's).
"""

from annotations.addb import encode_addb_review, export_addb_review, write_addb_review
from annotations.errors import AnnotationError, AnnotationFileError
from annotations.masks import frames_to_ranges, ranges_to_mask
from annotations.model import (
    ACTIVITY_LABELS,
    EXCLUDED,
    FEET,
    FLAG_KINDS,
    SOURCES,
    UNMEASURED_FORCE,
    ActivityRange,
    Conflict,
    Edit,
    FlagRun,
    FrameFlag,
    Note,
    Provenance,
    TrialReview,
)
from annotations.recovery import RecoveryReport
from annotations.schema import SCHEMA, VERSION
from annotations.store import AnnotationStore

__all__ = [
    "ACTIVITY_LABELS",
    "EXCLUDED",
    "FEET",
    "FLAG_KINDS",
    "SCHEMA",
    "SOURCES",
    "UNMEASURED_FORCE",
    "VERSION",
    "ActivityRange",
    "AnnotationError",
    "AnnotationFileError",
    "AnnotationStore",
    "Conflict",
    "Edit",
    "FlagRun",
    "FrameFlag",
    "Note",
    "Provenance",
    "RecoveryReport",
    "TrialReview",
    "encode_addb_review",
    "export_addb_review",
    "frames_to_ranges",
    "ranges_to_mask",
    "write_addb_review",
]
