"""The addb application: the `addb` command line (cli.py, one module per subcommand in
commands/), the browser review app (app/) and the recordings (recording/)."""
