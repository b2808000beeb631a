"""The dynamics stage: the AddBiomechanics dynamics pass with unmeasured-force frames (stage.py
runs it in order; the README's "How the dynamics work")."""
