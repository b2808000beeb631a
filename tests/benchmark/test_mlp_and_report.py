"""MLP baseline (one epoch on a tiny set; skipped without PyTorch), the protocols, the
report and the filtering study."""

from __future__ import annotations

import json

import numpy as np
import pytest

from solver.benchmark.dataset import BenchmarkError, build_dataset
from solver.benchmark.filtering import filtering_markdown, filtering_study, plot_filtering
from solver.benchmark.mlp import FeatureSpec, MlpOptions, history_index, torch_available, train_mlp
from solver.benchmark.report import PAPER, dataset_summary, to_json, to_markdown, write_report
from solver.benchmark.run import run_benchmark
from tests.conftest import TORCH_REASON, in_ci, needs_tool, tool_available

from .conftest import motion, processed_trial


@pytest.fixture(scope="module")
def three_subjects():
    trials = [
        processed_trial(40, subject="a"),
        processed_trial(40, subject="b", q=motion(40, accel=(0.2, 0.0, 0.1), swing=0.2)),
        processed_trial(40, subject="c", q=motion(40, accel=(-0.3, 0.0, 0.0), swing=0.4)),
    ]
    return build_dataset(trials, inputs="processed")


def test_history_samples_every_stride_frames_clamped_at_the_start() -> None:
    idx = history_index(100, np.array([0, 47, 99]), MlpOptions())
    assert idx.shape == (3, 10)
    assert idx[0].tolist() == [0] * 10
    assert idx[1].tolist() == [2, 7, 12, 17, 22, 27, 32, 37, 42, 47]
    assert idx[2, -1] == 99 and idx[2, 0] == 54


@needs_tool("torch", torch_available(), TORCH_REASON)
def test_mlp_trains_one_epoch_and_predicts_every_frame(three_subjects) -> None:
    trials = three_subjects.trials
    spec = FeatureSpec.common(trials)
    model = train_mlp(trials[:2], trials[2:], spec=spec, options=MlpOptions(epochs=1, hidden=16))
    assert len(model.history) == 1 and np.isfinite(model.history[0]["dev_loss"])
    pred = model.predict(trials[2])
    n = trials[2].n_frames
    assert pred.grf.shape == (n, 2, 3) and pred.tau.shape == (n, trials[2].q.shape[1])
    # the CoM acceleration follows from the predicted force
    np.testing.assert_allclose(pred.com_acc, pred.grf.sum(axis=1) / trials[2].mass_kg + [0, -9.80665, 0], atol=1e-9)


@needs_tool("torch", torch_available(), TORCH_REASON)
def test_leave_one_subject_out_scores_every_subject_once(three_subjects) -> None:
    result = run_benchmark(three_subjects, methods=("analytical", "mlp"), mlp_options=MlpOptions(epochs=1, hidden=8))
    assert [r.method for r in result.rows] == ["analytical (measured contact)", "MLP"]
    assert result.rows[0].n_frames == result.rows[1].n_frames == three_subjects.n_frames
    for fold in result.rows[1].notes["folds"]:
        assert not set(fold["test"]) & set(fold["train"])


def test_protocol_errors(three_subjects) -> None:
    with pytest.raises(BenchmarkError, match="unknown method"):
        run_benchmark(three_subjects, methods=("oracle",))
    with pytest.raises(BenchmarkError, match="both in the training"):
        run_benchmark(three_subjects, train=three_subjects.of_subjects(["a"]))
    seeded = run_benchmark(three_subjects, split="seeded", seed=1)
    assert len(seeded.test_subjects) == 1 and seeded.rows[0].n_frames == 40


def test_report_layout(three_subjects, tmp_path) -> None:
    result = run_benchmark(three_subjects, contacts=("measured", "kinematic"))
    summary = dataset_summary(three_subjects, activities={"overground_walking": 1.2})
    assert summary["frames"] == 120 and summary["hicks_pass_rate"] == 1.0
    assert summary["phases"]["single_support"] == 1.0
    md = to_markdown(result, summary, command="addb benchmark x")
    assert "| analytical (measured contact) | 120 |" in md and "CoM acc. error (m/s²)" in md
    assert "analytical (paper)" in md and "4.47" in md and "not targets" in md
    assert "overground_walking 1.2 s" in md
    assert "* analytical (measured contact): the paper's analytical baseline handed the force plates' contact" in md
    data = to_json(result, summary)
    assert data["rows"][1]["method"] == "analytical (kinematic contact)" and data["paper"]["rows"] == PAPER
    js, _ = write_report(tmp_path, result, summary)
    assert json.loads(js.read_text())["rows"][0]["frames"] == 120


def test_filtering_study_table_and_plot(three_subjects, tmp_path) -> None:
    """The study's rows and table; the plot is a PNG when matplotlib is installed, and
    without it (not a dependency) nothing is written and the call says so (False). Under
    CI=true a missing matplotlib fails the test: the test command installs the plot extra."""
    rows = filtering_study(three_subjects, cutoffs=(4.0, 30.0, 60.0))
    assert [r["cutoff_hz"] for r in rows] == [4.0, 30.0, 60.0]
    # smooth synthetic motion: heavy filtering distorts it, light filtering hardly
    assert rows[0]["com_acc"] > rows[1]["com_acc"]
    assert "60 (none)" in filtering_markdown(rows)
    png = tmp_path / "f.png"
    drawn = plot_filtering(rows, png)
    assert drawn == tool_available("matplotlib")
    if in_ci():
        assert drawn, "CI=true and matplotlib (the plot extra, installed by scripts/run-tests.sh) is missing"
    if drawn:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 1000
    else:
        assert not png.exists()
