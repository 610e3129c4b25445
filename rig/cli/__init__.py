"""Command lines of the lab side: ``python -m rig`` (:mod:`rig.cli.main` dispatches to
:mod:`rig.cli.run` for runs, :mod:`rig.cli.service` for the acquisition service and
:mod:`rig.cli.workflow` for the whole chain from the random test to the report)."""
