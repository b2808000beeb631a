"""The bundled demo subject (package data); see README.md in this folder."""

from __future__ import annotations

from pathlib import Path

DEMO_SUBJECT = Path(__file__).resolve().parent / "rajagopal2016_walk"
