"""Where the benchmarks write their results: ``benchmarks/results/NAME.json`` per benchmark (the
last full run's figures, with the machine and the date) and ``benchmarks/RESULTS.md``, made
anew from those files after every run. Neither is edited by hand."""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
from pathlib import Path

__all__ = ["machine", "record", "write_markdown"]

FOLDER = Path(__file__).resolve().parent / "results"
MARKDOWN = Path(__file__).resolve().parent / "RESULTS.md"


def machine() -> dict:
    """What the figures were measured on."""
    import numpy as np

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpus": os.cpu_count(),
        "cpu": cpu,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "blas_threads": os.environ.get("OMP_NUM_THREADS"),
    }


def code_version() -> str:
    """The commit measured (``+changes`` when the work tree differs from it)."""
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=root,
            text=True,
            capture_output=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            text=True,
            capture_output=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+changes" if dirty else "")


def record(
    name: str,
    figures: dict,
    folder: Path = FOLDER,
    markdown: Path = MARKDOWN,
    code: str | None = None,
) -> Path:
    """Write one benchmark's figures and make ``RESULTS.md`` again; ``code``: the commit the
    figures were measured on (default: the work tree's, as the run ends)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.json"
    doc = {
        "benchmark": name,
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "code": code or code_version(),
        "machine": machine(),
        "figures": figures,
    }
    path.write_text(json.dumps(doc, indent=1, default=str) + "\n")
    write_markdown(folder, markdown)
    return path


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    text = json.dumps(value, default=str)
    return text if len(text) <= 120 else text[:117] + "..."


def write_markdown(folder: Path = FOLDER, markdown: Path = MARKDOWN) -> Path:
    """``RESULTS.md`` from every recorded benchmark: its date, machine and top-level figures
    (the per-case details stay in the JSON)."""
    lines = [
        "# Benchmark results",
        "",
        "Written by `python -m benchmarks NAME` from `benchmarks/results/NAME.json` (the "
        "last full run of each); not edited by hand.",
        "",
    ]
    for path in sorted(folder.glob("*.json")):
        doc = json.loads(path.read_text())
        m = doc.get("machine", {})
        where = (
            f"{doc['date']}, code {doc.get('code', 'unknown')}; {m.get('cpus')} CPUs "
            f"({m.get('cpu')}), Python {m.get('python')}, numpy {m.get('numpy')}, BLAS threads "
            f"{doc['figures'].get('blas_threads', m.get('blas_threads'))}"
        )
        lines += [f"## `{doc['benchmark']}`", "", where, "", "| figure | value |", "|---|---|"]
        for key, value in doc["figures"].items():
            if key != "details":
                lines.append(f"| `{key}` | {_cell(value)} |")
        lines.append("")
    markdown.write_text("\n".join(lines))
    return markdown
