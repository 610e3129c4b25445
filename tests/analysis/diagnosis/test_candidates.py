"""Candidates: the library's kinds only, and each kind of change written into a model file."""

from __future__ import annotations

import pytest

from analysis.diagnosis.candidates import Candidate, Law, default_candidates, default_laws
from analysis.model import load_model


def test_candidates_are_the_library_at_every_plausible_location(reference_model) -> None:
    cands = default_candidates(reference_model)
    kinds = {c.law.kind for c in cands}
    # the simulator's hysteretic element is registered in this session, yet never a candidate
    assert "jenkins" not in kinds
    assert {
        "cubic_spring",
        "hertz_contact",
        "coulomb_friction",
        "quadratic_damper",
        "mass",
        "joint_spring",
        "parameter",
    } <= kinds
    locations = {c.location.name for c in cands}
    assert {"point 7", "point 13", "springs k_mount", "joint clamp rz"} <= locations
    assert all(c.law.kind != "mass" or c.location.point is not None for c in cands)
    sides = {c.law.options.get("side") for c in cands if c.law.kind == "hertz_contact"}
    assert sides == {-1, 1}


def _find(cands, label):
    return next(c for c in cands if c.label == label)


def test_each_kind_of_change_writes_a_valid_model(reference_model, tmp_path) -> None:
    cands = default_candidates(reference_model)
    cases = {
        "cubic_spring at springs k_mount": {"k3": 1e12},
        "hertz_contact (above) at point 7": {"k_c": 4e5, "v": 20.0, "gap": 1e-3},
        "coulomb_friction with a joint spring at joint clamp rz": {"f_slip": 2.0, "k_joint": 5e4},
        "mass at point 6": {"m": 0.05},
        "linear parameter E_beam": {"E_beam": 2.0e11},
    }
    for label, values in cases.items():
        cand = _find(cands, label)
        model, new = cand.apply(reference_model, values)
        assert new, label
        path = model.save(tmp_path / f"{cand.key}.toml")
        back = load_model(path)
        for name in new:
            assert back.parameters[name].value == model.parameters[name].value
    mounts, new = _find(cands, "cubic_spring at springs k_mount").apply(
        reference_model, {"k3": 1e12}
    )
    assert len([s for s in mounts.nonlinear if s.kind == "cubic_spring"]) == 4
    assert new == ["k3_cubic_spring_springs_k_mount"]
    joint, new = _find(cands, "coulomb_friction with a joint spring at joint clamp rz").apply(
        reference_model, {"f_slip": 2.0, "k_joint": 5e4}
    )
    assert next(j for j in joint.frame.joints if j.name == "clamp").rz == "k_clamp_rz"
    assert joint.parameters["k_clamp_rz"].group == "linear"
    # the original is untouched
    assert reference_model.frame.joints[0].rz == "rigid"
    # a screen's joint stiffness below zero is refused, naming the candidate and the joint
    gap = _find(cands, "gap_spring (below) with a joint spring at joint clamp rz")
    with pytest.raises(ValueError, match=r"gap_spring \(below\).*joint clamp in rz.*-2\.793e\+04"):
        gap.apply(reference_model, {"k": 1.8e5, "gap": 2e-5, "k_joint": -2.793e4})


def test_linear_laws_are_reported_as_linear() -> None:
    laws = {law.kind: law for law in default_laws()}
    assert laws["mass"].is_linear and laws["linear_spring"].is_linear
    assert not laws["cubic_spring"].is_linear and not laws["coulomb_friction"].is_linear
    assert Candidate(default_candidates(load_model())[0].location, Law("joint_spring")).is_linear


def test_locations_come_from_the_structure(reference_model) -> None:
    from analysis.diagnosis.candidates import default_locations

    locs = {loc.name: loc for loc in default_locations(reference_model, "structure")}
    kinds: dict[str, set[str]] = {}
    for name, loc in locs.items():
        kinds.setdefault(loc.kind, set()).add(name)
    # every spring on its own and the group sharing k_mount, named by what they are
    assert kinds["spring"] == {
        f"spring mount_{s}" for s in ("left_x", "left_y", "right_x", "right_y")
    }
    assert kinds["group"] == {"springs k_mount"}
    assert len(locs["springs k_mount"].incidences) == 4
    # every rigid direction of the clamp
    assert kinds["joint"] == {"joint clamp x", "joint clamp y", "joint clamp rz"}
    # each point in the other direction the frame moves in there (beam points measure y)
    assert {"point 7 x", "point 13 y"} <= kinds["direction"]
    assert len(kinds["direction"]) == len(reference_model.points)
    # two nodes of different members within reach; none along one member (point 6 and the tip
    # are 33 mm apart on the beam), none between coincident nodes (the clamp is a joint)
    assert "point 7 to right_top y" in kinds["pair"]
    at, to = locs["point 7 to right_top y"].incidences[0]
    assert (at.node, to.node, at.direction, to.direction) == ("tip", "right_top", "y", "y")
    assert not any("point 6 to point 7" in n or "point 7 to point 6" in n for n in kinds["pair"])
    assert not any("beam_root" in n or "left_top" in n for n in kinds["pair"])
    # a mass only at a point's own location (it acts in every direction of its node)
    structure = default_candidates(reference_model, scope="structure")
    masses = {c.location.kind for c in structure if c.law.kind == "mass"}
    assert masses == {"point"}


def test_the_measured_scope_is_what_the_sensors_see(reference_model) -> None:
    from analysis.diagnosis.candidates import default_locations

    locs = default_locations(reference_model)
    names = [loc.name for loc in locs]
    # each point in its measured direction, the spring group, the clamp's rotation and
    # transverse direction: nothing the sensors see only through the structure
    assert names == [
        *(f"point {n}" for n in reference_model.points),
        "springs k_mount",
        "joint clamp rz",
        "joint clamp y",
    ]
    structure = {loc.name for loc in default_locations(reference_model, "structure")}
    assert set(names) < structure
    with pytest.raises(ValueError, match="locations: expected one of"):
        default_locations(reference_model, "everywhere")


def test_springs_not_sharing_a_parameter_form_no_group(reference_model) -> None:
    import dataclasses

    from analysis.diagnosis.candidates import default_locations

    frame = reference_model.frame
    springs = tuple(dataclasses.replace(s, k=2.0e5) for s in frame.springs)
    model = dataclasses.replace(reference_model, frame=dataclasses.replace(frame, springs=springs))
    kinds = {loc.kind for loc in default_locations(model, "structure")}
    assert "group" not in kinds and "spring" in kinds
