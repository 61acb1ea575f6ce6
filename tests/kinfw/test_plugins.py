"""Plugins from another installed package (:mod:`kinfw.plugins`), through the shell.

Two tiny distributions are built in a temporary folder and installed there without
network (``pip install --no-deps --no-build-isolation --no-index --target SITE``):

- ``kinfw-origin-plugin``: the entry point ``origin`` (a module whose import registers an
  observation kind ``"origin"``, a frame's origin measured in the URDF root, a robot block
  ``cyclic`` of ``--model``, a gear's cyclic error, and a command ``kinfw origin``) and
  ``horaud`` (a ``module:function`` that registers Horaud & Dornaika's (1995) quaternion
  form of ``A X = X B`` as the start ``horaud_q``);
- ``kinfw-broken-plugin``: an entry point whose module raises on import.

Every check runs the venv's ``kinfw`` console script with ``PYTHONPATH=SITE``, both
plugins installed: the broken one is named in one warning line and the rest works. The
truths are Pinocchio's forward kinematics of the URDFs and the poses a hand-eye scene was
built from (tests/pin_se3.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from kinfw.model import load_robot
from kinfw.simulation import perturb_robot
from kinfw.verification.evaluation import random_joint_values
from tests.pin_se3 import inverse, random_axis, rotation, transform
from tests.robots import ARM_6R

KINFW = Path(sys.executable).parent / "kinfw"
NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")

PYPROJECT = """\
[build-system]
requires = ["setuptools"]
build-backend = "setuptools.build_meta"

[project]
name = "{name}"
version = "0.1"

[project.entry-points."kinfw.plugins"]
{entry_points}

