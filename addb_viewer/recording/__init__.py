"""Recordings of processed trials for reports and other tools.

:func:`~addb_viewer.recording.rerun_writer.write_rerun`
    Rerun ``.rrd`` file (3D scene + time series + default blueprint), no viewer.
:func:`~addb_viewer.recording.mcap_writer.write_mcap`
    MCAP file with JSON channels (Foxglove ``FrameTransforms`` for the skeleton); read
    back with :mod:`solver.io.mcap_file`.
:func:`~addb_viewer.recording.metadata.recording_info`
    What both carry to tell two recordings apart: subject, trial, solver settings and
    the review (annotation) state they were made with.
:mod:`~addb_viewer.recording.jobs`
    ``record_trial`` / ``export_trial``: from a subject folder (processed on demand) to
    a file; used by ``addb record``, ``addb export`` and the review app.
"""
