"""Run a benchmark scenario: ``python -m benchmarks NAME [--quick]``."""

from __future__ import annotations

import os

# Small dense linear algebra is slowed badly by BLAS threads on a shared 2-core machine.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402

SCENARIOS = {
    "calibrate": "benchmarks.calibrate",
    "continuation": "benchmarks.continuation",
    "coverage": "benchmarks.coverage",
    "diagnose": "benchmarks.diagnose",
    "mhb": "benchmarks.mhb",
    "planning": "benchmarks.planning",
    "service": "benchmarks.service",
    "speed": "benchmarks.speed",
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    parser.add_argument("name", choices=sorted(SCENARIOS), help="scenario to run")
    parser.add_argument("--quick", action="store_true", help="a reduced run (for smoke tests)")
    args = parser.parse_args(argv)
    module = importlib.import_module(SCENARIOS[args.name])
    from benchmarks.results import code_version

    code = code_version()  # as the run starts: what it measures
    figures = module.run(quick=args.quick)
    figures["blas_threads"] = os.environ.get("OMP_NUM_THREADS")
    if not args.quick:
        from benchmarks.results import record

        record(args.name, figures, code=code)
    print(json.dumps(figures, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
