"""The lab side: what a run is told, how it runs, and the front ends that start it.

The folders follow a run's data flow (``python -m rig run``):

- :mod:`rig.config`: a lab setup and a test plan, read from TOML;
- :mod:`rig.procedures`: the plan becomes a procedure of commands (stepped sine with its force
  control, random test, pretest checks);
- :mod:`rig.signals` and :mod:`rig.estimation`: multi-sine and random synthesis, harmonic
  estimation, the settling test and FRFs;
- :mod:`rig.run`: the engine executes the commands on a DAQ backend (:mod:`rig.backends`),
  checks every block, publishes events and writes each completed step to the measurement file;
  the run session ties this to the device lock, the amplifier (:mod:`rig.instruments`) and the
  file;
- :mod:`rig.cli`, :mod:`rig.service`, :mod:`rig.gui`: the command line (and the whole
  workflow), the acquisition service and the lab GUI, which all start runs the same way;
- :mod:`rig.export`: measurement files in other tools' formats.
"""
