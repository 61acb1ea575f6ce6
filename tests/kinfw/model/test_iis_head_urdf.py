"""Checks of ``robots/iis_head.urdf`` against the IIS-head of Shih et al. (Tables 2 and 3).

The truth is computed here, independently of kinfw: the standard (distal) DH product of the
paper's Table 3, i-1_T_i = Rot(z, theta_i) Trans(z, d_i) Trans(x, a_i) Rot(x, alpha_i), with
hand-written numpy rotations and translations, preceded by the world_T_base that the URDF's
``world_to_base`` joint declares (read with plain XML parsing and an own rpy -> matrix).
Pinocchio's forward kinematics of the URDF must reproduce that product at the plates
(DH frames 5L and 5R) to 1e-12.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from tests.paths import HEAD_URDF as URDF_PATH

DEG = np.pi / 180.0
MM = 1e-3

ATOL_POSE = 1e-12  # m and (dimensionless) rotation-matrix entries
ATOL_LIMIT = 1e-15  # limits are written with repr, so they must be exact
SEED = 20240611
N_RANDOM = 64

MOVABLE_JOINTS = ("x_table", "y_table", "pan", "tilt", "vergence_left", "vergence_right")

# Table 3 of the paper: theta, d, alpha, a (mm -> m, deg -> rad). For a revolute joint the
# joint variable is theta (offset 0 here), for a prismatic one it is d (offset 0 here).
TABLE3 = {
    "x_table": {"type": "prismatic", "theta": 0.0 * DEG, "d": 0.0, "alpha": -90.0 * DEG, "a": 0.0},
    "y_table": {"type": "prismatic", "theta": 90.0 * DEG, "d": 0.0, "alpha": -90.0 * DEG, "a": 0.0},
    "pan": {"type": "revolute", "theta": 0.0, "d": 450.0 * MM, "alpha": -90.0 * DEG, "a": 0.0},
    "tilt": {
        "type": "revolute",
        "theta": 0.0,
        "d": 150.0 * MM,
        "alpha": 85.0 * DEG,
        "a": 50.0 * MM,
    },
    "vergence_left": {
        "type": "revolute",
        "theta": 0.0,
        "d": 100.0 * MM,
        "alpha": 0.0 * DEG,
        "a": 0.0,
    },
    "vergence_right": {
        "type": "revolute",
        "theta": 0.0,
        "d": 250.0 * MM,
        "alpha": 35.0 * DEG,
        "a": 70.0 * MM,
    },
}

# Table 2 of the paper: joint ranges (mm -> m, deg -> rad).
TABLE2_LIMITS = {
    "x_table": (0.0, 1000.0 * MM),
    "y_table": (0.0, 500.0 * MM),
    "pan": (0.0, 180.0 * DEG),
    "tilt": (0.0, 60.0 * DEG),
    "vergence_left": (0.0, 90.0 * DEG),
    "vergence_right": (0.0, 90.0 * DEG),
}

# (joint, type, parent link, child link) as the design requires.
TREE = (
    ("world_to_base", "fixed", "world", "base"),
    ("x_table", "prismatic", "base", "x_carriage"),
    ("y_table", "prismatic", "x_carriage", "y_carriage"),
    ("pan", "revolute", "y_carriage", "pan_link"),
    ("tilt", "revolute", "pan_link", "tilt_link"),
    ("vergence_left", "revolute", "tilt_link", "vergence_left_link"),
    ("vergence_right", "revolute", "tilt_link", "vergence_right_link"),
    ("left_plate_joint", "fixed", "vergence_left_link", "left_plate"),
    ("right_plate_joint", "fixed", "vergence_right_link", "right_plate"),
    ("left_camera_joint", "fixed", "left_plate", "left_camera"),
    ("right_camera_joint", "fixed", "right_plate", "right_camera"),
)

# side -> (plate link, camera link, vergence joint)
BRANCHES = {
    "left": ("left_plate", "left_camera", "vergence_left"),
    "right": ("right_plate", "right_camera", "vergence_right"),
}


# --------------------------------------------------------------------------- own maths
def rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[0, 0], T[0, 2], T[2, 0], T[2, 2] = c, s, -s, c
    return T


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[0:2, 0:2] = [[c, -s], [s, c]]
    return T


def trans(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[0:3, 3] = [x, y, z]
    return T


def xyz_rpy_to_T(xyz, rpy) -> np.ndarray:
    """URDF origin: Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)."""
    roll, pitch, yaw = rpy
    return trans(*xyz) @ rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard (distal) DH link transform i-1_T_i."""
    return rot_z(theta) @ trans(0.0, 0.0, d) @ trans(a, 0.0, 0.0) @ rot_x(alpha)


