"""The model workbench: a run and a model side by side, the diagnosis, adding an effect.

Load a stepped-sine run and a model file (or the reference rig, or the model of a calibration
result); *Compare* shows measured against model FRFs and the residual maps; *Diagnose* runs
:func:`analysis.diagnosis.diagnose` in a worker thread with its progress and shows the verdict,
the evidence and the ranked candidates; *Add effect and recalibrate* runs
:func:`analysis.diagnosis.augment` on the selected candidate with the error falling live; on a
tie, *Run the separating test* writes the measurement that separates the tied candidates as a
plan, runs it on the simulated rig the opened run was made on (:func:`rig.run.session.open_rig`
and :class:`rig.run.session.TestRun`, as ``rig run`` does) and ranks them again on the new file.
The Calibration and Planning tabs show calibration result files and pretest plans. Everything is
computed by the analysis package's public API; this module only arranges it.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from analysis.diagnosis import (
    BranchMatchedPredictor,
    augment,
    compare,
    diagnose,
)
from analysis.events import Event, EventBus, Iteration, Listener, StageDone, UnitDone
from analysis.measurement_file import MeasurementFileError, SteppedSineData, read_measurement
from analysis.model import load_model
from rig.gui.comparison_view import ComparisonView
from rig.gui.diagnosis_options import DiagnosisOptions
from rig.gui.diagnosis_view import DiagnosisView
from rig.gui.planning_view import CalibrationView, PlanningView
from rig.gui.residual_view import ResidualView
from rig.gui.run_setup import runs_folder
from rig.gui.style import ALARM
from rig.gui.tasks import Task

__all__ = ["WorkbenchPanel"]

logger = logging.getLogger(__name__)


class _FileRow(QtWidgets.QWidget):
    """A label, a path and an Open button."""

    def __init__(self, label: str, pattern: str, parent=None) -> None:
        super().__init__(parent)
        self.pattern = pattern
        self.path = QtWidgets.QLineEdit()
        self.path.setReadOnly(True)
        self.path.setPlaceholderText("none")
        self.button = QtWidgets.QPushButton("Open…")
        row = QtWidgets.QHBoxLayout(self)
        row.setContentsMargins(0, 0, 0, 0)
        title = QtWidgets.QLabel(label)
        title.setMinimumWidth(110)
        row.addWidget(title)
        row.addWidget(self.path, 1)
        row.addWidget(self.button)

    def ask(self, parent) -> str:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(parent, "Open", "", self.pattern)
        return name


class WorkbenchPanel(QtWidgets.QWidget):
    """Compare a model with a run, diagnose it, add an effect, see plans and calibrations.

    Signals
    -------
    task_finished(str, bool)
        A background task (``"compare"``, ``"diagnosis"``, ``"recalibration"``,
        ``"planning"``, ``"separating test"``) ended, successfully or not.

    Parameters
    ----------
    controller : RunController, optional
        Where the window runs tests (:mod:`rig.gui.controller`): the separating test runs in
        this process only, so with the acquisition service it is written and not run; its
        ``lock_dir`` is used for the simulated rig's lock. None: this process, default locks.
    """

    task_finished = QtCore.Signal(str, bool)

    def __init__(self, controller=None, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.controller = controller
        self.separation = None
        self.data: SteppedSineData | None = None
        self.model: Any = None
        self.model_label = ""
        self.linear_run: Path | None = None
        self.comparison = None
        self.before = None
        self.diagnosis = None
        self.augmented = None
        self.task: Task | None = None

        self.run_row = _FileRow("run (stepped sine)", "HDF5 files (*.h5 *.hdf5)")
        self.model_row = _FileRow("model", "Model files (*.toml)")
        self.reference_button = QtWidgets.QPushButton("Reference rig")
        self.reference_button.setToolTip("the shipped model of the rig (nominal values)")
        self.model_row.layout().addWidget(self.reference_button)
        self.linear_row = _FileRow("linear run (optional)", "HDF5 files (*.h5 *.hdf5)")
        self.linear_row.setToolTip("the random test, for recalibrating linear candidates")
        self.compare_button = QtWidgets.QPushButton("Compare")
        self.diagnose_button = QtWidgets.QPushButton("Diagnose")
        self.augment_button = QtWidgets.QPushButton("Add effect and recalibrate")
        self.augment_button.setToolTip(
            "add the candidate selected in the ranking to the model and recalibrate everything"
        )
        self.save_button = QtWidgets.QPushButton("Save augmented model…")
        self.separate_button = QtWidgets.QPushButton("Run the separating test")
        self.separate_button.setToolTip(
            "on a tie: run the measurement that separates the tied candidates on the simulated "
            "rig the run was made on, then rank them again on the new file"
        )
        self.stage = QtWidgets.QLabel("")
        self.progress = QtWidgets.QProgressBar()
        self.progress.setMaximumWidth(260)
        self.progress.hide()
        self.options = DiagnosisOptions()

        self.frfs = ComparisonView()
        self.residuals = ResidualView()
        self.diagnosis_view = DiagnosisView()
        self.calibration_view = CalibrationView()
        self.planning_view = PlanningView()
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(self.frfs, "Measured vs model FRFs")
        self.tabs.addTab(self.residuals, "Residual map")
        self.tabs.addTab(self.diagnosis_view, "Diagnosis")
        self.tabs.addTab(self.calibration_view, "Calibration")
        self.tabs.addTab(self.planning_view, "Planning")

        self._lay_out()
        self._connect()
        self._calibrated: Any = None
        self._buttons()

    def _connect(self) -> None:
        """The buttons to their actions."""
        self.run_row.button.clicked.connect(lambda: self._ask(self.run_row, self.open_run))
        self.model_row.button.clicked.connect(lambda: self._ask(self.model_row, self.open_model))
        self.linear_row.button.clicked.connect(
            lambda: self._ask(self.linear_row, self.open_linear_run)
        )
        self.reference_button.clicked.connect(lambda: self.open_model(None))
        self.compare_button.clicked.connect(self.compare)
        self.diagnose_button.clicked.connect(self.diagnose)
        self.augment_button.clicked.connect(self.augment_selected)
        self.save_button.clicked.connect(self._save_dialog)
        self.separate_button.clicked.connect(self.run_separating_test)
        self.calibration_view.open_button.clicked.connect(self._open_calibration_dialog)
        self.calibration_view.use_button.clicked.connect(self.use_calibrated_model)
        self.planning_view.run_button.clicked.connect(self.run_planning)
        self.planning_view.open_button.clicked.connect(self._open_plan_dialog)

    def _lay_out(self) -> None:
        """The inputs and actions on top; the views beside the diagnosis options."""
        inputs = QtWidgets.QVBoxLayout()
        inputs.addWidget(self.run_row)
        inputs.addWidget(self.model_row)
        inputs.addWidget(self.linear_row)
        actions = QtWidgets.QHBoxLayout()
        for b in (
            self.compare_button,
            self.diagnose_button,
            self.augment_button,
            self.separate_button,
            self.save_button,
        ):
            actions.addWidget(b)
        actions.addWidget(self.progress)
        actions.addWidget(self.stage, 1)
        inputs.addLayout(actions)
        scroll = QtWidgets.QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.options)
        scroll.setMaximumWidth(360)
        top = QtWidgets.QHBoxLayout()
        top.addLayout(inputs, 1)
        body = QtWidgets.QSplitter()
        body.addWidget(self.tabs)
        body.addWidget(scroll)
        body.setSizes([1300, 330])
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(top)
        layout.addWidget(body, 1)

    # -- inputs ----------------------------------------------------------------------------
    def _ask(self, row: _FileRow, action) -> None:
        name = row.ask(self)
        if name:
            action(name)

    def _say(self, text: str, error: bool = False) -> None:
        self.stage.setText(f"<span style='color:{ALARM}'>{text}</span>" if error else text)

    def open_run(self, path: str | Path) -> bool:
        """Load a stepped-sine run."""
        try:
            data = read_measurement(path)
        except (MeasurementFileError, OSError, ValueError) as exc:
            self._say(f"cannot read {path}: {exc}", error=True)
            return False
        if not isinstance(data, SteppedSineData) or data.n_steps == 0:
            self._say(f"{path}: a stepped-sine run with steps is needed", error=True)
            return False
        self.data = data
        self.run_row.path.setText(str(path))
        self._reset_results()
        self._say(
            f"run: {data.n_steps} steps, levels {'/'.join(f'{v:g}' for v in data.levels_n)} N"
        )
        return True

    def open_model(self, path: str | Path | None) -> bool:
        """Load a model file (None: the shipped reference rig)."""
        try:
            model = load_model(path)
        except (OSError, ValueError) as exc:
            self._say(f"cannot load the model: {exc}", error=True)
            return False
        self.model = model
        self.model_label = "reference rig (nominal)" if path is None else Path(path).name
        self.model_row.path.setText(self.model_label if path is None else str(path))
        self._reset_results()
        self._say(f"model: {self.model_label}")
        return True

    def open_linear_run(self, path: str | Path) -> bool:
        self.linear_run = Path(path)
        self.linear_row.path.setText(str(path))
        return True

    def open_calibration(self, path: str | Path) -> bool:
        """Show a calibration result (``calibration.json``); its model can then be used."""
        from analysis.calibration.results import load_calibration

        try:
            result, model, data_path = load_calibration(path)
        except (OSError, ValueError) as exc:
            self._say(f"cannot read the calibration: {exc}", error=True)
            return False
        self._calibrated = (result, model, Path(path))
        self.calibration_view.show_calibration(result, data_path, str(path))
        if self.data is None and data_path and Path(data_path).exists():
            self.open_run(data_path)
        self.tabs.setCurrentWidget(self.calibration_view)
        return True

    def use_calibrated_model(self) -> None:
        if self._calibrated is None:
            return
        result, model, path = self._calibrated
        self.model = result.calibrated_model(model)
        self.model_label = f"calibrated ({path.name})"
        self.model_row.path.setText(f"{self.model_label}: {path}")
        self._reset_results()

    def _reset_results(self) -> None:
        self.comparison = self.before = self.diagnosis = self.augmented = None
        self.separation = None
        self._buttons()

    def _buttons(self) -> None:
        idle = self.task is None
        ready = idle and self.data is not None and self.model is not None
        self.compare_button.setEnabled(ready)
        self.diagnose_button.setEnabled(ready)
        ranked = self.diagnosis is not None and bool(self.diagnosis.ranking)
        self.augment_button.setEnabled(ready and ranked)
        d = self.diagnosis
        tied = d is not None and len(d.group) > 1 and bool(d.recommendation)
        self.separate_button.setEnabled(ready and tied)
        self.save_button.setEnabled(idle and self.augmented is not None)
        self.planning_view.run_button.setEnabled(idle)

    # -- tasks -----------------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self.task is not None

    def _start(self, name: str, work, on_done, on_progress=None) -> bool:
        if self.task is not None:
            return False
        task = Task(name, work, self)
        self.task = task
        self.progress.setRange(0, 0)
        self.progress.show()
        self._say(f"{name}…")
        task.progress.connect(on_progress or self._progress)

        def done(result: Any) -> None:
            self._end_task()
            self._say(f"{name} done")
            on_done(result)  # may say more
            self.task_finished.emit(name, True)

        def failed(message: str) -> None:
            self._end_task()
            self._say(message, error=True)
            self.task_finished.emit(name, False)

        task.done.connect(done)
        task.failed.connect(failed)
        self._buttons()
        task.start()
        return True

    def _end_task(self) -> None:
        if self.task is not None:
            self.task.wait()
            self.task.deleteLater()
        self.task = None
        self.progress.hide()
        self._buttons()

    def _progress(self, event: Event) -> None:
        """A task's :mod:`analysis.events`: counted units on the progress bar, iterations and
        milestones in the status line."""
        if isinstance(event, UnitDone) and event.total:
            self.progress.setRange(0, event.total)
            self.progress.setValue(event.done)
            label = f": {event.label}" if event.label else ""
            self._say(f"{event.stage} {event.done}/{event.total}{label}")
            return
        self.progress.setRange(0, 0)
        if isinstance(event, Iteration):
            self._say(f"{event.stage}: iteration {event.iteration}, metric {event.cost:.4g}")
        elif isinstance(event, StageDone):
            self._say(event.text())

    # -- compare, diagnose, augment ----------------------------------------------------------
    def compare(self) -> bool:
        """Measured against model FRFs and the residual maps (in a worker thread)."""
        if self.data is None or self.model is None:
            return False
        model, data = self.model, self.data

        def work(report):
            return compare(model, data, predictor=BranchMatchedPredictor(model, data))

        return self._start("compare", work, self._compared)

    def _compared(self, cmp) -> None:
        self.comparison, self.before = cmp, None
        self._show_comparison(self.model_label)
        self.tabs.setCurrentIndex(0)
        self._say(
            f"compared with {self.model_label}: residual {cmp.rms_over_noise:.3g} x noise "
            "(FRFs here, per sensor and order in the residual map)"
        )

    def compare_run(self, path: str | Path) -> bool:
        """Open a run and compare it with the model (the shipped reference rig when none is
        loaded): the FRFs and residual maps appear when the comparison ends. False, with the
        reason in the status line, when it cannot start."""
        if self.task is not None:
            self._say(f"{self.task.name} is running: open {Path(path).name} when it ends")
            return False
        if not self.open_run(path):
            return False
        if self.model is None and not self.open_model(None):
            return False
        return self.compare()

    def diagnose(self) -> bool:
        """Which effect is missing (in a worker thread, with progress)."""
        if self.data is None or self.model is None:
            return False
        try:
            settings = self.options.settings()
        except ValueError as exc:
            self._say(f"diagnosis settings: {exc}", error=True)
            return False
        cands = self.options.candidates(self.model)
        if cands is not None and not cands:
            self._say("no candidate matches the location and law filters", error=True)
            return False
        model, data, linear = self.model, self.data, self.linear_run

        def work(report):
            return diagnose(
                model, data, linear_run=linear, candidates=cands, settings=settings, progress=report
            )

        return self._start("diagnosis", work, self._diagnosed)

    def _diagnosed(self, d) -> None:
        self.diagnosis, self.separation = d, None
        self.comparison, self.before, self.augmented = d.comparison, None, None
        self.diagnosis_view.show_diagnosis(d)
        self._show_comparison(self.model_label)
        self.tabs.setCurrentWidget(self.diagnosis_view)
        self._buttons()

    def augment_selected(self) -> bool:
        """Add the selected (by default the best) candidate and recalibrate everything."""
        ranked = self.diagnosis_view.selected()
        if ranked is None or self.data is None or self.model is None:
            return False
        model, data, linear = self.model, self.data, self.linear_run
        cand, screen = ranked.candidate, ranked.screen
        values = dict(screen.values) if screen is not None else None
        known = dict(screen.known) if screen is not None else None
        n_starts = self.options.starts.value()
        self.diagnosis_view.augment_started(cand.label, self.diagnosis.comparison.rms_over_noise)
        self.tabs.setCurrentWidget(self.diagnosis_view)

        def work(report):
            return augment(
                model,
                data,
                cand,
                values=values,
                known=known,
                linear_run=linear,
                n_starts=n_starts,
                progress=report,
            )

        def progress(event: Event) -> None:
            self.diagnosis_view.augment_progress(event)
            self._progress(event)

        return self._start("recalibration", work, self._augmented, progress)

    def _augmented(self, result) -> None:
        self.augmented = result
        self.diagnosis_view.augment_finished(result)
        self.before, self.comparison = result.before, result.after
        self._show_comparison(f"with {result.candidate.label}")
        self._buttons()

    def save_augmented(self, path: str | Path) -> Path:
        """Write the augmented model to a new file."""
        if self.augmented is None:
            raise ValueError("no augmented model: add an effect first")
        return Path(self.augmented.save(path))

    def _save_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getSaveFileName(
            self, "Save the augmented model", "augmented_model.toml", "Model files (*.toml)"
        )
        if name:
            try:
                self._say(f"model written to {self.save_augmented(name)}")
            except (OSError, ValueError) as exc:
                self._say(str(exc), error=True)

    # -- the separating test ---------------------------------------------------------------
    def _needs_the_rig(self, data: SteppedSineData) -> str:
        """Why the separating test cannot run here ("" when it can)."""
        from rig.gui.controller import LocalRunController
        from rig.run.session import previous_rig

        c = self.controller
        if c is not None and not isinstance(c, LocalRunController):
            return (
                f"this window runs tests on {c.description}: the separating test needs the rig "
                "there; run the plan from the Acquisition tab"
            )
        backend, options = previous_rig(data.config)
        if backend != "sim":
            made = f"on the {backend!r} backend" if backend else "on a rig the file does not name"
            return (
                f"{data.path.name} was made {made}, not on the simulated rig: the separating "
                "test needs the rig; run the plan from the Acquisition tab or with rig run"
            )
        if "truth" not in options:
            return f"{data.path.name} does not record its simulated rig's truth structure"
        return ""

    def run_separating_test(self) -> bool:
        """On a tie: write the separating plan, run it on the opened run's simulated rig (in a
        worker thread) and rank the tied candidates on the new file. Where the test needs the
        rig (hardware, the acquisition service) the plan is written and the view says so."""
        from analysis.diagnosis.separate import write_separating_plan

        d, data = self.diagnosis, self.data
        if d is None or data is None or len(d.group) < 2 or not d.recommendation:
            return False
        out = _free_path(runs_folder(), f"{data.path.stem}-separate", ".h5")
        plan_path = out.with_suffix(".plan.toml")
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            write_separating_plan(plan_path, d.recommendation, data)
        except (OSError, ValueError) as exc:
            self._say(f"cannot write the separating plan: {exc}", error=True)
            return False
        self.tabs.setCurrentWidget(self.diagnosis_view)
        why = self._needs_the_rig(data)
        if why:
            self.diagnosis_view.show_separation_note(why, plan_path)
            self._say(f"the separating test needs the rig: plan written to {plan_path}")
            return False
        lock_dir = getattr(self.controller, "lock_dir", None)
        group, tie = list(d.group), d.settings.tie_bic

        def work(report):
            from analysis.diagnosis.separate import rank_on_separating_run

            path = _separating_run(plan_path, out, data, lock_dir, report)
            return rank_on_separating_run(group, read_measurement(path), tie), path

        note = f"running the separating test on the simulated rig into {out.name}…"
        self.diagnosis_view.show_separation_note(note, plan_path)
        return self._start("separating test", work, self._separated)

    def _separated(self, result) -> None:
        sep, path = result
        self.separation = sep
        self.diagnosis_view.show_separation(sep, path)
        self.tabs.setCurrentWidget(self.diagnosis_view)
        if sep.resolved:
            self._say(f"separating test: {sep.tied[0]} first alone ({Path(path).name})")
        else:
            self._say(f"separating test: still tied, {'; '.join(sep.tied)}")

    # -- display ---------------------------------------------------------------------------
    def _show_comparison(self, title: str) -> None:
        self.frfs.show_comparison(self.data, self.comparison, self.before, self.model_label)
        self.residuals.show_comparison(self.comparison, title)

    # -- planning --------------------------------------------------------------------------
    def run_planning(self) -> bool:
        """Rank test configurations by det(FIM) with the model (in a worker thread)."""
        from analysis.planning import PAPER_LINEAR, paper_candidates, plan_tests, quick_candidates

        params = self.planning_view.parameter_names()
        model = self.model if self.model is not None else load_model().with_values(PAPER_LINEAR)
        which = self.planning_view.candidates.currentData()
        make = quick_candidates if which == "quick" else paper_candidates

        def work(report):
            return plan_tests(model, make(params), executor=None).to_dict()

        def done(result: dict) -> None:
            self.planning_view.show_plan(result)
            self.tabs.setCurrentWidget(self.planning_view)

        return self._start("planning", work, done)

    def open_plan_json(self, path: str | Path) -> bool:
        """Show a plan saved by ``python -m analysis plan --json``."""
        try:
            result = json.loads(Path(path).read_text())
            self.planning_view.show_plan(result)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            self._say(f"{path}: not a plan result ({exc})", error=True)
            return False
        self.tabs.setCurrentWidget(self.planning_view)
        return True

    def _open_plan_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open a plan", "", "JSON (*.json)")
        if name:
            self.open_plan_json(name)

    def _open_calibration_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, "Open a calibration result", "", "JSON (*.json)"
        )
        if name:
            self.open_calibration(name)

    def shutdown(self) -> None:
        if self.task is not None:
            self.task.wait()


def _free_path(folder: Path, stem: str, suffix: str) -> Path:
    """``folder/stem.suffix``, numbered ``-2``, ``-3``... when it or its plan is taken."""
    path, n = folder / f"{stem}{suffix}", 2
    while path.exists() or path.with_suffix(".plan.toml").exists():
        path, n = folder / f"{stem}-{n}{suffix}", n + 1
    return path


def _separating_run(
    plan_path: Path, out: Path, first: SteppedSineData, lock_dir: Any, report: Listener
) -> Path:
    """Run the plan on the simulated rig ``first`` was made on (its truth, seed and lab setup)
    as ``rig run`` does; each step written is reported. Returns the new file."""
    from rig.config.plans import load_plan
    from rig.config.setup import load_setup, setup_from_dict
    from rig.run.events import StepFinished
    from rig.run.session import TestRun, open_rig, previous_rig

    plan = load_plan(plan_path)
    # the bench the first run was made on (its sensors, sample rate), else the plan's own
    setup = setup_from_dict(first.setup, str(first.path)) if first.setup else load_setup(plan.setup)
    _, previous = previous_rig(first.config)
    options = {**previous, "sensor_masses_kg": setup.sensor_masses_kg()}
    info = {"backend": "sim", "backend_options": previous, "client": "rig gui"}
    bus = EventBus()

    def step(e: Event) -> None:
        if isinstance(e, StepFinished):
            hz = f"{e.record.frequency_hz:.4g} Hz"
            report(UnitDone("separating run", e.n_done, e.n_steps, hz))

    bus.subscribe(step, kinds=(StepFinished,))
    with open_rig("sim", setup, backend_options=options, lock_dir=lock_dir) as rig:
        run = TestRun(
            rig.backend, plan, setup, out, bus=bus, amplifier=rig.amplifier, run_info=info
        )
        summary = run.execute()
    if summary.status != "success":
        raise RuntimeError(
            f"the separating run ended {summary.status}: {summary.message} "
            f"({summary.n_done} of {summary.n_planned} steps kept in {out})"
        )
    return out
