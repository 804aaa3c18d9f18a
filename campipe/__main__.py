"""``python -m campipe``: the command line."""

from campipe.cli import main

# Guarded: a spawned worker process (the processes scheduler, compiling the kernels in two
# processes) imports this module again as ``__mp_main__`` and must not run the command.
if __name__ == "__main__":
    main()
