"""The exported scaled model and coordinates round-trip through OpenSim 4.6: OpenSim's marker
positions for our .osim at the coordinates of our _ik.mot equal ours within 1e-5 m."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.io.mot import read_coordinates
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from solver.pipeline import process_kinematics
from tests.conftest import OPENSIM, OPENSIM_REASON, SHARED_DATA, require_tool

pytestmark = pytest.mark.opensim


def test_opensim_reproduces_our_markers_from_the_exported_files(tmp_path: Path) -> None:
    require_tool("opensim", OPENSIM, OPENSIM_REASON)
    from tests.model import opensim_ref as ref

    out = tmp_path / "out"
    process_kinematics(SHARED_DATA / "subjects" / "rajagopal2016_walk", out)
    model_file = out / "rajagopal2016_walk_scaled.osim"
    ours = Skeleton(read_osim(model_file))
    rotational = [c.name for c in ours.osim.coordinates if c.motion_type == "rotational"]
    table = read_coordinates(out / "walk" / "walk_ik.mot", rotational=rotational)
    q = np.column_stack([table.column(c) for c in ours.coordinate_names])
    om = ref.OpenSimModel(str(model_file))
    assert om.names == list(ours.coordinate_names)
    frames = np.linspace(0, q.shape[0] - 1, 12).astype(int)
    worst = 0.0
    for k in frames:
        om.set_state(q[k])
        names, pos = om.markers()
        mine = ours.marker_positions(q[k], ours.marker_index(names))[0]
        worst = max(worst, float(np.abs(mine - pos).max()))
    assert worst < 1e-5, worst
    assert len(names) > 60  # the fitted marker set, written back into the model
