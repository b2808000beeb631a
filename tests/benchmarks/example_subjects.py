"""Subject folders for the benchmarks: the shared subjects, or examples assembled on demand.

An example (``scripts/make_example_subject.py NAME DIR``: the Camargo circuit and others)
is assembled once into the caller's temporary folder, outside any timed span.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SUBJECTS = REPO.parent / "shared" / "data" / "subjects"
EXAMPLES = ("camargo2021_levelground",)


def subject_folder(name: str, tmp: Path) -> Path:
    """The folder of subject ``name``: ``../shared/data/subjects/NAME``, or for a name of
    :data:`EXAMPLES` the example assembled into ``tmp/examples/NAME`` (once).

    Raises
    ------
    subprocess.CalledProcessError
        The example could not be assembled.
    """
    if name not in EXAMPLES:
        return SUBJECTS / name
    dst = tmp / "examples" / name
    if not dst.exists():
        subprocess.run([sys.executable, str(REPO / "scripts" / "make_example_subject.py"), name, str(dst)], check=True, capture_output=True)
    return dst
