"""One module per ``addb`` subcommand. Each defines ``register(subparsers)`` that adds its
parser and sets ``handler`` to its ``run(args) -> exit code``; heavy imports happen inside the
handler so that ``addb --help`` stays fast. A handler raises :class:`solver.errors.AddbError`
or :class:`annotations.AnnotationError` for bad input (naming the file, line or frame):
:func:`addb_viewer.cli.main` prints it and exits with 1."""

from __future__ import annotations

import argparse
from collections.abc import Callable

#: The ``--fit`` names of ``addb process`` and ``addb info``: :data:`solver.pipeline.FIT_CHOICES`,
#: written out because the CLI does not import the pipeline at start-up (a test compares them).
FIT_CHOICES = ("default", "converged", "rounds", "band")


def fit_settings(fit: str) -> dict[str, str]:
    """The ``settings`` a dataset run keys its subjects on for ``--fit fit``
    (:attr:`solver.dataset.runner.DatasetOptions.settings`): ``{}`` for ``default``, so that a
    plain ``addb process DATASET_DIR`` keeps its key, else ``{"fit": fit}``. ``addb process
    DATASET_DIR --fit`` records it and ``addb info DATASET_DIR --fit`` compares with it, so the
    two cannot disagree."""
    return {"fit": fit} if fit != "default" else {}


def whole_number(least: int) -> Callable[[str], int]:
    """An argparse ``type`` for a whole number of at least ``least``: the parser it returns
    raises ``argparse.ArgumentTypeError`` for any other text, so ``--workers -1`` is refused at
    the command line ("expected a whole number of at least 1, got '-1'") instead of reaching
    Dask, where no worker would ever start."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"expected a whole number of at least {least}, got {text!r}")
        return value

    return parse


def memory_size(text: str) -> str:
    """An argparse ``type`` for a worker's memory limit: ``auto``, or a size Dask reads
    (``4GB``, ``500MiB``, ``2e9``) above zero; anything else raises
    ``argparse.ArgumentTypeError``, so it is refused at the command line instead of failing
    inside Dask's parser once the run has started."""
    if text.strip().lower() == "auto":
        return "auto"
    from dask.utils import parse_bytes

    try:
        value = parse_bytes(text)
    except (ValueError, TypeError):
        raise argparse.ArgumentTypeError(f"expected a size such as 4GB or 500MiB, or auto, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a size above zero, got {text!r}")
    return text


def output_folder(text: str) -> str:
    """An argparse ``type`` for an ``--out`` folder a command writes (``process``,
    ``kinematics``, ``convert``): ``argparse.ArgumentTypeError`` when the path is a file, or
    lies under a file, so that the command refuses at once instead of after computing
    everything (the folder itself is made, or replaced, when the outputs are written)."""
    from pathlib import Path

    path = Path(text).expanduser()
    if path.is_file():
        raise argparse.ArgumentTypeError(f"{text} is a file; expected a folder (new, empty, or an earlier output of addb)")
    for parent in path.absolute().parents:
        if parent.is_file():
            raise argparse.ArgumentTypeError(f"{text} lies under {parent}, which is a file, not a folder")
        if parent.is_dir():
            break
    return text
