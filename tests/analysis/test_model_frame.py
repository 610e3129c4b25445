"""The model file's frame records: read through their declarations and written back from them."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from analysis.elements import make_element
from analysis.elements.base import ElementParameterError
from analysis.fe import Joint, LumpedMass, Material, Member, Section, Spring
from analysis.model import Model, ModelFileError, load_model
from analysis.model_file import LinearPartSpec, to_document
from analysis.settings import ConfigError, build, declared_fields, dump

ROOT = Path(__file__).resolve().parents[2]
RIG = ROOT / "analysis/models/clearance_rig.toml"
CANTILEVER = ROOT / "examples/cantilever_tip_contact.toml"


def test_the_rig_frame_reads_to_the_values_its_file_gives():
    frame = load_model(RIG).frame
    beam, tube = frame.sections["beam"], frame.sections["tube"]
    assert (beam.shape, beam.b_m, beam.h_m) == ("rect", 0.030, 0.012)
    # section properties from the dimensions, computed here independently (rel. 1e-12)
    assert beam.area_m2 == pytest.approx(0.030 * 0.012, rel=1e-12)
    assert beam.inertia_m4 == pytest.approx(0.030 * 0.012**3 / 12, rel=1e-12)
    assert (tube.outer_m, tube.wall_m) == (0.080, 0.006)
    assert tube.area_m2 == pytest.approx(0.080**2 - 0.068**2, rel=1e-12)
    assert frame.materials["beam_steel"] == Material(E="E_beam", rho=7901.0)
    assert frame.materials["corner"] == Material(E="E_corner", rho="rho_corner")
    assert frame.members[0] == Member("beam", ("beam_root", "tip"), "beam", "beam_steel", 13,
                                      group="beam")  # fmt: skip
    post = frame.members[1]
    assert (post.name, post.nodes, post.section, post.material) == (
        "left_post", ("p9", "left_top"), "tube", "frame_steel"
    )  # fmt: skip
    assert (post.elements, post.max_element_length_m, post.nsm_kg_per_m) == (7, None, 6.73478564)
    assert [m.elements for m in frame.members] == [13, 7, 22, 7, 2, 1, 1, 2]
    assert frame.joints == (Joint("clamp", ("left_top", "beam_root")),)
    assert frame.joints[0].connection("rz") == "rigid"
    assert len(frame.springs) == 4
    assert frame.springs[3] == Spring("mount_right_y", "right_bottom", "y", "k_mount")
    assert frame.masses == (
        LumpedMass("clamped_length", "beam_root", 0.17952012, 2.3750512e-4, "clamp"),
    )


def test_models_with_equal_frames_share_one_structure_and_assemble_as_a_new_one():
    """Predictors and calibrations add their file's sensor masses to the model each time they
    are made (a new frame): equal frames share one structure, another mass gets its own, and
    the matrices are those of a structure built afresh."""
    from analysis.fe import build_structure

    model = load_model(RIG)
    a, b = model.add_masses({3: 0.012}), load_model(RIG).add_masses({3: 0.012})
    c = model.add_masses({3: 0.020})
    assert a.structure is b.structure and a.structure is not c.structure
    for m in (a, c):
        fresh = build_structure(m.frame)
        for which in ("M", "K"):
            assert (m.structure.matrix(which, m.values()) == fresh.matrix(which, m.values())).all()
    dm = c.structure.matrix("M", c.values()) - a.structure.matrix("M", a.values())
    assert dm.sum() == pytest.approx(2 * 0.008, rel=1e-12)  # x and y of point 3


def test_the_cantilever_frame_reads_to_the_values_its_file_gives():
    frame = load_model(CANTILEVER).frame
    assert frame.nodes == {"root": (0.0, 0.0), "tip": (0.5, 0.0)}
    assert frame.sections == {"bar": Section("rect", b_m=0.030, h_m=0.012)}
    assert frame.materials == {"steel": Material(E="E", rho=7800.0)}
    (beam,) = frame.members
    assert (beam.name, beam.nodes, beam.elements, beam.nsm_kg_per_m, beam.group) == (
        "beam", ("root", "tip"), 8, 0.0, "frame"
    )  # fmt: skip
    assert (frame.joints, frame.springs, frame.masses) == ((), (), ())


ROWS = {"members": Member, "joints": Joint, "springs": Spring, "masses": LumpedMass}
TABLES = {"sections": Section, "materials": Material}


def _same_table(cls: type, written: dict, given: dict) -> None:
    """``written`` holds what ``given`` holds, less the values that are the declared defaults
    (a reader supplies them again)."""
    defaults = {f.key: f.default for f in declared_fields(cls) if f.default is not None}
    missing = object()
    assert written == {k: v for k, v in given.items() if v != defaults.get(k, missing)}


@pytest.mark.parametrize("path", [RIG, CANTILEVER], ids=lambda p: p.name)
def test_the_writer_writes_the_frame_tables_of_the_file(tmp_path, path):
    source = tomllib.loads(path.read_text())
    model = load_model(path)
    doc = to_document(model)
    assert doc["nodes"] == source["nodes"]
    for key, cls in ROWS.items():
        assert len(doc.get(key, [])) == len(source.get(key, []))
        for written, given in zip(doc.get(key, []), source.get(key, []), strict=True):
            _same_table(cls, written, given)
    for key, cls in TABLES.items():
        assert doc[key].keys() == source[key].keys()
        for name, given in source[key].items():
            _same_table(cls, doc[key][name], given)
    again = load_model(model.save(tmp_path / path.name))
    assert again.frame == model.frame
    assert model.save(tmp_path / "twice.toml").read_text() == (tmp_path / path.name).read_text()


def test_every_frame_record_round_trips_through_dump_and_build():
    frame = load_model(RIG).frame
    records = [*frame.sections.values(), *frame.materials.values(), *frame.members,
               *frame.joints, *frame.springs, *frame.masses]  # fmt: skip
    for record in records:
        assert build(type(record), dump(record), "dump") == record
    assert set(dump(frame.masses[0])) == {"name", "node", "m", "J", "group"}
    assert dump(frame.members[0])["nsm"] == 0.0


SHORTHANDS = """
[nodes]
a = [0.0, 0.0]
b = [1.0, 0.0]
c = [1.0, 0.0]
[sections.s]
A = 1e-4
I = 1e-8
[materials.m]
E = 2e11
rho = 7800.0
[[members]]
nodes = ["a", "b"]
section = "s"
material = "m"
max_element_length = 0.25
nsm = 0.5
[[joints]]
nodes = ["b", "c"]
rz = { k = 300.0 }
x = "free"
[[springs]]
node = "c"
direction = "y"
k = 1e3
to = "a"
[[masses]]
node = "c"
m = 0.2
[supports]
a = "all"
"""


def test_file_shorthands_and_default_names(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(SHORTHANDS)
    frame = load_model(path).frame
    assert frame.sections["s"] == Section("general", area_m2=1e-4, inertia_m4=1e-8)
    assert frame.members == (Member("m0", ("a", "b"), "s", "m", None, 0.25, 0.5),)
    assert frame.joints == (Joint("joint0", ("b", "c"), x="free", rz=300.0),)
    assert frame.springs == (Spring("spring0", "c", "y", 1e3, "a"),)
    assert frame.masses == (LumpedMass("mass0", "c", 0.2),)


def test_a_file_uses_the_file_keys_not_the_field_names():
    keys = {f.name: f.key for f in declared_fields(Member)}
    assert keys["nsm_kg_per_m"] == "nsm" and keys["max_element_length_m"] == "max_element_length"
    with pytest.raises(ConfigError, match=r"unknown key\(s\) 'b_m' \(known here: A, I, b, h,") as e:
        build(Section, {"shape": "rect", "b_m": 0.1, "h": 0.1}, "f.toml", at=("sections", "s"))
    assert e.value.path == ("sections", "s")
    with pytest.raises(ConfigError, match=r"^Section\.wall_m: wall 0\.006 m is too thick"):
        Section("rect_tube", outer_m=0.01, wall_m=0.006)


@pytest.mark.parametrize(
    ("old", "new", "path", "problem"),
    [
        ("max_element_length = 0.25", "max_element_length = -0.25",
         ("members", 0, "max_element_length"), "must be positive, got -0.25"),
        ("max_element_length = 0.25", "max_element_length = nan",
         ("members", 0, "max_element_length"), "expected a finite number, got nan"),
        ("I = 1e-8", "", ("sections", "s", "I"), "required for shape 'general'"),
        ('nodes = ["b", "c"]', 'nodes = ["b"]', ("joints", 0, "nodes"), "need two nodes"),
        ("rz = { k = 300.0 }", "rz = { c = 300.0 }", ("joints", 0, "rz", "c"), "unknown key"),
        ('direction = "y"', 'direction = "z"', ("springs", 0, "direction"), "bad direction 'z'"),
        ("m = 0.2", "m = -0.2", ("masses", 0, "m"), "must be >= 0, got -0.2"),
        ("m = 0.2", 'm = 0.2\nJ = "0"', ("masses", 0, "J"), "unknown parameter '0'"),
        ("rho = 7800.0", "rho = true", ("materials", "m", "rho"), "expected a number, got True"),
    ],
)  # fmt: skip
def test_frame_errors_name_the_file_key(tmp_path, old, new, path, problem):
    assert old in SHORTHANDS
    file = tmp_path / "bad.toml"
    file.write_text(SHORTHANDS.replace(old, new, 1))
    with pytest.raises(ModelFileError, match=problem) as info:
        load_model(file)
    assert info.value.path == path
    assert str(info.value).startswith(f"{file}: ")


def test_element_errors_carry_the_parameter_name(tmp_path):
    with pytest.raises(ElementParameterError, match="parameter 'k_c' must be > 0") as info:
        make_element("hertz_contact", k_c=-1.0, gap=0.0, v=0.0)
    assert info.value.parameter == "k_c"
    text = CANTILEVER.read_text().replace("v = 0.0 }", "v = 0.0 }\noptions = { side = 3 }")
    file = tmp_path / "bad.toml"
    file.write_text(text)
    with pytest.raises(ModelFileError, match="option 'side' must be -1") as err:
        load_model(file)
    assert err.value.path == ("nonlinear", 0, "options", "side")


def test_the_linear_part_reads_with_its_files_beside_the_model_file():
    path = ROOT / "examples/duffing.toml"
    spec = load_model(path).linear_part
    assert spec == LinearPartSpec(
        format="mtx",
        files={k: str(path.parent.resolve() / f"duffing.{k}.mtx") for k in ("M", "K")},
        dof_map=("mass/x",),
    )
    with pytest.raises(ConfigError, match=r"LinearPartSpec\.dof_map: missing"):
        LinearPartSpec(format="mtx", files={"M": "a.mtx", "K": "b.mtx"})


LINEAR = '[linear_part]\nformat = "npz"\nfile = "p.npz"\n[points.1]\nnode = "2"\ndirection = "x"\n'


@pytest.mark.parametrize(
    ("old", "new", "path", "problem"),
    [
        ('file = "p.npz"', "file = 3", ("linear_part", "file"), "expected a string, got 3"),
        ('file = "p.npz"', "", ("linear_part", "file"), "missing"),
        ('"npz"', '"npy"', ("linear_part", "format"), "unknown format 'npy'"),
        ('"npz"\nfile = "p.npz"', '"mtx"\nfiles = {M = "a.mtx"}', ("linear_part", "files", "K"),
         "missing"),
        ('"npz"\nfile = "p.npz"', '"mtx"\nfiles = {M = "a", K = "b", D = "c"}',
         ("linear_part", "files", "D"), "unknown key"),
        ('"npz"\nfile = "p.npz"', '"mtx"\nfiles = {M = "a", K = "b"}', ("linear_part", "dof_map"),
         "missing \\(a file name or a list"),
        ('file = "p.npz"', 'file = "p.npz"\nmasses = {a = nan}', ("linear_part", "masses", "a"),
         "expected a finite number"),
    ],
)  # fmt: skip
def test_linear_part_errors_name_the_file_key(tmp_path, old, new, path, problem):
    assert old in LINEAR
    with pytest.raises(ModelFileError, match=problem) as info:
        Model.from_toml_text(LINEAR.replace(old, new, 1), str(tmp_path / "m.toml"))
    assert info.value.path == path
