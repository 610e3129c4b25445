"""Running a procedure: the engine that sequences commands on a backend and enforces safety
(:mod:`~rig.run.engine`, :mod:`~rig.run.commands`, :mod:`~rig.run.events`,
:mod:`~rig.run.safety`, :mod:`~rig.run.faults`), the device lock (:mod:`~rig.run.lock`), the
run session the command line, the GUI and the service share (:mod:`~rig.run.session`) and the
dry run that lists a plan's commands without hardware (:mod:`~rig.run.dry_run`)."""
