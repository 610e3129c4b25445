"""The lab side: drive signals, harmonic estimation, force control, DAQ backends, and the runs.

Data flow of a run (``python -m rig run``): a lab setup (:mod:`rig.setup`) and a test plan
(:mod:`rig.plans`) become a procedure of commands (:mod:`rig.run_stepped`,
:mod:`rig.run_random`, :mod:`rig.pretest`, :mod:`rig.commands`) that the engine
(:mod:`rig.engine`) executes on a DAQ backend (:mod:`rig.backends`), checking every block
(:mod:`rig.safety`), publishing events (:mod:`rig.events`) and writing each completed step to
the measurement file; :mod:`rig.runner` ties this to the device lock (:mod:`rig.lock`), the
amplifier (:mod:`rig.instruments`) and the file; :mod:`rig.export_uff` exports FRFs.
"""
