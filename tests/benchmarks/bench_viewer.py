"""Benchmark of the review app, ``addb view`` (run on demand, not a test).

    .venv/bin/python tests/benchmarks/bench_viewer.py [--out PROCESSED_DEMO]

Targets (issue "browser review app"):

* server-side time to update the scene for one frame, Rajagopal demo (41 markers,
  22 bodies, plate and centre-of-mass arrows): under 10 ms;
* start-up to first frame on the processed demo: under 5 s;
* memory for a 2,000-frame trial (the demo's arrays tiled).

The demo is processed with the full pipeline into a scratch folder first unless
``--out`` names a folder where it already is (e.g. ``~/.cache/addb/rajagopal2016_walk-*``
after ``addb view``). Per-frame figures are measured with one protocol-level client
connected (what a browser tab costs the server), playback-like sweeps over all frames.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(REPO), str(REPO / "tests" / "viewer")]

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.demo import DEMO_SUBJECT
from solver.results import load_processed, save_processed


def _stats(seconds: list[float]) -> str:
    ms = np.asarray(seconds) * 1e3
    return f"median {np.median(ms):6.2f} ms, p95 {np.percentile(ms, 95):6.2f} ms, max {ms.max():6.2f} ms"


def bench_frame_update(out: Path, passes: int = 3) -> None:
    """Per-frame server time: scene only, and the app's whole render (scene, slider,
    status, throttled charts), with a protocol client attached."""
    from viewer_support import ProtocolClient, wait_for

    from addb_viewer.app.server import ReviewApp

    with tempfile.TemporaryDirectory() as tmp:
        os.environ["XDG_CACHE_HOME"] = tmp
        app = ReviewApp(ReviewPaths.for_subject(DEMO_SUBJECT, out), reviewer="bench", port=0, background=False)
        client = ProtocolClient(app.port)
        try:
            wait_for(lambda: app.server.get_clients(), what="client")
            t = app.trial
            n_arrows = sum(1 for k in range(t.n_frames) if len(app.scene.show(k).plate_arrows))
            print(f"trial {t.subject}/{t.trial}: {t.n_frames} frames, {len(t.marker_names)} markers, "
                  f"{len(t.body_names)} bodies, {len(t.plates)} plates (arrows on {n_arrows} frames), "
                  f"dynamics: {t.has_dynamics}")
            for label, labels in (("scene.show (markers, 22 bones, arrows, COM)", False),
                                  ("scene.show with 41 marker names shown", True)):
                app.settings.show_labels = labels
                times = []
                for _ in range(passes):
                    for k in range(t.n_frames):
                        t0 = time.perf_counter()
                        app.scene.show(k)
                        times.append(time.perf_counter() - t0)
                print(f"  {label:<46} {_stats(times)}")
            app.settings.show_labels = False
            times = []
            app.playback.playing = True  # charts throttled as during playback
            for _ in range(passes):
                for k in range(t.n_frames):
                    t0 = time.perf_counter()
                    with app._lock:
                        app.render(k)
                    times.append(time.perf_counter() - t0)
            app.playback.playing = False
            print(f"  {'whole render while playing (charts <= 4/s)':<46} {_stats(times)}")
            times = []
            for k in range(0, t.n_frames, 4):
                t0 = time.perf_counter()
                with app._lock:
                    app.render(k, force_plots=True)
                times.append(time.perf_counter() - t0)
            print(f"  {'whole render incl. 4 chart updates (seek)':<46} {_stats(times)}")
        finally:
            client.close()
            app.stop()


def bench_startup(out: Path, repeats: int = 3) -> None:
    """Wall time from launching ``addb view`` to its first frame (interpreter start and
    imports included), on the processed demo."""
    walls, inner = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            env = dict(os.environ, XDG_CACHE_HOME=tmp, PYTHONPATH=str(REPO))
            t0 = time.perf_counter()
            proc = subprocess.Popen(
                [sys.executable, "-m", "addb_viewer.cli", "view", "--out", str(out), "--port", "0"],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
            )
            for line in proc.stdout:
                m = re.search(r"first frame shown ([\d.]+) s", line)
                if m:
                    walls.append(time.perf_counter() - t0)
                    inner.append(float(m.group(1)))
                    break
            proc.terminate()
            proc.wait(30)
            proc.stdout.close()
    print(f"start-up to first frame (processed demo, {repeats} runs): wall {statistics.median(walls):.2f} s "
          f"(min {min(walls):.2f}), of which app construction to first frame {statistics.median(inner):.2f} s")


_MEMORY_CHILD = r"""
import json, os, sys, time
sys.path[:0] = sys.argv[3:]
def rss(field="VmRSS"):
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith(field)) / 1024
from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.server import ReviewApp
from addb_viewer.demo import DEMO_SUBJECT
base = rss()
app = ReviewApp(ReviewPaths.for_subject(DEMO_SUBJECT, sys.argv[1]), reviewer="bench", port=0, background=False)
assert app.trial is not None and app.trial.n_frames == int(sys.argv[2]), app.panel.error.content
loaded = rss()
t = []
for k in range(0, app.trial.n_frames, 10):
    t0 = time.perf_counter()
    with app._lock:
        app.render(k, force_plots=True)
    t.append(time.perf_counter() - t0)