def table3_link(name: str, q: float) -> np.ndarray:
    p = TABLE3[name]
    if p["type"] == "revolute":
        return dh(p["theta"] + q, p["d"], p["a"], p["alpha"])
    return dh(p["theta"], p["d"] + q, p["a"], p["alpha"])


def table3_world_T_plates(q: dict[str, float], world_T_base: np.ndarray):
    """world_T_5L and world_T_5R of Table 3 (the paper's eq. 7 with DH links)."""
    base_T_4 = (
        table3_link("x_table", q["x_table"])
        @ table3_link("y_table", q["y_table"])
        @ table3_link("pan", q["pan"])
        @ table3_link("tilt", q["tilt"])
    )
    world_T_4 = world_T_base @ base_T_4
    return {
        "left": world_T_4 @ table3_link("vergence_left", q["vergence_left"]),
        "right": world_T_4 @ table3_link("vergence_right", q["vergence_right"]),
    }


def rotation_angle(R: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


# --------------------------------------------------------------------------- fixtures
def parse_floats(text: str | None, default: str) -> np.ndarray:
    return np.array([float(v) for v in (text or default).split()])


@pytest.fixture(scope="module")
def xml_root() -> ET.Element:
    return ET.parse(URDF_PATH).getroot()


def xml_joint(root: ET.Element, name: str) -> ET.Element:
    matches = [j for j in root.findall("joint") if j.get("name") == name]
    assert len(matches) == 1, f"expected exactly one joint {name!r}, found {len(matches)}"
    return matches[0]


def xml_origin_T(joint: ET.Element) -> np.ndarray:
    origin = joint.find("origin")
    if origin is None:
        return np.eye(4)
    return xyz_rpy_to_T(
        parse_floats(origin.get("xyz"), "0 0 0"), parse_floats(origin.get("rpy"), "0 0 0")
    )


@pytest.fixture(scope="module")
def world_T_base(xml_root) -> np.ndarray:
    return xml_origin_T(xml_joint(xml_root, "world_to_base"))


@pytest.fixture(scope="module")
def model() -> pin.Model:
    return pin.buildModelFromUrdf(str(URDF_PATH))


@pytest.fixture(scope="module")
def idx_q(model) -> dict[str, int]:
    out = {}
    for name in MOVABLE_JOINTS:
        assert model.existJointName(name), name
        out[name] = model.joints[model.getJointId(name)].idx_q
    return out


def random_configurations(n: int, seed: int) -> list[dict[str, float]]:
    rng = np.random.default_rng(seed)
    return [
        {name: float(rng.uniform(*TABLE2_LIMITS[name])) for name in MOVABLE_JOINTS}
        for _ in range(n)
    ]


ZERO = dict.fromkeys(MOVABLE_JOINTS, 0.0)
UPPER = {name: TABLE2_LIMITS[name][1] for name in MOVABLE_JOINTS}
CONFIGURATIONS = [ZERO, UPPER, *random_configurations(N_RANDOM, SEED)]


def pin_q(model, idx_q, q: dict[str, float]) -> np.ndarray:
    qv = pin.neutral(model)
    for name, value in q.items():
        qv[idx_q[name]] = value
    return qv


def frame_pose(model, data, name: str) -> np.ndarray:
    assert model.existFrame(name), name
    return data.oMf[model.getFrameId(name)].homogeneous.copy()


def pin_fk(model, idx_q, q: dict[str, float]):
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin_q(model, idx_q, q))
    return data


# --------------------------------------------------------------------------- tests
def test_file_loads_with_yourdfpy():
    robot = yourdfpy.URDF.load(URDF_PATH, load_meshes=False, build_scene_graph=False)
    assert robot.robot.name == "iis_head"
    assert tuple(robot.actuated_joint_names) == MOVABLE_JOINTS
    assert robot.robot.links[0].name == "world"
    for name in MOVABLE_JOINTS:
        limit = robot.joint_map[name].limit
        assert (limit.lower, limit.upper) == pytest.approx(TABLE2_LIMITS[name], abs=ATOL_LIMIT)
    for link in robot.robot.links:
        for visual in link.visuals:
            assert visual.geometry.mesh is None, link.name


def test_tree_has_the_required_links_joints_and_parents(xml_root):
    joints = {j.get("name"): j for j in xml_root.findall("joint")}
    assert set(joints) == {name for name, *_ in TREE}
    for name, jtype, parent, child in TREE:
        joint = joints[name]
        assert joint.get("type") == jtype, name
        assert joint.find("parent").get("link") == parent, name
        assert joint.find("child").get("link") == child, name
    links = {link.get("name") for link in xml_root.findall("link")}
    assert links == {"world"} | {child for *_, child in TREE}


