"""``python -m rig`` (also the ``rig`` command): the lab side's command line."""

from rig.cli.main import main

if __name__ == "__main__":
    raise SystemExit(main())
