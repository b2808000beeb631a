"""The browser review app (``addb view``): a viser server that replays a processed trial,
lets a reviewer flag frames with unmeasured force and reprocesses the trial.

Modules, one job each
---------------------
paths
    Where a subject's output, review record, recordings and job folders are; confines
    every path that comes from the page to those folders.
meshes
    VTK PolyData (``.vtp``) bone meshes -> trimesh, merged and scaled per body, cached.
state
    The playback controller (frame, play/pause, speed, loop, in/out points); no viser.
flags
    The reviewer's edits of one trial through :class:`annotations.AnnotationStore`, and the
    masks the page shows (flagged per foot, proposals pending / accepted / rejected).
summary
    Per-trial figures (marker RMS, residuals, Hicks thresholds) and the before/after table.
scene
    A processed trial frame -> viser scene nodes (markers, bones, force arrows, centre of mass).
plots
    uPlot charts synchronized with the current frame, flagged frames shaded.
panel
    The GUI controls (no behaviour; :mod:`~addb_viewer.app.server` wires them).
jobs
    The solver in a separate process, with progress and cancel.
camera
    Where the camera looks: the whole trial framed for each page's canvas, the anatomical
    views, following the pelvis.
timeline
    The trial's timeline strip (flags per foot, proposals, measured force, selection).
diagnosis
    What ``addb diagnose`` found and what is applied, as the panel's "Diagnosis" folder.
reprocess
    Solver runs started from the page (first processing, Reprocess, Diagnose, recording).
queue
    A dataset's review queue (processing and review state, sorted by need); no viser.
workbench
    ``addb view DATASET_DIR``: the queue's window, Open and Next trial to review.
access
    The access token when the app listens beyond this machine.
server_log
    Quiets the server's log about connections closed before saying anything.
server
    :class:`~addb_viewer.app.server.ReviewApp`: wiring, playback thread, errors in the page.
"""