def test_movable_joints_in_document_order_with_paper_types(xml_root, model):
    movable = [j for j in xml_root.findall("joint") if j.get("type") != "fixed"]
    assert tuple(j.get("name") for j in movable) == MOVABLE_JOINTS
    for joint in movable:
        name = joint.get("name")
        assert joint.get("type") == TABLE3[name]["type"], name
        np.testing.assert_array_equal(
            parse_floats(joint.find("axis").get("xyz"), ""), [0.0, 0.0, 1.0], err_msg=name
        )
    # Pinocchio: universe + the six joints, one coordinate each, in the same order
    assert tuple(model.names)[1:] == MOVABLE_JOINTS
    assert model.nq == len(MOVABLE_JOINTS)
    assert model.nv == len(MOVABLE_JOINTS)
    expected_short = {"prismatic": "JointModelPZ", "revolute": "JointModelRZ"}
    for name in MOVABLE_JOINTS:
        joint = model.joints[model.getJointId(name)]
        assert joint.shortname() == expected_short[TABLE3[name]["type"]], name


def test_joint_limits_match_table2(xml_root, model, idx_q):
    for name in MOVABLE_JOINTS:
        lower, upper = TABLE2_LIMITS[name]
        limit = xml_joint(xml_root, name).find("limit")
        assert limit is not None, name
        assert float(limit.get("lower")) == pytest.approx(lower, abs=ATOL_LIMIT), name
        assert float(limit.get("upper")) == pytest.approx(upper, abs=ATOL_LIMIT), name
        assert float(limit.get("effort")) > 0.0, name
        assert float(limit.get("velocity")) > 0.0, name
        i = idx_q[name]
        assert model.lowerPositionLimit[i] == pytest.approx(lower, abs=ATOL_LIMIT), name
        assert model.upperPositionLimit[i] == pytest.approx(upper, abs=ATOL_LIMIT), name


@pytest.mark.parametrize("side", ["left", "right"])
def test_zero_configuration_equals_dh_zero(model, idx_q, world_T_base, side):
    data = pin_fk(model, idx_q, ZERO)
    expected = table3_world_T_plates(ZERO, world_T_base)[side]
    np.testing.assert_allclose(
        frame_pose(model, data, BRANCHES[side][0]), expected, rtol=0.0, atol=ATOL_POSE
    )


def test_plate_poses_match_table3_dh_product(model, idx_q, world_T_base):
    assert len(CONFIGURATIONS) >= 50
    worst = 0.0
    for k, q in enumerate(CONFIGURATIONS):
        data = pin_fk(model, idx_q, q)
        expected = table3_world_T_plates(q, world_T_base)
        for side, (plate, _, _) in BRANCHES.items():
            world_T_plate = frame_pose(model, data, plate)
            err = float(np.max(np.abs(world_T_plate - expected[side])))
            worst = max(worst, err)
            assert err <= ATOL_POSE, f"configuration {k} {q}: {side} plate off by {err:.3e}"
    assert worst <= ATOL_POSE


def test_stereo_rig_faces_the_head_from_about_1p5_m(model, idx_q, world_T_base):
    # table at mid travel, pan 90 deg: the head looks towards the rig (DESIGN: rig ~1.5 m)
    q = {
        "x_table": 0.5,
        "y_table": 0.25,
        "pan": 90.0 * DEG,
        "tilt": 0.0,
        "vergence_left": 0.0,
        "vergence_right": 0.0,
    }
    data = pin_fk(model, idx_q, q)
    for plate, _, _ in BRANCHES.values():
        world_T_plate = frame_pose(model, data, plate)
        p = world_T_plate[:3, 3]
        assert 1.2 <= np.linalg.norm(p) <= 1.8, plate
        # in front of the rig, within 20 deg of its viewing direction (z)
        assert p[2] / np.linalg.norm(p) >= np.cos(20.0 * DEG), plate
        # the plate's looking direction (x of DH frame 5) points back at the rig
        assert world_T_plate[:3, 0] @ [0.0, 0.0, 1.0] <= -0.9, plate
    # the rig is above the head: the world "down" axis (y) has the base below the rig
    assert world_T_base[1, 3] > 0.0


