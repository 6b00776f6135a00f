"""`python -m bench.cli`: the same as the `gyrobench` command."""

from bench.cli import entry

entry()
