"""The diagnosis' causes: one module per cause (:mod:`.base` says what a cause provides),
listed by :mod:`.registry`. See solver/diagnose/README.md for the layout and how to add a
cause."""
