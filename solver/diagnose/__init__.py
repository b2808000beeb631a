"""`addb diagnose`: why a processed trial's residuals remain (the map of this folder and how to add a
cause: README.md here)."""
