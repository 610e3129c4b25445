"""Setting up a run: the backend (simulated rig or NI), the lab setup, the plan, the file.

:class:`RunSetupPanel` has three tabs: *Run* (backend, file, options), *Lab setup*
(:class:`~rig.gui.setup_editor.SetupEditor`) and *Plan* (:class:`~rig.gui.plan_editor.PlanEditor`).
It re-checks everything a moment after every edit: the plan and the setup by their loaders,
the plan's points against the setup's channels
(:meth:`rig.config.setup.LabSetup.channels_for_points`);
a problem is shown next to the field that causes it and the run cannot start until it is fixed.
:meth:`RunSetupPanel.request` gives the :class:`~rig.gui.controller.RunRequest` to start.

The measurement file of a run is a new one: by default ``run-YYYYmmdd-HHMMSS.h5`` in the runs
folder (:func:`runs_folder`, ``~/clearance-rig-runs`` unless ``CLEARANCE_RIG_RUNS`` names
another), and after each run a new name next to the last file (:func:`next_free_path`). A
file is replaced only when the operator ticks *replace an existing file*.
"""

from __future__ import annotations

import importlib.util
import os
import re
import time
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from rig.config.plans import Plan
from rig.config.setup import LabSetup, load_setup, setup_from_dict
from rig.config.tomlconfig import ConfigError
from rig.gui.controller import RunRequest
from rig.gui.plan_editor import PlanEditor
from rig.gui.setup_editor import SetupEditor
from rig.gui.style import ALARM, OK

__all__ = [
    "RUNS_FOLDER_ENV",
    "RunSetupPanel",
    "fresh_run_path",
    "next_free_path",
    "runs_folder",
    "simulated_truths",
]

#: Environment variable naming the folder of the GUI's new measurement files.
RUNS_FOLDER_ENV = "CLEARANCE_RIG_RUNS"

_STAMPED = re.compile(r"^run-\d{8}-\d{6}(-\d+)?$")
_NUMBERED = re.compile(r"^(.*?)-(\d+)$")


def runs_folder() -> Path:
    """Where the GUI puts new measurement files: ``$CLEARANCE_RIG_RUNS`` or
    ``~/clearance-rig-runs`` (created when the first run starts)."""
    named = os.environ.get(RUNS_FOLDER_ENV, "").strip()
    return Path(named).expanduser() if named else Path.home() / "clearance-rig-runs"


def _short(folder: Path) -> str:
    """A folder as a person writes it (``~/clearance-rig-runs``)."""
    try:
        return str(Path("~") / Path(folder).resolve().relative_to(Path.home().resolve()))
    except ValueError:
        return str(folder)


def _numbered(folder: Path, stem: str, suffix: str, n: int) -> Path:
    """``folder/stem-n.suffix`` with the first ``n`` not taken."""
    while (folder / f"{stem}-{n}{suffix}").exists():
        n += 1
    return folder / f"{stem}-{n}{suffix}"


def fresh_run_path(folder: Path | None = None, now: float | None = None) -> Path:
    """A file that does not exist yet: ``run-YYYYmmdd-HHMMSS.h5`` in ``folder`` (default
    :func:`runs_folder`), ``-2``, ``-3``... appended when that name is taken."""
    folder = runs_folder() if folder is None else Path(folder)
    stem = "run-" + time.strftime("%Y%m%d-%H%M%S", time.localtime(now))
    path = folder / f"{stem}.h5"
    return _numbered(folder, stem, ".h5", 2) if path.exists() else path


def next_free_path(last: Path, now: float | None = None) -> Path:
    """A new file next to ``last``: a new time stamp for a stamped name, otherwise the name
    numbered (``beam.h5`` -> ``beam-2.h5``, ``beam-2.h5`` -> ``beam-3.h5``)."""
    last = Path(last)
    suffix = last.suffix or ".h5"
    if _STAMPED.match(last.stem):
        return fresh_run_path(last.parent, now)
    numbered = _NUMBERED.match(last.stem)
    if numbered:
        return _numbered(last.parent, numbered.group(1), suffix, int(numbered.group(2)) + 1)
    return _numbered(last.parent, last.stem, suffix, 2)


