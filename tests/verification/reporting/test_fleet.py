"""A fleet's robots: which measurement file, which nominal URDF, which name
(:func:`kinfw.verification.reporting.fleet_members`)."""

import shutil

import pytest

from kinfw.verification.reporting import FleetMember, fleet_members
from tests.paths import HEAD_URDF


def _robot(folder, data="data.json", urdf="robot.urdf"):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / data).write_text("{}")
    if urdf:
        shutil.copyfile(HEAD_URDF, folder / urdf)
    return folder / data


def test_a_folder_per_robot_is_named_after_its_folder_and_uses_its_urdf(tmp_path):
    for name in ("b7", "a1"):
        _robot(tmp_path / "robots" / name)
    members = fleet_members([str(tmp_path / "robots" / "*" / "data.json")])
    assert members == (
        FleetMember("a1", tmp_path / "robots/a1/robot.urdf", tmp_path / "robots/a1/data.json"),
        FleetMember("b7", tmp_path / "robots/b7/robot.urdf", tmp_path / "robots/b7/data.json"),
    )
    # the folder of robot folders names the same fleet
    assert fleet_members([tmp_path / "robots"]) == members


def test_files_with_their_own_names_are_named_after_them(tmp_path):
    for name in ("ur10_left", "ur10_right"):
        _robot(tmp_path, f"{name}.json", urdf=None)
    members = fleet_members(
        [tmp_path / "ur10_right.json", str(tmp_path / "*.json")], urdf=HEAD_URDF
    )
    # in the order given, each file once
    assert [(m.name, m.urdf, m.data.name) for m in members] == [
        ("ur10_right", HEAD_URDF, "ur10_right.json"),
        ("ur10_left", HEAD_URDF, "ur10_left.json"),
    ]


def test_a_sidecar_beside_the_data_is_not_a_measurement_file(tmp_path):
    _robot(tmp_path / "robots" / "r1")
    (tmp_path / "robots" / "r1" / "robot.kinfw.json").write_text("{}")
    (tmp_path / "robots" / ".git").mkdir()
    assert [m.data.name for m in fleet_members([tmp_path / "robots"])] == ["data.json"]


@pytest.mark.parametrize(
    ("layout", "source", "message"),
    [
        ({}, "robots/*/data.json", r"'.*robots/\*/data.json': matches no file"),
        ({}, "nothing.json", r"nothing.json: no such measurement file or folder"),
        ({"robots/": None}, "robots", r"robots: a folder of robots .* it has none"),
        (
            {"robots/r1/data.json": "robot.urdf", "robots/r1/held_out.json": None},
            "robots",
            r"r1: expected one measurement file \(\*.json\) .* found data.json, held_out.json; "
            r"name the files with a pattern instead",
        ),
        (
            {"robots/r1/data.json": None},
            "robots",
            r"r1/data.json: expected one nominal URDF \(\*.urdf\) beside it, found none; "
            r"put it there or give one URDF for the whole fleet \(--urdf\)",
        ),
        (
            {"robots/r1/data.json": "robot.urdf", "robots/r1/old.urdf": None},
            "robots",
            r"expected one nominal URDF \(\*.urdf\) beside it, found old.urdf, robot.urdf",
        ),
        (
            {"a/r1/data.json": "robot.urdf", "b/r1/data.json": "robot.urdf"},
            "*/r1/data.json",
            r"two robots named 'r1': .*a/r1/data.json and .*b/r1/data.json",
        ),
    ],
)
def test_a_layout_that_names_no_robot_or_two_of_a_name_is_refused(
    tmp_path, layout, source, message
):
    for path, urdf in layout.items():
        if path.endswith("/"):
            (tmp_path / path).mkdir(parents=True)
        else:
            _robot((tmp_path / path).parent, (tmp_path / path).name, urdf=urdf)
    with pytest.raises(ValueError, match=message):
        fleet_members([str(tmp_path / source)])
