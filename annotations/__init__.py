"""The review record: per-frame flags, activity ranges, notes, who and when.

Independent of :mod:`solver` and :mod:`addb_viewer` (the app imports this package and
turns the record into the masks the solver takes). Only the standard library and numpy.

Main entry points
-----------------
:class:`AnnotationStore`
    ``AnnotationStore.open(subject_folder, reviewer="ana")``: durable, multi-writer store.
:func:`mask_to_ranges`, :func:`ranges_to_mask`, :func:`resample_mask`
    Conversions between boolean ``(T,)`` masks and half-open frame ranges.
:func:`import_addb_review`, :func:`export_addb_review`
    Exchange with AddBiomechanics ``review.json`` files.
"""

from annotations.addb import (
    export_addb_review,
    import_addb_review,
    read_addb_review,
    write_addb_review,
)
from annotations.errors import AnnotationError, AnnotationFileError
from annotations.masks import frames_to_ranges, mask_to_ranges, ranges_to_mask, resample_mask
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
    "export_addb_review",
    "frames_to_ranges",
    "import_addb_review",
    "mask_to_ranges",
    "ranges_to_mask",
    "read_addb_review",
    "resample_mask",
    "write_addb_review",
]
