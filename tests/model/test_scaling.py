"""Scaling as OpenSim's ScaleTool does it, and the .osim writer, checked against OpenSim 4.6."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from solver.errors import OsimModelError
from solver.model.osim import read_osim
from solver.model.osim_writer import write_osim
from solver.model.scaling import scale_model
from solver.model.skeleton import Skeleton
from tests.conftest import OPENSIM, OPENSIM_REASON, require_tool
from tests.model.conftest import MODELS, SHARED

SCALE_SET = SHARED / "data" / "trials" / "rajagopal2016" / "scaleSet_applied_walk.xml"
GENERICS = [MODELS / "Rajagopal2016.osim", SHARED / "data" / "subjects" / "rajagopal2016_walk" / "unscaled_generic.osim"]


def _study_scales(body_names: tuple[str, ...]) -> dict[str, list[float]]:
    root = ET.parse(SCALE_SET).getroot()
    out = {s.findtext("segment"): [float(v) for v in s.findtext("scales").split()] for s in root.iter("Scale")}
    return {k: v for k, v in out.items() if k in body_names}


@pytest.mark.opensim
@pytest.mark.parametrize("generic", GENERICS, ids=lambda p: p.parent.name)
@pytest.mark.parametrize("preserve", [True, False])
def test_scaling_matches_opensim_model_scale(generic: Path, preserve: bool, tmp_path: Path) -> None:
    require_tool("opensim", OPENSIM, OPENSIM_REASON)
    from tests.model import opensim_ref as ref

    model = read_osim(generic)
    scales = _study_scales(model.body_names)
    ours = scale_model(model, scales, mass=85.0668, preserve_mass_distribution=preserve)
    om = ref.osim.Model(str(generic))
    state = om.initSystem()
    scale_set = ref.osim.ScaleSet()
    for body, f in scales.items():
        sc = ref.osim.Scale()
        sc.setSegmentName(body)
        sc.setScaleFactors(ref.osim.Vec3(*f))
        sc.setApply(True)
        scale_set.cloneAndAppend(sc)
    om.scale(state, scale_set, preserve, 85.0668)
    om.printToXML(str(tmp_path / "opensim_scaled.osim"))
    theirs = read_osim(tmp_path / "opensim_scaled.osim")
    for a, b in zip(ours.bodies, theirs.bodies):
        assert a.name == b.name
        assert a.mass == pytest.approx(b.mass, rel=1e-12)
        np.testing.assert_allclose(a.com, b.com, atol=1e-12)
        np.testing.assert_allclose(a.inertia, b.inertia, atol=1e-10)
    q = Skeleton(ours).cmap.complete(np.random.default_rng(0).uniform(-0.6, 0.6, (5, len(ours.coordinates))))
    np.testing.assert_allclose(Skeleton(ours).marker_positions(q), Skeleton(theirs).marker_positions(q), atol=1e-6)


@pytest.mark.opensim
@pytest.mark.parametrize("generic", GENERICS, ids=lambda p: p.parent.name)
def test_written_model_loads_in_opensim_with_our_markers(generic: Path, tmp_path: Path) -> None:
    require_tool("opensim", OPENSIM, OPENSIM_REASON)
    from tests.model import opensim_ref as ref

    model = read_osim(generic)
    scaled = scale_model(model, _study_scales(model.body_names), mass=80.0)
    out = write_osim(scaled, tmp_path / "ours.osim", name="scaled")
    om = ref.OpenSimModel(str(out))
    sk = Skeleton(scaled)
    q = sk.cmap.complete(ref.random_states(sk.ranges, 3, seed=5))
    for k in range(3):
        om.set_state(q[k])
        names, pos = om.markers()
        np.testing.assert_allclose(sk.marker_positions(q[k], sk.marker_index(names))[0], pos, atol=1e-5)
    assert om.model.getTotalMass(om.state) == pytest.approx(80.0, rel=1e-12)


def test_write_read_round_trip_keeps_the_model(tmp_path: Path) -> None:
    model = read_osim(MODELS / "Rajagopal2016.osim")
    scaled = scale_model(model, {"femur_r": [1.1, 1.2, 1.1], "pelvis": [0.9, 1.0, 1.05]}, mass=70.0)
    back = read_osim(write_osim(scaled, tmp_path / "m.osim"))
    a, b = Skeleton(scaled), Skeleton(back)
    q = a.cmap.complete(np.random.default_rng(1).uniform(-0.5, 0.5, (4, a.n)))
    np.testing.assert_allclose(b.marker_positions(q), a.marker_positions(q), atol=1e-12)
    np.testing.assert_allclose(b.center_of_mass(q), a.center_of_mass(q), atol=1e-12)
    assert back.total_mass == pytest.approx(70.0, rel=1e-12)


def test_uniform_scale_scales_segment_lengths_and_keeps_total_mass_rule() -> None:
    model = read_osim(MODELS / "Rajagopal2016.osim")
    scaled = scale_model(model, {b: [1.1, 1.1, 1.1] for b in model.body_names}, preserve_mass_distribution=False)
    sk0, sk1 = Skeleton(model), Skeleton(scaled)
    q = sk0.neutral()[None]
    p0, p1 = sk0.marker_positions(q)[0], sk1.marker_positions(q)[0]
    # with the pelvis fixed at the origin every distance between markers grows by 1.1
    d0 = np.linalg.norm(p0[:, None] - p0[None], axis=-1)
    d1 = np.linalg.norm(p1[:, None] - p1[None], axis=-1)
    np.testing.assert_allclose(d1, 1.1 * d0, rtol=1e-9, atol=1e-12)
    assert scaled.total_mass == pytest.approx(model.total_mass * 1.1**3, rel=1e-12)


def test_bad_scale_factors_are_rejected() -> None:
    model = read_osim(MODELS / "Rajagopal2016.osim")
    with pytest.raises(OsimModelError, match="unknown body 'femur'"):
        scale_model(model, {"femur": [1, 1, 1]})
    with pytest.raises(OsimModelError, match="3 positive numbers"):
        scale_model(model, {"femur_r": [1, -1, 1]})
