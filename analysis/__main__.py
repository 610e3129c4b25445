"""``python -m analysis``: the analysis command line (see ``--help``)."""

from analysis.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
