"""The acquisition service: one process owns the rig; the GUI and scripts attach to it.

A long-running process (``python -m rig service start``) takes the device lock, opens the DAQ
backend and the serial amplifier once, and runs a queue of runs (stepped-sine and random
plans) one at a time on the run engine, writing the measurement files. Clients talk to it over
HTTP on the loopback interface: submit, list, status, pause, resume, abort, a live event stream
per run, and where the results are. Every request carries the service's token.

Modules, in the order data flows through them:

- :mod:`rig.service.directory`: the service directory (token, address, state, results);
- :mod:`rig.service.auth`: the access token;
- :mod:`rig.service.state`: run records and the queue, persisted as JSON;
- :mod:`rig.service.worker`: the thread that owns the rig and runs the queue;
- :mod:`rig.service.codec`: events as JSON (the event stream's lines);
- :mod:`rig.service.hub`: each run's event log and the streams that follow it;
- :mod:`rig.service.server`: the HTTP API (aiohttp) and the process's life cycle;
- :mod:`rig.service.client`: :class:`~rig.service.client.ServiceClient` for the GUI and scripts;
- :mod:`rig.service.launch`: start a service in the background (``ensure_service``).

The API is described in ``docs/service-api.md``. Importing this package imports neither the
server stack nor numpy: clients stay light.
"""

from rig.service.client import (
    AuthenticationError,
    EventStream,
    ServiceClient,
    ServiceError,
    ServiceUnavailable,
)

__all__ = [
    "AuthenticationError",
    "EventStream",
    "ServiceClient",
    "ServiceError",
    "ServiceUnavailable",
]
