"""``python -m campipe``: the command line."""

from campipe.cli import main

main()
