"""One module per ``addb`` subcommand. Each defines ``register(subparsers)`` that adds its
parser and sets ``handler`` to its ``run(args) -> exit code``; heavy imports happen inside the
handler so that ``addb --help`` stays fast. A handler raises :class:`solver.errors.AddbError`
or :class:`annotations.AnnotationError` for bad input (naming the file, line or frame):
:func:`addb_viewer.cli.main` prints it and exits with 1."""