@pytest.mark.parametrize("side", ["left", "right"])
def test_camera_is_rigidly_attached_to_its_plate(xml_root, model, idx_q, side):
    plate, camera, _ = BRANCHES[side]
    nominal = xml_origin_T(xml_joint(xml_root, f"{side}_camera_joint"))
    for k, q in enumerate(CONFIGURATIONS):
        data = pin_fk(model, idx_q, q)
        plate_T_camera = np.linalg.inv(frame_pose(model, data, plate)) @ frame_pose(
            model, data, camera
        )
        np.testing.assert_allclose(
            plate_T_camera, nominal, rtol=0.0, atol=ATOL_POSE, err_msg=f"configuration {k}"
        )
    # a non-trivial, plausible hand-eye transform: tens of mm away from the plate
    offset = np.linalg.norm(nominal[:3, 3])
    assert 0.02 <= offset <= 0.15, offset


@pytest.mark.parametrize("side", ["left", "right"])
def test_camera_follows_optical_convention_and_looks_forward(model, idx_q, world_T_base, side):
    plate, camera, vergence = BRANCHES[side]
    jid = model.getJointId(vergence)
    for k, q in enumerate(CONFIGURATIONS):
        data = pin_fk(model, idx_q, q)
        world_R_camera = frame_pose(model, data, camera)[:3, :3]
        vergence_axis = data.oMi[jid].rotation[:, 2]  # URDF axis 0 0 1 of the joint
        looking = table3_world_T_plates(q, world_T_base)[side][:3, 0]  # x of DH frame 5
        z_cam, y_cam = world_R_camera[:, 2], world_R_camera[:, 1]
        msg = f"configuration {k}"
        # optical axis roughly perpendicular to the vergence axis ...
        assert abs(z_cam @ vergence_axis) < 0.2, msg
        # ... pointing the way the head looks, with the image upright (y down the axis)
        assert z_cam @ looking > 0.95, msg
        assert y_cam @ vergence_axis < -0.9, msg
    # the nominal mount is a few degrees off the exact optical alignment (non-trivial)
    data = pin_fk(model, idx_q, ZERO)
    plate_R_camera = (
        np.linalg.inv(frame_pose(model, data, plate)) @ frame_pose(model, data, camera)
    )[:3, :3]
    plate_R_vergence = (
        np.linalg.inv(frame_pose(model, data, plate))[:3, :3] @ data.oMi[jid].rotation
    )
    z_ideal = np.array([1.0, 0.0, 0.0])
    y_ideal = -plate_R_vergence[:, 2]
    y_ideal = y_ideal - (y_ideal @ z_ideal) * z_ideal
    y_ideal /= np.linalg.norm(y_ideal)
    plate_R_ideal = np.column_stack([np.cross(y_ideal, z_ideal), y_ideal, z_ideal])
    misalignment = rotation_angle(plate_R_ideal.T @ plate_R_camera)
    assert 0.5 * DEG <= misalignment <= 10.0 * DEG, misalignment / DEG


def test_links_have_primitive_visuals_materials_and_plausible_inertials(xml_root):
    materials = {}
    for m in xml_root.findall("material"):
        color = m.find("color")
        assert color is not None, m.get("name")
        rgba = parse_floats(color.get("rgba"), "")
        assert rgba.shape == (4,)
        assert np.all((rgba >= 0.0) & (rgba <= 1.0)), m.get("name")
        materials[m.get("name")] = rgba
    assert len(materials) >= 4
    for link in xml_root.findall("link"):
        name = link.get("name")
        visuals = link.findall("visual")
        assert visuals, f"link {name} has no visual"
        for visual in visuals:
            shapes = [g.tag for g in visual.find("geometry")]
            assert len(shapes) == 1, name
            assert shapes[0] in {"box", "cylinder", "sphere"}, (name, shapes)
            for dim in ("size", "radius", "length"):
                value = visual.find("geometry")[0].get(dim)
                if value is not None:
                    assert np.all(
                        (parse_floats(value, "") > 0.0) & (parse_floats(value, "") < 2.0)
                    ), (name, dim, value)
            material = visual.find("material")
            assert material is not None and material.get("name") in materials, name
        inertial = link.find("inertial")
        if name == "world":
            assert inertial is None  # the stereo rig is the fixed root, not a body
            continue
        assert inertial is not None, name
        mass = float(inertial.find("mass").get("value"))
        assert 0.01 <= mass <= 100.0, (name, mass)
        i = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
        inertia = np.array(
            [
                [i["ixx"], i["ixy"], i["ixz"]],
                [i["ixy"], i["iyy"], i["iyz"]],
                [i["ixz"], i["iyz"], i["izz"]],
            ]
        )
        principal = np.linalg.eigvalsh(inertia)
        assert principal[0] > 0.0, name
        # triangle inequality of principal moments (a physical rigid body)
        assert principal[0] + principal[1] >= principal[2] * (1.0 - 1e-9), name
