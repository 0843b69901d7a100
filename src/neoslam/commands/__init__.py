"""The work behind each CLI command, one module a command: `simulate`, `run`, `detect`, `evaluate`, `route` (the
`sweep` command is its own package, neoslam.sweep, which runs its cells through `run`). The CLI only parses arguments
and calls these; they are also the Python API of a whole command."""
