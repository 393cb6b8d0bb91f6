"""``python -m station``: the same command line as the ``station`` console script."""

from station.cli import main

if __name__ == "__main__":  # pragma: no cover
    main()
