"""Measurement files written out in other tools' formats (UFF dataset 58:
:mod:`~rig.export.uff`)."""
