"""Candidates: the library's kinds only, and each kind of change written into a model file."""

from __future__ import annotations

import numpy as np
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

    places = default_locations(reference_model, "structure")
    locs = {loc.name: loc for loc in places}
    # every place, those folded into one that moves as they do included
    kinds: dict[str, set[str]] = {}
    for loc in places:
        kinds.setdefault(loc.kind, set()).update({loc.name, *loc.moves_as})
    every = set().union(*kinds.values())
    # every spring on its own and the group sharing k_mount, named by what they are
    assert {f"spring mount_{s}" for s in ("left_x", "left_y", "right_x", "right_y")} <= every
    assert kinds["group"] == {"springs k_mount"}
    assert len(locs["springs k_mount"].incidences) == 4
    # every rigid direction of the clamp
    assert kinds["joint"] == {"joint clamp x", "joint clamp y", "joint clamp rz"}
    # each point in the other direction the frame moves in there (beam points measure y)
    assert {"point 7 x", "point 13 y"} <= every
    assert len({n for n in every if n.startswith("point") and n[-2:] in (" x", " y")}) >= len(
        reference_model.points
    )
    # two nodes of different members within reach; none along one member (point 6 and the tip
    # are 33 mm apart on the beam), none between coincident nodes (the clamp is a joint)
    assert "point 7 to right_top y" in kinds["pair"]
    at, to = locs["point 7 to right_top y"].incidences[0]
    assert (at.node, to.node, at.direction, to.direction) == ("tip", "right_top", "y", "y")
    assert not any("point 6 to point 7" in n or "point 7 to point 6" in n for n in every)
    assert not any("beam_root" in n or "left_top" in n for n in every)
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


def test_places_that_move_alike_are_one_candidate(reference_model, monkeypatch) -> None:
    """Two places whose motions differ by under SAME_MOTION of their own under any static load
    are one candidate (the one the sensors see most directly, then the shortest pair), the
    others named in ``moves_as``; checked against the displacements under random loads."""
    import numpy as np

    from analysis.diagnosis import candidates
    from analysis.diagnosis.candidates import SAME_MOTION, default_locations

    places = default_locations(reference_model, "structure")
    # every place with its incidences, before places that move alike are folded
    with monkeypatch.context() as m:
        m.setattr(candidates, "_merge_same_motion", lambda locs, asm, xy: locs)
        unfolded = {x.name: x.incidences for x in default_locations(reference_model, "structure")}
    by_name = {loc.name: loc for loc in places}
    folded = {alias: loc.name for loc in places for alias in loc.moves_as}
    # the right post is axially rigid: its y motion is the right mount's, at both its points
    assert folded["spring mount_right_y"] == "point 12 y"
    assert folded["point 13 y"] == "point 12 y"
    # the shorter of two pairs that move alike is kept (the tip to the post's top)
    assert folded["point 7 to point 13 y"] == "point 7 to right_top y"
    # across the post the tip's x motion differs from the post's: two places
    assert "point 7 to right_top x" in by_name and "point 7 to point 13 x" in by_name
    asm = reference_model.assemble()
    rng = np.random.default_rng(1)
    loads = rng.standard_normal((asm.n_dofs, 200))
    u = np.linalg.solve(np.asarray(asm.K), loads)

    def motion(name: str) -> np.ndarray:
        ((at, to),) = unfolded[name]
        out = u[asm.dof_index(at.node, at.direction)].copy()
        if to is not None:
            out -= u[asm.dof_index(to.node, to.direction)]
        return out

    for alias, home in folded.items():
        a, b = motion(alias), motion(home)
        assert np.max(np.abs(a - b)) <= SAME_MOTION * np.max(np.abs(b)), (alias, home)
    a, b = motion("point 7 to right_top x"), motion("point 7 to point 13 x")
    assert np.max(np.abs(a - b)) > 0.1 * np.max(np.abs(b))


def test_the_look_alike_places_of_a_place(reference_model) -> None:
    """A group's springs each alone (wherever they are folded), a spring's group, a point's
    pairs in its direction and a pair's point; nothing for a place with no look-alike."""
    from analysis.diagnosis.candidates import default_locations
    from analysis.diagnosis.diagnose import look_alike_places

    places = default_locations(reference_model, "structure")
    by_name = {loc.name: loc for loc in places}

    def alike(name: str) -> set[str]:
        return {loc.name for loc in look_alike_places(by_name[name], places)}

    # each mount spring alone, under its own name or that of a place that moves as it
    found = look_alike_places(by_name["springs k_mount"], places)
    reached = {n for loc in found for n in (loc.name, *loc.moves_as)}
    assert {f"spring mount_{s}" for s in ("left_x", "left_y", "right_x", "right_y")} <= reached
    assert all(loc.kind in ("spring", "direction", "point") for loc in found)
    assert "springs k_mount" in alike("point 12 y")
    assert alike("point 7") == {"point 7 to right_top y"}
    assert alike("point 7 to right_top y") == {"point 7"}
    assert alike("point 5") == set()  # no node of another member within reach
    assert alike("joint clamp rz") == set()


def test_a_linear_spring_is_a_spring_of_the_frame(reference_model, tmp_path) -> None:
    """A linear spring enters the stiffness matrix (what the linear test sees), to ground or
    between two nodes, one spring per incidence sharing one parameter; never below zero."""
    cands = default_candidates(reference_model, scope="structure")
    K0 = reference_model.assemble().K
    point, new = _find(cands, "linear_spring at point 5").apply(reference_model, {"k": 2.5e3})
    assert new == ["k_linear_spring_point_5"] and point.nonlinear == reference_model.nonlinear
    assert point.parameters[new[0]].group == "linear" and point.parameters[new[0]].lower == 0.0
    asm = point.assemble()
    i = asm.dof_index("p5", "y")
    dK = asm.K - K0
    assert dK[i, i] == pytest.approx(2.5e3, rel=1e-12)
    dK[i, i] = 0.0
    assert np.abs(dK).max() <= 1e-9 * np.abs(K0).max()
    # between two nodes: +k on each diagonal, -k between them
    pair = _find(cands, "linear_spring at point 9 to point 10 x")
    m2, _ = pair.apply(reference_model, {"k": 4e3})
    asm = m2.assemble()
    a, b = asm.dof_index("p9", "x"), asm.dof_index("p10", "x")
    dK = asm.K - K0
    assert dK[np.ix_([a, b], [a, b])] == pytest.approx(np.array([[4e3, -4e3], [-4e3, 4e3]]))
    # a group: one spring at each of its four places, one parameter
    group, new = _find(cands, "linear_spring at springs k_mount").apply(reference_model, {"k": 1e3})
    assert len(group.frame.springs) == len(reference_model.frame.springs) + 4 and len(new) == 1
    # a screen's estimate below zero starts at zero; the model file round-trips
    neg, new = _find(cands, "linear_spring at point 5").apply(reference_model, {"k": -3e3})
    assert neg.parameters[new[0]].value == 0.0
    back = load_model(neg.save(tmp_path / "spring.toml"))
    assert back.parameters[new[0]].value == 0.0