after = rss()
peak = rss("VmHWM")  # not ru_maxrss: Linux keeps that across execve (the parent's peak)
app.stop()
print(json.dumps({"base": base, "loaded": loaded, "after": after, "peak": peak, "render_ms": sorted(t)[len(t) // 2] * 1e3}))
"""


def tiled_trial(out: Path, n_frames: int):
    """The processed demo walk with its arrays tiled to ``n_frames`` frames (trial "walk2000")."""
    walk = load_processed(out, "walk")
    reps = -(-n_frames // walk.n_frames)

    def tile(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a] * reps)[:n_frames]

    arrays = {f.name: tile(getattr(walk, f.name)) for f in dataclasses.fields(walk)
              if isinstance(getattr(walk, f.name), np.ndarray) and getattr(walk, f.name).shape[:1] == (walk.n_frames,)}
    arrays["time"] = np.arange(n_frames) / walk.rate_hz
    plates = tuple(dataclasses.replace(p, force=tile(p.force), cop=tile(p.cop), free_moment=tile(p.free_moment),
                                       body=tile(p.body)) for p in walk.plates)
    return dataclasses.replace(walk, trial="walk2000", plates=plates,
                               proposal_reasons=tuple(np.resize(np.array(walk.proposal_reasons, dtype=object), n_frames)),
                               **arrays)  # fmt: skip


def bench_timeline(out: Path, n_frames: int = 2000, edits: int = 20) -> None:
    """Server-side timeline redraw after an edit on a ``n_frames`` trial: the tracks read
    again from the review state and the strip drawn and handed to viser (target < 20 ms)."""
    from addb_viewer.app.server import ReviewApp
    from addb_viewer.app.timeline import track_data

    long = tiled_trial(out, n_frames)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "out"
        save_processed(folder / "walk2000" / "trial.npz", long)
        os.environ["XDG_CACHE_HOME"] = tmp
        app = ReviewApp(ReviewPaths.for_subject(DEMO_SUBJECT, folder), reviewer="bench", port=0, background=False)
        try:
            times, edit_times = [], []
            for k in range(edits):
                app.select(50 * k, 50 * k + 30)
                t0 = time.perf_counter()
                app.selection_edit("Flag")  # the store edit (journal fsync) and the redraw it triggers
                edit_times.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                app.tracks = track_data(app.trial, app.editor.view(), app.hicks)
                app.draw_timeline()
                times.append(time.perf_counter() - t0)
        finally:
            app.stop()
    print(f"timeline redraw after an edit, {n_frames}-frame trial (review state read, tracks, strip, image "
          f"handed to viser): {_stats(times)}; the whole edit incl. the durable store write: {_stats(edit_times)}")


def bench_memory(out: Path, n_frames: int = 2000) -> None:
    """RSS of an ``addb view`` process showing a ``n_frames`` trial (demo arrays tiled)."""
    long = tiled_trial(out, n_frames)
    arrays = {f.name: getattr(long, f.name) for f in dataclasses.fields(long)
              if isinstance(getattr(long, f.name), np.ndarray) and getattr(long, f.name).shape[:1] == (n_frames,)}
    plates = long.plates
    nbytes = sum(a.nbytes for a in arrays.values()) + sum(p.force.nbytes * 3 + p.body.nbytes for p in plates)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "out"
        save_processed(folder / "walk2000" / "trial.npz", long)
        env = dict(os.environ, XDG_CACHE_HOME=tmp)
        res = subprocess.run([sys.executable, "-c", _MEMORY_CHILD, str(folder), str(n_frames), str(REPO)],
                             capture_output=True, text=True, env=env, timeout=300, check=False)
        if res.returncode:
            raise RuntimeError(res.stderr[-2000:])
        m = json.loads(res.stdout.strip().splitlines()[-1])
    print(f"memory, {n_frames}-frame trial (demo tiled; arrays {nbytes / 1e6:.1f} MB): process RSS "
          f"{m['base']:.0f} MB after imports, {m['loaded']:.0f} MB with the trial shown (+{m['loaded'] - m['base']:.0f} MB), "
          f"{m['after']:.0f} MB after {n_frames // 10} seeks, peak {m['peak']:.0f} MB")
    print(f"  render with 4 chart updates at {n_frames} frames: median {m['render_ms']:.1f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="the demo already processed into this folder")
    args = parser.parse_args()
    tmp = None
    out = args.out
    if out is None:
        from solver.pipeline import process_subject

        tmp = tempfile.TemporaryDirectory()
        out = Path(tmp.name) / "out"
        t0 = time.perf_counter()
        process_subject(DEMO_SUBJECT, out)
        print(f"processed the demo (full pipeline) in {time.perf_counter() - t0:.1f} s")
    try:
        bench_frame_update(out)
        bench_timeline(out)
        bench_startup(out)
        bench_memory(out)
    finally:
        if tmp is not None:
            tmp.cleanup()


if __name__ == "__main__":
    main()
