"""One module per ``addb`` subcommand. Each defines ``register(subparsers)`` that adds its
parser and sets ``handler`` to a function ``(args) -> exit code``; heavy imports happen
inside the handler so that ``addb --help`` stays fast."""