[tool.setuptools]
packages = ["{package}"]
"""

#: The plugin's module: registers the kind and the command when it is imported.
ORIGIN_MODULE = '''\
"""The kind "origin" (xyz of a frame's origin in the URDF root), the robot block
"cyclic" (a gear's cyclic error) and ``kinfw origin``."""

import json
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from kinfw.cli import register_command
from kinfw.model import BlockKey, ParameterName, SpecBlock, register_block
from kinfw.observations import (
    POSITION,
    ObservationKind,
    data_array,
    register_kind,
    sample_array,
)


@dataclass(frozen=True, slots=True, eq=False)
class OriginObservations:
    kind: ClassVar[str] = "origin"
    frame: str
    sample: np.ndarray
    w_p_origin: np.ndarray

    def __post_init__(self):
        sample = sample_array(self.sample, "OriginObservations.sample")
        object.__setattr__(self, "sample", sample)
        p = data_array(self.w_p_origin, (len(sample), 3), "OriginObservations.w_p_origin")
        object.__setattr__(self, "w_p_origin", p)


class OriginKind(ObservationKind):
    name = "origin"
    group_type = OriginObservations
    row_fields = ("w_p_origin",)
    components = (POSITION,)

    def parse(self, reader, obs, at, frame):
        xyz = reader.numbers(reader.get(obs, "xyz", at, "3 numbers [x, y, z]"), 3, f"{at}.xyz")
        return (("frame", frame),), reader.lengths(xyz)

    def group_from_rows(self, key, sample, rows):
        return OriginObservations(sample=sample, w_p_origin=rows, **dict(key))

    def to_dicts(self, group, top_measured_in):
        return [
            {"frame": group.frame, "kind": "origin", "xyz": p} for p in group.w_p_origin.tolist()
        ]

    def frames(self, group):
        return (group.frame,)

    def direct_frames(self, group):
        return (group.frame,)

    def data(self, group):
        return group.w_p_origin

    def residual(self, group, model, m):
        return m - model.w_T(group.frame)[0:3, 3]

    def predict(self, group, model):
        return model.w_T(group.frame, group.sample)[:, :3, 3]


register_kind(OriginKind())


@register_block
@dataclass(frozen=True, slots=True)
class CyclicErrorBlock(SpecBlock):
    """A gear's cyclic error: the joint turns q + b sin q for a reading q (b rad)."""

    joint: str = ""
    block_name: ClassVar[str] = "cyclic"

    @classmethod
    def from_spec(cls, argument):
        return cls(BlockKey("cyclic", argument), joint=argument)

    @property
    def fields(self):
        return ("cyclic_error",)

    @property
    def names(self):
        return (ParameterName(self.joint, "cyclic_error"),)

    @property
    def units(self):
        return ("rad",)

    def casadi_joint_values(self, q, d, c, joint_names, s=None):
        import casadi as ca

        k = joint_names.index(self.joint)
        e = [0.0] * len(joint_names)
        e[k] = 1.0
        return q + self.casadi_value(d, c)[0] * ca.sin(q[k]) * ca.DM(e)



def add_origin_parser(sub):
    p = sub.add_parser("origin", help="a frame's origin in the URDF root (mm) at joint values")
    p.add_argument("model")
    p.add_argument("frame")
    p.add_argument("--q", type=float, nargs="+", required=True, help="joint values, rad")
    p.set_defaults(func=cmd_origin)


def cmd_origin(args):
    from kinfw.model import load_robot

    robot = load_robot(args.model)
    if len(args.q) != len(robot.joint_names):
        raise ValueError(f"--q: expected {len(robot.joint_names)} joint values, got {len(args.q)}")
    xyz = robot.frame_poses(np.array(args.q), args.frame)[:3, 3]
    print(json.dumps({"frame": args.frame, "xyz_mm": (1e3 * xyz).tolist()}))
    return 0


register_command(add_origin_parser)
'''

#: A ``module:function`` entry point: the function registers the start (counted, so a
#: second registration would show).
STARTS_MODULE = '''\
"""Horaud & Dornaika (1995): (L(q_A) - R(q_B)) q_X = 0, then the translation."""

import numpy as np

from kinfw.geometry import average_transform, quat_xyzw_from_matrix
from kinfw.identification.handeye import StartMethod, register_start

REGISTERED = []


def _left(q):
    v, w = q[:3], q[3]
    out = np.empty((4, 4))
    out[:3, :3] = w * np.eye(3) + np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    out[:3, 3], out[3, :3], out[3, 3] = v, -v, w
    return out


def _right(p):
    u, s = p[:3], p[3]
    out = np.empty((4, 4))
    out[:3, :3] = s * np.eye(3) - np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    out[:3, 3], out[3, :3], out[3, 3] = u, -u, s
    return out


def horaud_axxb(A, B):
    i, j = np.triu_indices(len(A), k=1)
    A_ij = np.linalg.inv(A[j]) @ A[i]
    B_ij = B[j] @ np.linalg.inv(B[i])
    q_A = quat_xyzw_from_matrix(A_ij[:, :3, :3])
    q_B = quat_xyzw_from_matrix(B_ij[:, :3, :3])
    q_A *= np.sign(q_A[:, 3:4] + (q_A[:, 3:4] == 0))
    q_B *= np.sign(q_B[:, 3:4] + (q_B[:, 3:4] == 0))
    M = np.concatenate([_left(a) - _right(b) for a, b in zip(q_A, q_B)])
    x, y, z, w = np.linalg.svd(M)[2][-1]
    X = np.eye(4)
    X[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    lhs = (A_ij[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (B_ij[:, :3, 3] @ X[:3, :3].T - A_ij[:, :3, 3]).reshape(-1)
    X[:3, 3] = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return X, average_transform(A @ X @ B)


def register():
    REGISTERED.append(1)
    register_start("horaud_q", StartMethod("axxb", horaud_axxb))
'''

BROKEN_MODULE = 'raise RuntimeError("broken on purpose\\nthis second line is not shown")\n'


def _package(root: Path, name: str, package: str, entry_points: str, files: dict) -> Path:
    where = root / name
    (where / package).mkdir(parents=True)
    (where / "pyproject.toml").write_text(
        PYPROJECT.format(name=name, package=package, entry_points=entry_points)
    )
    for file, text in files.items():
        (where / package / file).write_text(text)
    return where


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """Both distributions installed into one folder, offline."""
    root = tmp_path_factory.mktemp("plugins")
    good = _package(
        root,
        "kinfw-origin-plugin",
        "kinfw_origin_plugin",
        'origin = "kinfw_origin_plugin"\nhoraud = "kinfw_origin_plugin.starts:register"',
        {"__init__.py": ORIGIN_MODULE, "starts.py": STARTS_MODULE},
    )
    broken = _package(
        root,
        "kinfw-broken-plugin",
        "kinfw_broken_plugin",
        'broken = "kinfw_broken_plugin"',
        {"__init__.py": BROKEN_MODULE},
    )
    target = root / "site"
    done = subprocess.run(
        [
            *(sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation"),
            *("--no-index", "--target", str(target), str(good), str(broken)),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    # setuptools >= 70.1 (the test extra) builds the wheels without the wheel package
    assert done.returncode == 0, done.stderr
    return target


def _run(site: Path, *args, program=(str(KINFW),)) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(site)}
    return subprocess.run(
        [*program, *map(str, args)], capture_output=True, text=True, env=env, check=False
    )


def _kinfw(site: Path, *args) -> str:
    """stdout of the shell's ``kinfw ARGS`` (exit code 0), after checking that stderr
    holds the broken plugin's warning, once, on one line."""
    done = _run(site, "-q", *args)
    assert done.returncode == 0, done.stderr
    warned = [line for line in done.stderr.splitlines() if "plugin 'broken'" in line]
    assert len(warned) == 1, done.stderr
    return done.stdout


def _origins(urdf_xml: str, qs: np.ndarray, frame: str) -> np.ndarray:
    """Pinocchio: the origin of ``frame`` in the root at each row of ``qs`` (NAMES), m
    (a continuous joint's two coordinates are cos and sin of its angle)."""
    model = pin.buildModelFromXML(urdf_xml)
    data = model.createData()
    out = []
    for q_row in np.atleast_2d(qs):
        q = pin.neutral(model)
        for name, value in zip(NAMES, q_row, strict=True):
            joint = model.joints[model.getJointId(name)]
            q[joint.idx_q : joint.idx_q + joint.nq] = (
                [value] if joint.nq == 1 else [np.cos(value), np.sin(value)]
            )
        pin.framesForwardKinematics(model, data, q)
        out.append(data.oMf[model.getFrameId(frame)].translation.copy())
    return np.array(out)


def _origin_file(path: Path, qs: np.ndarray, xyz_m: np.ndarray) -> Path:
    """A hand-written measurement file of ``origin`` observations of the flange, in mm."""
    samples = [
        {"q": q.tolist(), "observations": [{"frame": "flange", "kind": "origin", "xyz": p}]}
        for q, p in zip(qs, (1e3 * xyz_m).tolist(), strict=True)
    ]
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "mm", "angle": "rad"},
        "joint_names": list(NAMES),
        "samples": samples,
    }
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.slow
def test_help_lists_the_command_and_one_line_names_the_broken_plugin(site):
    done = _run(site, "--help")
    assert done.returncode == 0
    assert "origin" in done.stdout and "a frame's origin in the URDF root" in done.stdout
    (line,) = done.stderr.splitlines()
    assert line == (
        "kinfw: warning: plugin 'broken' of kinfw-broken-plugin (kinfw_broken_plugin) failed "
        "to load and was skipped: RuntimeError: broken on purpose"
    )
    assert len(line) < 200
    without = _run(site.parent / "nowhere", "--help")  # the same kinfw without the plugins
    assert without.returncode == 0 and "origin" not in without.stdout and not without.stderr


@pytest.mark.slow
def test_loading_is_lazy_once_and_thread_safe(site):
    """``import kinfw`` and ``import kinfw.cli`` load no plugin; the first look-up of a
    registry does, once, even when four threads ask at the same time: the function entry
    point ran once and the records name every entry point, the broken one's error too."""
    code = textwrap.dedent(
        """
        import sys, threading, warnings
        import kinfw, kinfw.cli
        print("before", "kinfw_origin_plugin" in sys.modules)
        from kinfw.plugins import load_plugins
        from kinfw.observations import kinds
        warnings.simplefilter("ignore")
        found = []
        threads = [threading.Thread(target=lambda: found.append(load_plugins())) for _ in range(4)]
        for t in threads: t.start()
        for t in threads: t.join()
        from kinfw_origin_plugin.starts import REGISTERED
        print("after", len(REGISTERED), len({id(f) for f in found}), kinds()[-1].name)
        for p in sorted(load_plugins(), key=lambda p: p.name):
            print(p.distribution, p.name, p.value, p.error)
        """
    )
    done = _run(site, "-c", code, program=(sys.executable,))
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "before False",
        "after 1 1 origin",
        "kinfw-broken-plugin broken kinfw_broken_plugin RuntimeError: broken on purpose",
        "kinfw-origin-plugin horaud kinfw_origin_plugin.starts:register None",
        "kinfw-origin-plugin origin kinfw_origin_plugin None",
    ]


@pytest.mark.slow
def test_the_plugin_command_runs_from_the_shell(site, tmp_path):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM_6R)
    q = np.array([0.3, -0.4, 0.5, 0.2, -0.1, 0.7])
    doc = json.loads(_kinfw(site, "origin", urdf, "flange", "--q", *q))
    np.testing.assert_allclose(doc["xyz_mm"], 1e3 * _origins(ARM_6R, q, "flange")[0], atol=1e-9)
    done = _run(site, "-q", "origin", urdf, "flange", "--q", "0.1")  # its error: one line
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1] == (
        "kinfw origin: error: --q: expected 6 joint values, got 1"
    )


@pytest.mark.slow
def test_a_file_of_the_plugin_kind_is_verified_and_calibrated_exactly(site, tmp_path):
    """40 noise-free origins of a perturbed 6R arm's flange, in mm: ``kinfw verify`` of
    the nominal arm gives the plugin kind's errors as Pinocchio computes them, and
    ``kinfw calibrate --params full`` recovers the flange's origin at 50 held-out
    configurations to 1e-9 m (the only data are of the plugin's kind)."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(3)
    truth = perturb_robot(nominal, rng)
    qs = random_joint_values(nominal, NAMES, 90, rng)
    true = _origins(truth, qs, "flange")
    train = _origin_file(tmp_path / "train.json", qs[:40], true[:40])
    held = _origin_file(tmp_path / "held.json", qs[40:], true[40:])
    (tmp_path / "arm.urdf").write_text(ARM_6R)

    doc = json.loads(_kinfw(site, "verify", tmp_path / "arm.urdf", held, "--json"))
    (group,) = doc["groups"]
    error = np.linalg.norm(true[40:] - _origins(ARM_6R, qs[40:], "flange"), axis=1)
    assert group["kind"] == "origin" and error.max() > 1e-3  # the nominal is off by mm
    assert group["position_rms_mm"] == pytest.approx(1e3 * np.sqrt(np.mean(error**2)), rel=1e-9)

    out = tmp_path / "cal.urdf"
    _kinfw(site, "calibrate", train, "--urdf", tmp_path / "arm.urdf", "--out", out, "--params=full")
    calibrated = _origins(out.read_text(), qs[40:], "flange")
    np.testing.assert_allclose(calibrated, true[40:], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_the_plugin_block_is_calibrated_and_reapplied_by_verify(site, tmp_path):
    """The truth's j2 turns q + b sin q (b = 10 mrad) for a reading q: ``kinfw calibrate
    --model cyclic:j2`` recovers b to 1e-9 from 40 noise-free origins, the sidecar
    records the plugin's block, and ``kinfw verify`` re-applies it with no flag: 50
    held-out origins to 1e-6 mm."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(4)
    truth = perturb_robot(nominal, rng)
    qs = random_joint_values(nominal, NAMES, 90, rng)
    turned = qs.copy()
    turned[:, 1] += 0.01 * np.sin(qs[:, 1])
    true = _origins(truth, turned, "flange")
    train = _origin_file(tmp_path / "train.json", qs[:40], true[:40])
    held = _origin_file(tmp_path / "held.json", qs[40:], true[40:])
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    out = tmp_path / "cal.urdf"
    _kinfw(
        site,
        "calibrate",
        train,
        "--urdf",
        tmp_path / "arm.urdf",
        "--out",
        out,
        "--params=full",
        "--model",
        "cyclic:j2",
    )
    (record,) = json.loads(out.with_suffix(".kinfw.json").read_text())["robot_blocks"]
    assert record["block"] == "cyclic:j2" and record["names"] == ["j2:cyclic_error"]
    assert record["values"][0] == pytest.approx(0.01, abs=1e-9)
    doc = json.loads(_kinfw(site, "verify", out, held, "--json"))
    assert doc["groups"][0]["position_max_mm"] < 1e-6


def _hand_eye_pairs(path: Path, seed: int = 7, n: int = 10):
    """Noise-free eye-in-hand pose pairs (as a .json list of [base_T_hand,
    camera_T_target]) and their truth ``hand_T_camera``, ``base_T_target``."""
    rng = np.random.default_rng(seed)
    hand_T_camera = transform(rotation(random_axis(rng) * 2.0), [0.03, -0.02, 0.08])
    base_T_target = transform(rotation(random_axis(rng)), [0.5, 0.1, 0.2])
    base_T_hands = np.stack(
        [
            transform(rotation(random_axis(rng) * rng.uniform(0.2, 1.5)), rng.uniform(-0.3, 0.3, 3))
            for _ in range(n)
        ]
    )
    camera_T_targets = inverse(hand_T_camera) @ inverse(base_T_hands) @ base_T_target
    pairs = zip(base_T_hands.tolist(), camera_T_targets.tolist(), strict=True)
    path.write_text(json.dumps([list(pair) for pair in pairs]))
    return path, hand_T_camera, base_T_target


@pytest.mark.slow
def test_the_plugin_start_is_fitted_by_handeye_method(site, tmp_path):
    pairs, hand_T_camera, base_T_target = _hand_eye_pairs(tmp_path / "pairs.json")
    doc = json.loads(_kinfw(site, "handeye", pairs, "--method", "horaud_q", "--json"))
    kinfw_row, row = doc["methods"]
    assert (kinfw_row["method"], row["method"], row["error"]) == ("kinfw", "horaud_q", None)
    np.testing.assert_allclose(row["hand_T_camera"], hand_T_camera, rtol=0, atol=1e-9)
    np.testing.assert_allclose(row["base_T_target"], base_T_target, rtol=0, atol=1e-9)
    assert row["kfold"]["rms_translation_mm"] < 1e-6  # 5 folds, each fitted by the start
    every = json.loads(_kinfw(site, "handeye", pairs, "--method", "all", "--k", "2", "--json"))
    assert [r["method"] for r in every["methods"]][-1] == "horaud_q"
    done = _run(site, "-q", "handeye", pairs, "--method", "nobody")
    assert done.returncode == 2
    assert "unknown method(s) nobody: use all or some of tsai, park" in done.stderr
    assert "li, horaud_q" in done.stderr
