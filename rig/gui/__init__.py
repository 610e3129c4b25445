"""The lab GUI: the acquisition window (set up, run and watch a stepped-sine test) and the model
workbench (measured against model FRFs, residual maps, diagnosis, recalibration, planning).

``python -m rig gui`` starts it (:func:`rig.gui.app.main`); by default it runs plans on the
simulated rig in this process. The GUI is a leaf of the package tree: nothing imports it. It
runs the same engine, plans, setups and files as the command line (:mod:`rig.run.session`,
:mod:`rig.config.plans`, :mod:`rig.config.setup`) and the analysis through its public API
(:mod:`analysis.diagnosis`, :mod:`analysis.planning`, :mod:`analysis.calibration.results`).

Modules
-------
app
    The main window (acquisition, run browser and workbench as tabs) and the entry point.
qt_check
    Refuses a Qt binding that would crash the interpreter.
style, heatmap, frf_view
    Fonts, colours, plots with labelled axes; annotated heatmaps; multi-harmonic FRF plots.
settings_fields, forms, settings_editor, setup_editor, plan_editor
    Settings forms generated from the frozen settings dataclasses; validation messages from
    the settings' own errors, shown next to the field that is wrong; the lab-setup and plan
    editors (load, edit, check, save).
run_setup
    Backend, lab setup, plan and file of the next run.
controller, sample_tap, service_controller
    :class:`~rig.gui.controller.RunController` (what the window needs from whoever runs a
    test); the in-process implementation (the engine in a worker thread) with its tap on the
    samples read; the implementation on the acquisition service's client.
live_data, live_plots, run_control, acquisition
    Events accumulated into what the live plots show; the plots; the run-control strip and
    status panel; the acquisition tab.
run_browser
    Open a finished or interrupted measurement file and browse it.
tasks
    Slow analysis work (compare, diagnose, augment, plan) in a worker thread with progress.
comparison_view, residual_view, diagnosis_options, diagnosis_view, planning_view, workbench
    The workbench: measured against model FRFs, residual maps, the diagnosis and its
    settings, the recalibration, calibration and planning results.
"""
