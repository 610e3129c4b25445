"""Test procedures as generators of commands: the stepped multi-sine run
(:mod:`~rig.procedures.stepped_sine`) with its off-line force control
(:mod:`~rig.procedures.force_control`, :mod:`~rig.procedures.gain_prediction`), the random
test (:mod:`~rig.procedures.random_test`) and the pretest checks
(:mod:`~rig.procedures.pretest`). They never touch hardware or Qt."""
