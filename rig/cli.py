"""Command line of the acquisition side: ``python -m rig COMMAND ...``.

Commands
--------
backends    list the DAQ backends and check that each can be opened here
amplifier   talk to the serial power amplifier (status, enable, mute, gain, clear)
"""

from __future__ import annotations

import argparse
import json
import logging
import sys

from rig.backends import available_backends, open_backend
from rig.backends.protocol import BackendError


def cmd_backends(args) -> dict:
    report = {}
    for name in available_backends():
        try:
            backend = open_backend(name, **({"device": args.device} if name == "ni" else {}))
        except BackendError as exc:
            report[name] = {"available": False, "message": str(exc)}
            continue
        backend.close()
        report[name] = {"available": True, "message": "ok"}
    if not args.json:
        for name, r in report.items():
            print(f"{name:4s} {'available' if r['available'] else 'not available'}: {r['message']}")
    return report


def cmd_amplifier(args) -> dict:
    from rig.instruments.amplifier import PowerAmplifier

    with PowerAmplifier(args.port, timeout_s=args.timeout) as amp:
        if args.action == "enable":
            amp.enable()
        elif args.action == "mute":
            amp.mute()
        elif args.action == "clear":
            amp.clear_overload()
        elif args.action == "gain":
            if args.value is None:
                raise SystemExit("amplifier gain: give the gain in V/V, e.g. 'gain 5'")
            amp.set_gain(args.value)
        ident = amp.identify()
        status = amp.status()
    result = {
        "instrument": f"{ident.manufacturer} {ident.model} (serial {ident.serial})",
        "enabled": status.enabled,
        "muted": status.muted,
        "overload": status.overload,
        "gain_v_per_v": status.gain_v_per_v,
        "current_a": status.current_a,
    }
    if not args.json:
        for k, v in result.items():
            print(f"{k:13s} {v}")
    return result


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rig", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = p.add_subparsers(dest="command", required=True)

    sp = sub.add_parser("backends", help="list DAQ backends and check them")
    sp.add_argument("--device", default="Dev1", help="NI device name (default Dev1)")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_backends)

    sp = sub.add_parser("amplifier", help="serial power amplifier")
    sp.add_argument("action", choices=["status", "enable", "mute", "gain", "clear"])
    sp.add_argument("value", nargs="?", type=float, help="gain in V/V (for 'gain')")
    sp.add_argument("--port", required=True, help="serial port or pyserial URL")
    sp.add_argument("--timeout", type=float, default=1.0, help="reply timeout [s]")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_amplifier)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        result = args.func(args)
    except (OSError, ValueError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result))
    return 0
