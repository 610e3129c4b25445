"""What a run is told: test plans (:mod:`~rig.config.plans` gathers the plan types, their
settings and the plan files) and lab setups (:mod:`~rig.config.setup`), declared once
(:mod:`~rig.config.settings`) and read from TOML with errors at their key path
(:mod:`~rig.config.tomlconfig`). The built-in files are in
``rig/plans/`` and ``rig/setups/``."""
