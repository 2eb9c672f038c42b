"""The `ktcs-bench` command: thin argparse front-ends over library objects.

Each module here that defines `register(subparsers)` adds one subcommand; `main` discovers them, so
a new tool is a new file. Exit codes: 0 success, 1 a check failed (CRC error, conformance failure,
difference on replay), 2 usage or configuration error, 3 a peer or I/O failure, 130 interrupted.

Must not hold logic a library call cannot reach: everything a subcommand does is a call into
the packages below, and nothing below imports `cli`.
"""
