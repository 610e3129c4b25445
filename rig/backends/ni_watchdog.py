"""Hardware watchdog for the NI drive output.

A DAQmx watchdog task runs a timer in the device. While the timer is reset often enough nothing
happens; when it expires, the device sets the listed output channels to their expiration states
by itself, without the host. :class:`AoWatchdog` arms it with the drive channel's expiration state
at 0 V and is reset from every :meth:`rig.backends.ni.NiDaqBackend.read`, so a host that hangs or
is killed while the shaker is driven leaves the amplifier input at 0 V after ``watchdog_s``.

Not every device has a watchdog that can hold analogue outputs (many multifunction and dynamic
signal acquisition devices have none; some C Series chassis and modules do). Where there is
none, the backend runs without it and logs a warning: the power amplifier's mute (or its
interlock) is then the only protection against a hard kill of the process.

Whether an armed watchdog still expires after the driver has cleaned up the tasks of a killed
process depends on the device and driver version; check it on the rig before relying on it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from rig.backends.protocol import BackendError

__all__ = ["AoWatchdog", "NO_WATCHDOG_WARNING"]

logger = logging.getLogger(__name__)

NO_WATCHDOG_WARNING = (
    "NI device %s has no usable hardware watchdog for %s (%s); nothing on the device is sure "
    "to bring the drive to 0 V if this process hangs or is killed: the amplifier mute is then "
    "the only protection for a hard kill"
)


class AoWatchdog:
    """The device watchdog holding the drive output at 0 V on expiry (or nothing, if absent).

    Build it with :meth:`create`; every method is a no-op when the device has no watchdog
    (``armed`` is then False).

    Parameters
    ----------
    task : object or None
        A configured ``nidaqmx.system.WatchdogTask`` (or a stand-in with the same methods), or
        None when the device has no watchdog.
    device : str
        Device name, for messages.
    timeout_s : float
        Expiration time of the watchdog timer [s].
    """

    def __init__(self, task: Any | None, device: str, timeout_s: float) -> None:
        self._task = task
        self.device = device
        self.timeout_s = timeout_s
        self._running = False

    @classmethod
    def create(
        cls,
        factory: Callable[..., Any],
        device: str,
        ao_physical: str,
        timeout_s: float,
    ) -> AoWatchdog:
        """Create the watchdog task and set the drive channel's expiration state to 0 V.

        Parameters
        ----------
        factory : callable
            ``nidaqmx.system.WatchdogTask`` or a stand-in with its signature.
        device : str
            Device (or cDAQ chassis) that owns the watchdog timer.
        ao_physical : str
            Drive channel, e.g. ``"Dev1/ao0"``.
        timeout_s : float
            Expiration time [s]; the timer must be reset more often than this.

        Returns
        -------
        AoWatchdog
            Armed on :meth:`start`; unarmed (with a warning logged) if the device has none.

        Raises
        ------
        BackendError
            If the NI-DAQmx driver itself is missing.
        """
        import nidaqmx.errors
        from nidaqmx.constants import WatchdogAOExpirState
        from nidaqmx.types import AOExpirationState

        try:
            task = factory(device, timeout=timeout_s)
        except nidaqmx.errors.DaqError as exc:
            logger.warning(NO_WATCHDOG_WARNING, device, ao_physical, _first_line(exc))
            return cls(None, device, timeout_s)
        except nidaqmx.errors.Error as exc:
            raise BackendError(
                f"NI-DAQmx driver not found ({exc}). Install NI-DAQmx or use --backend sim"
            ) from exc
        state = AOExpirationState(
            physical_channel=ao_physical,
            expiration_state=0.0,
            output_type=WatchdogAOExpirState.VOLTAGE,
        )
        try:
            task.cfg_watchdog_ao_expir_states([state])
        except nidaqmx.errors.DaqError as exc:
            _close_quietly(task)
            logger.warning(NO_WATCHDOG_WARNING, device, ao_physical, _first_line(exc))
            return cls(None, device, timeout_s)
        logger.info(
            "hardware watchdog on %s: %s goes to 0 V if no read for %.3g s",
            device,
            ao_physical,
            timeout_s,
        )
        return cls(task, device, timeout_s)

    @property
    def armed(self) -> bool:
        """Whether the device has a watchdog holding the drive output."""
        return self._task is not None

    def start(self) -> None:
        """Start the timer (before the output starts)."""
        if self._task is not None and not self._running:
            self._task.start()
            self._running = True

    def reset(self) -> None:
        """Reset the timer; called from every read."""
        if self._task is not None and self._running:
            self._task.reset_timer()

    def expired(self) -> bool:
        """Whether the timer has expired (False if unarmed or not running, or unreadable)."""
        if self._task is None or not self._running:
            return False
        try:
            return bool(self._task.expired)
        except Exception:  # a diagnostic query must not mask the original error
            return False

    def stop(self) -> None:
        """Stop the timer (after the output has been stopped at 0 V).

        An expiration is cleared first (the device stays locked otherwise); the output task is
        stopped by then, so the drive stays at 0 V.
        """
        if self._task is None or not self._running:
            return
        try:
            if self.expired():
                logger.warning(
                    "watchdog on %s had expired (the output was forced to 0 V); clearing it",
                    self.device,
                )
                self._task.clear_expiration()
        finally:
            self._running = False
            self._task.stop()

    def close(self) -> None:
        """Stop the timer if running, then release the watchdog task."""
        task = self._task
        if task is None:
            return
        try:
            self.stop()
        finally:
            self._task = None
            task.close()

    def expiry_message(self) -> str:
        """The explanation to attach to a DAQmx error caused by an expired watchdog."""
        return (
            f"the hardware watchdog on {self.device} expired (no read for more than "
            f"{self.timeout_s:g} s), so the device forced the drive output to 0 V; stop() and "
            "configure() again"
        )


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _close_quietly(task: Any) -> None:
    try:
        task.close()
    except Exception as exc:  # cleanup after a failed configuration
        logger.debug("closing the watchdog task failed: %s", exc)
