"""``plan`` on the command line: ``--quick`` runs and prints one JSON object."""

from __future__ import annotations

import argparse
import json

from analysis.planning.cli import add_parser, main


def test_quick_plan_prints_json(capsys):
    assert main(["plan", "--quick", "--json", "--workers", "1", "--top", "3"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_configurations"] == 630
    assert len(out["top"]) == 3
    assert out["top"][0]["range_hz"] == "[21-40]"
    assert out["parameters"] == ["k_c", "gap", "v_c"]
    assert out["refined"]["step_plan"] == "[21-40] + 0.1 Hz in 24-28"
    assert out["correlations"]["fim_inverse"][1][1] > 0


def test_plan_text_report_and_choice(capsys):
    args = ["plan", "--quick", "--workers", "1", "--no-refine", "--choose", "3:3,6,7:2,6:21-40"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "No. actuator" in text and "FIM^-1" in text and "[21-40]" in text
    assert "chosen: actuator 3, levels [2, 6] N, range [21-40] Hz, sensors [3, 6, 7]" in text


def test_bad_arguments_give_an_error_message(capsys):
    assert main(["plan", "--quick", "--workers", "1", "--set", "k_c=abc"]) == 2
    assert "NAME=NUMBER" in capsys.readouterr().err
    assert main(["plan", "--quick", "--workers", "1", "--choose", "3:3,6,7:2,6:22-41"]) == 2
    assert "no candidate range" in capsys.readouterr().err


def test_add_parser_registers_plan_on_another_command_line():
    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["plan", "--scheduler", "tcp://h:8786", "--top", "7"])
    assert args.scheduler == "tcp://h:8786" and args.top == 7 and callable(args.func)