def simulated_truths() -> list[str]:
    """Names of the simulated rig's truth structures, if the simulator is installed."""
    spec = importlib.util.find_spec("sim_backend")
    if spec is None or not spec.submodule_search_locations:
        return ["reference"]
    names: set[str] = set()
    for folder in spec.submodule_search_locations:
        names |= {p.stem for p in (Path(folder) / "truths").glob("*.toml")}
    return ["reference", *sorted(names - {"reference"})]


class BackendBox(QtWidgets.QWidget):
    """Backend and file of a run."""

    changed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.sim = QtWidgets.QRadioButton("simulated rig (in this process)")
        self.ni = QtWidgets.QRadioButton("NI-DAQmx device")
        self.sim.setChecked(True)
        self.truth = QtWidgets.QComboBox()
        self.truth.setEditable(True)
        self.truth.addItems(simulated_truths())
        self.truth.setToolTip("the structure the simulated rig hides (a name or a truth file)")
        self.seed = QtWidgets.QLineEdit()
        self.seed.setPlaceholderText("the truth's")
        self.seed.setToolTip("noise seed of the simulated rig (empty: the truth's own)")
        self.realtime = QtWidgets.QCheckBox("pace to the clock (as slow as a real test)")
        self.device = QtWidgets.QLineEdit()
        self.device.setPlaceholderText("the setup's DAQ device")
        self.path = QtWidgets.QLineEdit(str(fresh_run_path()))
        self.path.setToolTip(
            f"a new file for each run, by default in {runs_folder()} (the folder is made when "
            f"the run starts; {RUNS_FOLDER_ENV} names another)"
        )
        browse = QtWidgets.QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        self.new_file = QtWidgets.QPushButton("New file")
        self.new_file.setToolTip("a new, unused file name next to this one")
        self.new_file.clicked.connect(self.use_new_file)
        self.overwrite = QtWidgets.QCheckBox("replace an existing file")
        self.pause_on_fault = QtWidgets.QCheckBox("pause on recoverable faults")
        self.pause_on_fault.setToolTip(
            "clipping, a silent sensor, lost force or an amplifier overload pause the run "
            "(output ramped to 0 V) instead of ending it; fix the cause and resume"
        )
        self.pause_on_fault.setChecked(True)
        self.resume_note = QtWidgets.QLabel("")
        self.resume_note.setWordWrap(True)
        self.resume_note.setStyleSheet("color: #0072B2; font-weight: bold;")
        self.cancel_resume = QtWidgets.QPushButton("New run instead")
        self.cancel_resume.hide()
        self.path_error = QtWidgets.QLabel("")
        self.path_error.setStyleSheet(f"color: {ALARM};")
        self.path_error.setWordWrap(True)
        self.path_error.hide()

        self._lay_out(browse)
        for w in (self.sim, self.ni, self.realtime, self.overwrite, self.pause_on_fault):
            w.toggled.connect(self._changed)
        for line in (self.seed, self.device, self.path):
            line.textChanged.connect(self._changed)
        self.truth.currentTextChanged.connect(self._changed)
        self._changed()

    def _lay_out(self, browse: QtWidgets.QPushButton) -> None:
        """The backend's group above the measurement file's."""
        backend = QtWidgets.QGroupBox("Backend")
        form = QtWidgets.QFormLayout(backend)
        form.addRow(self.sim)
        form.addRow("truth structure", self.truth)
        form.addRow("noise seed", self.seed)
        form.addRow(self.realtime)
        form.addRow(self.ni)
        form.addRow("device", self.device)
        out = QtWidgets.QGroupBox("Measurement file")
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.path, 1)
        row.addWidget(self.new_file)
        row.addWidget(browse)
        form2 = QtWidgets.QFormLayout(out)
        form2.addRow("file", row)
        form2.addRow("", self.path_error)
        form2.addRow(self.overwrite)
        form2.addRow(self.pause_on_fault)
        form2.addRow(self.resume_note)
        form2.addRow(self.cancel_resume)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(backend)
        layout.addWidget(out)
        layout.addStretch(1)

    def set_remote(self, where: str) -> None:
        """Runs go to ``where``, which owns the rig: its backend and setup apply."""
        for w in (self.sim, self.ni, self.truth, self.seed, self.realtime, self.device):
            w.setEnabled(False)
        self.resume_note.setText(
            f"runs on {where}: its backend and lab setup apply; the plan is sent and the file "
            "is written in its results folder under this file name"
        )
        self._remote = True

    def _changed(self, *_args) -> None:
        if getattr(self, "_remote", False):
            self.changed.emit()
            return
        sim = self.sim.isChecked()
        for w in (self.truth, self.seed, self.realtime):
            w.setEnabled(sim)
        self.device.setEnabled(not sim)
        self.changed.emit()

    def use_new_file(self) -> Path:
        """Put a new, unused file name next to the current one (or in the runs folder)."""
        text = self.path.text().strip()
        path = next_free_path(Path(text).expanduser()) if text else fresh_run_path()
        self.path.setText(str(path))
        return path

    def _browse(self) -> None:
        text = self.path.text().strip()
        start = text if text and Path(text).expanduser().parent.is_dir() else ""
        name, _ = QtWidgets.QFileDialog.getSaveFileName(
            self, "Measurement file", start or str(runs_folder()), "HDF5 files (*.h5)"
        )
        if name:
            self.path.setText(name)

    @property
    def backend(self) -> str:
        return "sim" if self.sim.isChecked() else "ni"

    def options(self) -> dict[str, Any]:
        """Backend options (raises ValueError for a seed that is not an integer)."""
        if self.backend == "ni":
            device = self.device.text().strip()
            return {"device": device} if device else {}
        options: dict[str, Any] = {"truth": self.truth.currentText().strip() or "reference"}
        seed = self.seed.text().strip()
        if seed:
            try:
                options["seed"] = int(seed)
            except ValueError:
                raise ValueError(f"noise seed: expected an integer, got {seed!r}") from None
        if self.realtime.isChecked():
            options["realtime"] = True
        return options


