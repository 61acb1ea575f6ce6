"""Real robots (example-robot-data): they load despite their extras, and calibrate.

Five URDFs as their makers ship them: Panda, UR10, TIAGo (prismatic torso lift, arm and
head on it, continuous wheels), PR2 (prismatic torso, two arms with continuous rolls,
mimic gripper joints) and iCub (torso, neck and two arms: a tree of three branches).
Meshes are ``package://`` files that are never resolved, and the joints off the measured
paths (mimic fingers, wheels, legs, the other arm) are ignored whatever their type.

For each robot the truth is the nominal URDF with errors on every joint of the measured
paths (1 mm, 0.2 deg; the data sees nothing else), and :func:`kinfw.identification.refine`
started from the nominal URDF must recover it from noise-free simulated data, checked
independently of the CPC model: Pinocchio FK of the truth against Pinocchio FK of the
exported calibrated URDF, at held-out configurations.

- ``pose`` observations of the measured frames in the URDF root;
- ``point`` observations of mocap markers, three of unknown offset on each measured frame
  and one of known offset, all in a ``mocap`` frame whose pose is unknown.

The iCub of example-robot-data 6.0 has no eye joints (its head is the neck's three joints
only), so the binocular-head case stays with the IIS head of the other tests.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

import numpy as np
import pytest

from kinfw.geometry import matrix_from_rotation_vector, transform_from_rotation_translation
from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel
from kinfw.measurements import Measurements
from kinfw.model import Robot, geometry_from_cpc, load_robot
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import pose_discrepancy, random_joint_values
from tests.erd import robots_dir, urdf_path

if robots_dir() is None:  # a test dependency (the "test" extra): fail, never skip
    raise ImportError("example-robot-data is not installed: pip install -e '.[test]'")

SIGMA = NoiseModel(1e-3, 1e-3)
TOL = 1e-8  # m and rad
MOCAP_T_ROOT = transform_from_rotation_translation(
    matrix_from_rotation_vector([0.3, -0.2, 1.0]), [1.0, -0.5, 0.2]
)


@dataclass(frozen=True)
class RealRobot:
    """A robot of example-robot-data and what the tests measure on it.

    ``frames`` are measured (poses; three unknown markers each); ``known_frame`` carries
    the one marker of known offset. ``features`` is what makes the URDF a loading test.
    """

    name: str
    urdf: str
    frames: tuple[str, ...]
    known_frame: str
    features: frozenset[str]
    n: int = 60


REAL_ROBOTS = (
    RealRobot(
        "panda",
        "panda_description/urdf/panda.urdf",
        ("panda_hand",),
        "panda_hand",
        frozenset({"meshes", "mimic", "idle joints"}),
    ),
    RealRobot(
        "ur10", "ur_description/urdf/ur10_robot.urdf", ("tool0",), "tool0", frozenset({"meshes"})
    ),
    RealRobot(
        "tiago",
        "tiago_description/robots/tiago.urdf",
        ("arm_tool_link", "xtion_rgb_optical_frame"),
        "arm_tool_link",
        frozenset({"meshes", "sensors", "wheels", "prismatic on path", "idle joints"}),
    ),
    RealRobot(
        "pr2",
        "pr2_description/urdf/pr2.urdf",
        ("l_gripper_tool_frame", "r_gripper_tool_frame"),
        "l_gripper_tool_frame",
        frozenset(
            {"meshes", "sensors", "mimic", "continuous on path", "prismatic on path", "idle joints"}
        ),
    ),
    # 'head', 'l_hand', 'r_hand' are child links of revolute joints; the known marker goes
    # on 'imu_frame' (fixed on the head); see the export test at the end.
    RealRobot(
        "icub",
        "icub_description/robots/icub.urdf",
        ("head", "l_hand", "r_hand"),
        "imu_frame",
        frozenset({"meshes", "sensors", "idle joints"}),
    ),
)
BY_NAME = {r.name: r for r in REAL_ROBOTS}


def _features(robot: Robot, frames: tuple[str, ...]) -> frozenset[str]:
    on_paths = set(robot.topology(frames).joint_names)
    found = set()
    if re.search(r"<mesh\s+filename=\"package://", robot.urdf_xml):
        found.add("meshes")
    if "<sensor" in robot.urdf_xml:
        found.add("sensors")
    for j in robot.joints:
        if j.mimic is not None:
            found.add("mimic")
        if j.type == "continuous":
            found.add("continuous on path" if j.name in on_paths else "wheels")
        if j.type == "prismatic" and j.name in on_paths:
            found.add("prismatic on path")
        if j.is_movable and j.name not in on_paths:
            found.add("idle joints")
    return frozenset(found)


def _path_joints(robot: Robot, frames: tuple[str, ...]) -> tuple[str, ...]:
    """Every URDF joint (fixed ones too) on the paths from the root to ``frames``."""
    return tuple(dict.fromkeys(j.name for f in frames for j in robot.path_joints(f)))


def _identifiable_count(robot: Robot, frames: tuple[str, ...]) -> int:
    """4 per revolute joint, 2 per prismatic joint, 6 per end frame (DESIGN.md) — 4 for
    an end frame that is itself a revolute joint's child link, whose origin a URDF keeps
    on the joint axis."""
    revolute = robot.topology(frames).revolute
    on_axis = sum(
        1
        for f in frames
        if robot.path_joints(f)[-1].child == f and robot.path_joints(f)[-1].is_revolute
    )
    return 4 * sum(revolute) + 2 * (len(revolute) - sum(revolute)) + 6 * len(frames) - 2 * on_axis


def _setup(spec: RealRobot, frames: tuple[str, ...], seed: int, n: int | None = None):
    """Nominal and true robots, the joints of the paths, data and held-out configurations."""
    nominal = load_robot(urdf_path(spec.urdf))
    rng = np.random.default_rng(seed)
    truth = load_robot(
        perturb_robot(
            nominal,
            rng,
            origin_mm=1.0,
            origin_deg=0.2,
            axis_deg=0.2,
            joints=_path_joints(nominal, frames),
        )
    )
    names = nominal.topology(frames).joint_names
    qs = random_configurations(*nominal.joint_limits(names), n or spec.n, rng, fraction=0.8)
    q_test = random_joint_values(nominal, names, 30, np.random.default_rng(seed + 1))
    return nominal, truth, names, qs, q_test, rng


def _mocap_data(
    truth: Robot, qs, names, spec: RealRobot, rng: np.random.Generator, *, noise_m: float = 0.0
):
    """Points of three unknown-offset markers per frame and one known, in 'mocap'."""
    offsets = {
        (f, f"{f}_m{k}"): rng.normal(0.0, 0.05, size=3) for f in spec.frames for k in range(3)
    }
    known = (spec.known_frame, np.array([0.02, -0.01, 0.03]))
    markers = [(f, offset, name) for (f, name), offset in offsets.items()]
    data = simulate_at(truth, qs, names, markers=[*markers, known], rng=rng, noise_m=noise_m)
    R, p = MOCAP_T_ROOT[:3, :3], MOCAP_T_ROOT[:3, 3]
    moved = tuple(
        replace(g, meas_p_point=g.meas_p_point @ R.T + p, measured_in="mocap") for g in data.points
    )
    return Measurements(data.joint_names, data.qs, points=moved), offsets, known


def _marker_prediction_errors(
    result, nominal: Robot, truth: Robot, names, q_test, offsets, known
) -> dict[str, float]:
    """Largest distance (m) per marker between the calibrated prediction in mocap
    (export's w_T_root @ Pinocchio FK of the exported URDF @ estimated offset) and the
    truth's, at held-out configurations."""
    export = export_urdf(nominal, geometry_from_cpc(result.model), root_is_measurement_frame=False)
    calibrated = load_robot(export.urdf_xml)
    estimated = {u.name: u.value for u in result.unknowns if u.kind == "offset"}
    checks = [(f, estimated[f"{f}:{name}"], offset, name) for (f, name), offset in offsets.items()]
    checks.append((known[0], known[1], known[1], "known"))
    errors = {}
    for frame, offset_hat, offset, name in checks:
        pred = export.w_T_root @ calibrated.frame_poses(q_test, frame, names)
        true = MOCAP_T_ROOT @ truth.frame_poses(q_test, frame, names)
        d = (
            pred[:, :3, :3] @ offset_hat
            + pred[:, :3, 3]
            - (true[:, :3, :3] @ offset + true[:, :3, 3])
        )
        errors[name] = float(np.linalg.norm(d, axis=-1).max())
    return errors


@pytest.mark.parametrize("spec", REAL_ROBOTS, ids=lambda r: r.name)
def test_the_robot_loads_without_meshes_despite_joints_off_the_measured_paths(spec, tmp_path):
    """Copied alone into an empty directory, no mesh can be found; it loads all the same,
    and only the measured paths must be revolute, continuous or prismatic."""
    copy = tmp_path / "robot.urdf"
    copy.write_text(urdf_path(spec.urdf).read_text(encoding="utf-8"), encoding="utf-8")
    robot = load_robot(copy)
    assert [p.name for p in tmp_path.iterdir()] == ["robot.urdf"]
    assert len(robot.joints) == len(ET.fromstring(robot.urdf_xml).findall("joint"))
    continuous = sum(j.type == "continuous" for j in robot.joints)
    assert robot.model.nq == len(robot.joint_names) + continuous  # Pinocchio has them all
    assert _features(robot, spec.frames) == spec.features
    topology = robot.topology((*spec.frames, spec.known_frame))
    assert set(topology.joint_names) <= set(robot.joint_names)
    for name in topology.joint_names:
        assert robot.joint(name).mimic is None


@pytest.mark.slow
@pytest.mark.parametrize("spec", REAL_ROBOTS, ids=lambda r: r.name)
def test_poses_in_the_root_recover_the_truth_through_the_exported_urdf(spec):
    nominal, truth, names, qs, q_test, rng = _setup(spec, spec.frames, seed=10)
    data = simulate_at(truth, qs, names, frames=spec.frames, rng=rng)
    result = refine(nominal, data, noise=SIGMA)
    assert result.converged and result.model_frame is None
    ident = result.identifiability
    assert ident.rank == ident.n_parameters == _identifiable_count(nominal, spec.frames)
    export = export_urdf(nominal, geometry_from_cpc(result.model))
    calibrated = load_robot(export.urdf_xml)
    assert calibrated.joint_names == nominal.joint_names
    assert [j.mimic for j in calibrated.joints] == [j.mimic for j in nominal.joints]
    for frame in spec.frames:
        true = truth.frame_poses(q_test, frame, names)
        dp, dr = pose_discrepancy(result.model.frame_poses(q_test, frame), true)
        assert dp < TOL and dr < TOL, ("cpc", frame, dp, dr)
        dp, dr = pose_discrepancy(calibrated.frame_poses(q_test, frame, names), true)
        assert dp < TOL and dr < TOL, ("urdf", frame, dp, dr)


@pytest.mark.slow
@pytest.mark.parametrize("spec", REAL_ROBOTS, ids=lambda r: r.name)
def test_mocap_markers_of_unknown_offset_in_an_unknown_frame_are_recovered(spec):
    frames = tuple(dict.fromkeys((*spec.frames, spec.known_frame)))
    nominal, truth, names, qs, q_test, rng = _setup(spec, frames, seed=20)
    data, offsets, known = _mocap_data(truth, qs, names, spec, rng)
    result = refine(nominal, data, noise=SIGMA)
    assert result.converged and result.model_frame == "mocap"
    errors = _marker_prediction_errors(result, nominal, truth, names, q_test, offsets, known)
    assert max(errors.values()) < TOL, errors


@pytest.mark.slow
def test_noisy_mocap_markers_give_a_consistent_fit_and_sub_noise_predictions():
    """0.2 mm per coordinate on the Panda, noise estimated: the fit finds the noise it was
    given and predicts held-out marker positions better than one measurement."""
    spec = BY_NAME["panda"]
    nominal, truth, names, qs, q_test, rng = _setup(spec, spec.frames, seed=30, n=150)
    data, offsets, known = _mocap_data(truth, qs, names, spec, rng, noise_m=0.2e-3)
    result = refine(nominal, data)
    assert result.converged and result.noise.estimated
    assert result.noise.position_m == pytest.approx(0.2e-3, rel=0.1)
    errors = _marker_prediction_errors(result, nominal, truth, names, q_test, offsets, known)
    assert max(errors.values()) < 0.2e-3, errors
    frame, offset = known  # the nominal URDF, even given the true offset, is mm off
    d = nominal.frame_poses(q_test, frame, names) - truth.frame_poses(q_test, frame, names)
    assert np.linalg.norm(d[:, :3, :3] @ offset + d[:, :3, 3], axis=-1).max() > 2e-3


@pytest.mark.slow
def test_a_known_marker_on_the_child_link_of_a_revolute_joint_exports():
    """A known point leaves the frame's rotation about it unidentifiable; refine keeps a
    revolute joint's child-link origin on the joint axis, so the export accepts it."""
    spec = replace(BY_NAME["icub"], known_frame="head")
    nominal, truth, names, qs, q_test, rng = _setup(spec, spec.frames, seed=20)
    data, offsets, known = _mocap_data(truth, qs, names, spec, rng)
    result = refine(nominal, data, noise=SIGMA)
    errors = _marker_prediction_errors(result, nominal, truth, names, q_test, offsets, known)
    assert max(errors.values()) < TOL, errors
