"""The ``motor-comp`` command line: one module per subcommand."""