class RunSetupPanel(QtWidgets.QTabWidget):
    """Backend, setup and plan of the next run, checked as they are edited.

    Signals
    -------
    validity_changed(bool, str)
        Whether a run can start, and the first problem otherwise.
    """

    validity_changed = QtCore.Signal(bool, str)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.run_box = BackendBox()
        self.setup_editor = SetupEditor()
        self.plan_editor = PlanEditor()
        self.addTab(self.run_box, "Run")
        self.addTab(self.setup_editor, "Lab setup")
        self.addTab(self.plan_editor, "Plan")
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)
        self.plan: Plan | None = None
        self.setup: LabSetup | None = None
        self.valid = False
        self.problem = ""
        self.settings_problem = ""
        self.resume_path: Path | None = None
        self._timer = QtCore.QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(250)
        self._timer.timeout.connect(self.check)
        for signal in (self.run_box.changed, self.setup_editor.edited, self.plan_editor.edited):
            signal.connect(self._timer.start)
        self.plan_editor.loaded.connect(self._plan_loaded)
        self.run_box.cancel_resume.clicked.connect(self.cancel_resume)
        self.setup_editor.load("reference")
        self.plan_editor.load("quick")

    def _plan_loaded(self, plan: Plan) -> None:
        """A plan names the setup it expects: load that one (as the command line does)."""
        if self.setup_editor.value is not None and self.setup_editor.value.name == plan.setup:
            return
        try:
            load_setup(plan.setup)
        except ConfigError:
            return  # the operator picks a setup
        self.setup_editor.load(plan.setup)

    # -- checking --------------------------------------------------------------------------
    def check(self) -> bool:
        """Check setup, plan and file now; show problems at their fields."""
        self._timer.stop()
        setup, setup_error = self.setup_editor.check()
        plan, plan_error = self.plan_editor.check()
        problem = setup_error or plan_error
        if setup is not None and plan is not None:
            try:
                setup.channels_for_points(plan.points)
            except ValueError as exc:
                self.plan_editor.form.show_error("points", str(exc))
                problem = str(exc)
        try:
            self.run_box.options()
        except ValueError as exc:
            problem = problem or str(exc)
        self.settings_problem = problem
        problem = problem or self._check_path()
        self.plan, self.setup = plan, setup
        self.valid = not problem
        self.problem = problem
        if self.valid:
            into = self.resume_path or Path(self.run_box.path.text().strip()).expanduser()
            self.status.setText(
                f"<span style='color:{OK}'>ready: {plan.name} on {setup.name}, into "
                f"{into.name} in {_short(into.parent)}</span>"
            )
        else:
            self.status.setText(f"<span style='color:{ALARM}'>not ready: {problem}</span>")
        self.validity_changed.emit(self.valid, problem)
        return self.valid

    def _check_path(self) -> str:
        box = self.run_box
        text = box.path.text().strip()
        problem = ""
        if self.resume_path is not None:
            problem = ""
        elif not text:
            problem = "name the measurement file"
        elif Path(text).expanduser().exists() and not box.overwrite.isChecked():
            problem = (
                f"{Path(text).name} exists (a run is already in it): press 'New file' for a new "
                "name, choose another with 'Browse…', or tick 'replace an existing file'"
            )
        elif not self._folder_ready(Path(text).expanduser()):
            problem = (
                f"the folder of {text} does not exist: choose a file in an existing folder "
                "('Browse…')"
            )
        box.path_error.setText(problem)
        box.path_error.setVisible(bool(problem))
        return problem

    @staticmethod
    def _folder_ready(path: Path) -> bool:
        """The file's folder exists, or is the runs folder (made when the run starts)."""
        folder = path.resolve().parent
        return folder.is_dir() or folder == runs_folder().resolve()

    def after_run(self, path: Path | None) -> None:
        """A run wrote ``path``: the next one gets a new file next to it (a file is replaced
        only when the operator ticks the box), then everything is checked again."""
        box = self.run_box
        current = box.path.text().strip()
        written = path is not None and current and Path(current).name == Path(path).name
        taken = bool(current) and Path(current).expanduser().exists()
        if self.resume_path is None and (written or taken) and not box.overwrite.isChecked():
            box.use_new_file()
        self.check()

    # -- resume ----------------------------------------------------------------------------
    def set_resume(self, path: Path, data) -> None:
        """Complete an unfinished file: its stored plan and setup, its simulated rig."""
        from rig.config.plans import plan_from_dict

        plan = plan_from_dict(data.config["plan"], f"plan stored in {path}")
        setup = setup_from_dict(data.setup, f"setup stored in {path}")
        self.plan_editor.set_value(plan, f"stored in {path}")
        self.setup_editor.set_value(setup, f"stored in {path}")
        run = data.config.get("run", {}) if isinstance(data.config, dict) else {}
        options = run.get("backend_options", {}) if run.get("backend") == "sim" else {}
        if isinstance(options.get("truth"), str):
            self.run_box.truth.setCurrentText(options["truth"])
        if isinstance(options.get("seed"), int):
            self.run_box.seed.setText(str(options["seed"]))
        self.resume_path = Path(path)
        self.run_box.path.setText(str(path))
        self.run_box.path.setEnabled(False)
        self.run_box.resume_note.setText(
            f"completing {Path(path).name}: {data.n_steps} of {plan.n_steps} steps on disk; "
            "plan and setup as stored in the file"
        )
        self.run_box.cancel_resume.show()
        for editor in (self.plan_editor, self.setup_editor):
            editor.form.setEnabled(False)
        self.setCurrentWidget(self.run_box)
        self.check()

    def cancel_resume(self) -> None:
        self.resume_path = None
        self.run_box.path.setEnabled(True)
        self.run_box.resume_note.setText("")
        self.run_box.cancel_resume.hide()
        for editor in (self.plan_editor, self.setup_editor):
            editor.form.setEnabled(True)
        self.check()

    # -- the request -----------------------------------------------------------------------
    def request(self, *, pretest_only: bool = False) -> RunRequest:
        """The run to start (raises ValueError when something is not ready; a pretest needs no
        file)."""
        self.check()
        problem = self.settings_problem if pretest_only else self.problem
        if problem:
            raise ValueError(problem)
        box = self.run_box
        resume = self.resume_path is not None
        path = self.resume_path if resume else Path(box.path.text().strip()).expanduser()
        if not pretest_only:
            path.parent.mkdir(parents=True, exist_ok=True)  # the runs folder on a first run
        return RunRequest(
            plan=self.plan,
            setup=self.setup,
            path=path,
            backend=box.backend,
            backend_options=box.options(),
            overwrite=box.overwrite.isChecked(),
            resume=resume and not pretest_only,
            pause_on_fault=box.pause_on_fault.isChecked(),
            pretest_only=pretest_only,
        )
