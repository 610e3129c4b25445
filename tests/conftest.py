"""Shared pytest configuration.

Tests that need a real NI device run only when one is named: ``pytest --ni-device Dev1``.
"""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--ni-device",
        action="store",
        default=None,
        help="name of a real NI DAQ device (e.g. Dev1) for the hardware tests",
    )


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "xvfb: starts the real GUI on a virtual X server (part of the CI suite; skipped only "
        "where Xvfb is not installed: make gui-deps)",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--ni-device"):
        return
    skip = pytest.mark.skip(reason="needs a real NI device: run with --ni-device NAME")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def ni_device(request: pytest.FixtureRequest) -> str:
    """Name of the NI device given with ``--ni-device``."""
    return request.config.getoption("--ni-device")
