"""Readers and writers of lab files: TRC, MOT/STO, C3D, ExternalLoads XML, subject folders.

Every reader returns the immutable types of :mod:`solver.io.types` in SI units and the
OpenSim lab frame (Y up), and raises a :class:`~solver.errors.FileFormatError`
subclass naming the file and the line (or element) on bad input.
"""

from solver.io.c3d import read_c3d
from solver.io.external_loads import (
    ExternalForce,
    ExternalLoads,
    plates_by_force,
    read_external_loads,
    write_external_loads,
)
from solver.io.force_columns import PlateColumns, group_plates
from solver.io.mot import (
    is_force_table,
    read_coordinates,
    read_forces,
    read_table,
    write_coordinates,
    write_forces,
    write_table,
)
from solver.io.review import read_review
from solver.io.subject import Subject, Trial, TrialFiles, load_subject, load_trial
from solver.io.summary import format_summary, summarize
from solver.io.trc import read_trc, write_trc
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories, Table

__all__ = [
    "ExternalForce",
    "ExternalLoads",
    "ForcePlate",
    "ForceRecording",
    "MarkerTrajectories",
    "PlateColumns",
    "Subject",
    "Table",
    "Trial",
    "TrialFiles",
    "format_summary",
    "group_plates",
    "is_force_table",
    "load_subject",
    "load_trial",
    "plates_by_force",
    "read_c3d",
    "read_coordinates",
    "read_external_loads",
    "read_forces",
    "read_review",
    "read_table",
    "read_trc",
    "summarize",
    "write_coordinates",
    "write_external_loads",
    "write_forces",
    "write_table",
    "write_trc",
]
