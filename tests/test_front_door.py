"""The front door: ``import kinfw`` gives the workflow as verbs, each an alias of its home,
each checked against an independent truth; and every command of the command line is a
thin layer over the same verb (the same files from the same inputs)."""

import ast
import importlib
import json
import math
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

import kinfw
from kinfw.cli._main import main
from kinfw.files import OutputPathError
from kinfw.identification.checks import ChangeBound
from kinfw.identification.planning import Setup, read_plan
from kinfw.records import read_sidecar
from kinfw.view import external_urls
from tests.fixation import fk_errors_rad, ideal_fixation_points
from tests.paths import HEAD_URDF, REPO
from tests.robots import IDEAL_HEAD

PLATES = ("left_plate", "right_plate")
#: The verbs and their homes, as a reader of the docs would write them.
HOMES = """
load_robot kinfw.model.load_robot
builtin_head_urdf kinfw.model.builtin_head_urdf
read_measurements kinfw.measurements.read_measurements
write_measurements kinfw.measurements.write_measurements
calibrate kinfw.verification.reporting.calibrate_and_report
evaluate kinfw.verification.evaluation.evaluate_model
crossvalidate kinfw.verification.evaluation.crossvalidate
simulate kinfw.simulation.simulate_measurements
plan kinfw.identification.planning.plan_measurement
show kinfw.view.show
fixate kinfw.control.fixate
reach kinfw.control.reach
solve_axxb kinfw.identification.handeye.solve_axxb
solve_axyb kinfw.identification.handeye.solve_axyb
"""


def _fk(model: pin.Model, q_urdf: dict[str, float], frame: str) -> pin.SE3:
    """Pinocchio's pose of ``frame`` at the joint values ``q_urdf`` (others neutral)."""
    q = pin.neutral(model)
    for name, value in q_urdf.items():
        q[model.joints[model.getJointId(name)].idx_q] = value
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(frame)]


@pytest.fixture(scope="module")
def experiment(tmp_path_factory):
    """A noise-free simulated experiment of the head (stage 1, 5 mm / 1 deg errors) from
    files: the nominal URDF, the data (read back), and the front door's calibration."""
    d = tmp_path_factory.mktemp("front")
    (d / "nominal.urdf").write_text(HEAD_URDF.read_text())
    nominal = kinfw.load_robot(d / "nominal.urdf")
    sim = kinfw.simulate(nominal, noise_m=0.0, noise_rad=0.0, error_mm=5.0, error_deg=1.0, seed=4)
    kinfw.write_measurements(d / "data.json", sim.data)
    data = kinfw.read_measurements(d / "data.json")
    # the true head is 5 mm / 1 deg off per axis: the plausibility guard's bound for it
    bound = ChangeBound.for_known_error(5e-3, math.radians(1.0))
    return d, nominal, sim, data, kinfw.calibrate(nominal, data, change_bound=bound)


# -- the door itself ------------------------------------------------------------------
def test_the_front_door_is_the_verbs_each_an_alias_of_its_home():
    homes = dict(line.split() for line in HOMES.strip().splitlines())
    assert sorted(kinfw.__all__) == sorted(homes)
    for name, home in homes.items():
        module, home_name = home.rsplit(".", 1)
        assert getattr(kinfw, name) is getattr(importlib.import_module(module), home_name), name
    assert not hasattr(kinfw, "Robot") and not hasattr(kinfw, "DatasetError")


def test_import_kinfw_loads_no_heavy_module_and_the_cli_no_numpy():
    heavy = ("numpy", "pinocchio", "casadi", "meshcat", "matplotlib")
    code = "import sys, {0}; print([m for m in {1!r} if m in sys.modules])"
    for module in ("kinfw", "kinfw.cli"):
        out = subprocess.run(
            [sys.executable, "-c", code.format(module, heavy)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        assert out.strip() == "[]", module


# -- calibrate, write, evaluate, simulate ---------------------------------------------------
@pytest.mark.slow
def test_calibrate_noise_free_simulated_data_recovers_the_truth_through_the_written_urdf(
    experiment,
):
    d, nominal, sim, _, result = experiment
    result.write(d / "cal.urdf")
    truth = pin.buildModelFromXML(sim.truth_xml)
    written = pin.buildModelFromXML((d / "cal.urdf").read_text())
    nominal_model = pin.buildModelFromXML(nominal.urdf_xml)
    lower, upper = nominal.joint_limits(sim.joint_names)
    rng = np.random.default_rng(0)
    worst, nominal_off = 0.0, 0.0
    for _ in range(50):
        q = dict(zip(sim.joint_names, rng.uniform(lower, upper), strict=True))
        for frame in PLATES:
            true_pose = _fk(truth, q, frame)
            error = pin.log6(true_pose.inverse() * _fk(written, q, frame)).vector
            worst = max(worst, float(np.linalg.norm(error)))
            nominal_off = max(
                nominal_off,
                float(
                    np.linalg.norm(true_pose.translation - _fk(nominal_model, q, frame).translation)
                ),
            )
    assert worst < 1e-9  # m and rad
    assert nominal_off > 5e-3  # the nominal was millimetres off
    # the default of kinfw calibrate: enough rows per parameter for "full", no prior
    assert result.model.parameters == ("full",) and result.model.prior is None
    assert result.choice is not None and result.choice.candidates == ()


def test_write_writes_the_urdf_and_sidecar_and_refuses_to_overwrite_an_input(experiment):
    d, _, _, _, result = experiment
    out = d / "written"
    out.mkdir()
    before = {p: p.read_bytes() for p in (d / "data.json", d / "nominal.urdf")}
    with pytest.raises(OutputPathError, match=r"same file as data .*data\.json"):
        result.write(d / "data.json")
    with pytest.raises(OutputPathError, match=r"same file as nominal URDF .*nominal\.urdf"):
        result.write(d / "nominal.urdf")
    assert {p: p.read_bytes() for p in before} == before
    assert not (d / "data.kinfw.json").exists() and not (d / "nominal.kinfw.json").exists()
    report = result.write(out / "cal.urdf")
    assert sorted(p.name for p in out.iterdir()) == ["cal.kinfw.json", "cal.urdf"]  # no temp
    assert (out / "cal.urdf").read_text() == result.urdf_xml
    assert report.sidecar == str(out / "cal.kinfw.json") and result.report.sidecar is None
    side = read_sidecar(out / "cal.kinfw.json")
    assert side.calibrated_urdf == "cal.urdf"
    assert side.nominal_urdf == str(d / "nominal.urdf")
    assert side.data.sha256 == report.data.sha256 is None  # no data_path given


def test_a_path_where_a_robot_or_measurements_is_expected_is_a_type_error(experiment):
    d, nominal, _, data, _ = experiment
    with pytest.raises(TypeError, match=r"nominal: expected a Robot.*kinfw.load_robot"):
        kinfw.calibrate(str(d / "nominal.urdf"), data)
    with pytest.raises(TypeError, match=r"data: expected Measurements.*kinfw.read_measurements"):
        kinfw.calibrate(nominal, d / "data.json")
    with pytest.raises(TypeError, match=r"held_out: expected Measurements"):
        kinfw.calibrate(nominal, data, held_out=d / "data.json")
    with pytest.raises(TypeError, match=r"nominal: expected a Robot"):
        kinfw.simulate(d / "nominal.urdf")
    with pytest.raises(TypeError, match=r"robot: expected a Robot"):
        kinfw.plan(str(d / "nominal.urdf"), Setup(frames=PLATES))


def test_evaluate_of_the_true_robot_on_its_noise_free_data_is_zero(experiment):
    _, nominal, sim, data, _ = experiment
    truth = kinfw.evaluate(sim.truth, data)
    assert {g.frame for g in truth.groups} == set(PLATES)
    for g in truth.groups:
        assert [e.metric.name for e in g.errors] == ["position", "rotation"]
        assert all(e.values.max() < 1e-12 for e in g.errors)  # m, rad
    off = kinfw.evaluate(nominal, data)
    assert min(g.of("position").values.max() for g in off.groups) > 1e-3  # m: errors seen


def test_simulate_measures_the_true_robot_by_pinocchio(experiment):
    _, _, sim, data, _ = experiment
    truth = pin.buildModelFromXML(sim.truth_xml)
    assert data.n_samples == 1 + 9 * len(sim.joint_names)  # one joint at a time, 9 each
    for g in data.poses:
        for k, sample in enumerate(g.sample):
            q = dict(zip(data.joint_names, data.qs[sample], strict=True))
            expected = _fk(truth, q, g.frame).homogeneous
            np.testing.assert_allclose(g.meas_T_frame[k], expected, rtol=0, atol=1e-12)


# -- the command line is the same verbs ----------------------------------------------------
def test_the_cli_calibrate_writes_the_urdf_of_the_verb(experiment, capsys):
    d, *_, result = experiment
    argv = ["calibrate", d / "data.json", "--urdf", d / "nominal.urdf", "--out", d / "cli.urdf"]
    bound = ChangeBound.for_known_error(5e-3, math.radians(1.0))  # as the verb's
    argv += ["--max-change-mm", 1e3 * bound.max_m, "--max-change-deg", math.degrees(bound.max_rad)]
    assert main([str(a) for a in argv]) == 0
    capsys.readouterr()
    assert (d / "cli.urdf").read_text() == result.urdf_xml


def test_the_cli_simulate_writes_the_data_and_truth_of_the_verb(experiment, tmp_path, capsys):
    d, _, sim, _, _ = experiment
    argv = ["simulate", "--urdf", d / "nominal.urdf", "--out", tmp_path / "cli.json"]
    argv += ["--truth-out", tmp_path / "t.urdf", "--noise-mm", "0", "--noise-deg", "0"]
    argv += ["--error-mm", "5", "--error-deg", "1", "--seed", "4"]
    assert main([str(a) for a in argv]) == 0
    capsys.readouterr()
    assert (tmp_path / "t.urdf").read_text() == sim.truth_xml
    assert (tmp_path / "cli.json").read_text() == (d / "data.json").read_text()


@pytest.mark.slow
def test_the_cli_plan_is_the_verb_s_plan(tmp_path, capsys):
    head = kinfw.load_robot(HEAD_URDF)
    argv = ["plan", "--urdf", HEAD_URDF, "--n", "6", "--candidates", "60", "--test", "30"]
    argv += ["--seed", "2", "--out", tmp_path / "plan.json", "--json"]
    assert main([str(a) for a in argv]) == 0
    summary = json.loads(capsys.readouterr().out)
    setup = Setup(frames=PLATES, noise_m=0.5 * 1e-3, noise_rad=math.radians(0.5))
    plan = kinfw.plan(head, setup, 6, candidates=60, n_test=30, seed=2)
    names, qs = read_plan(tmp_path / "plan.json")
    assert names == plan.joint_names
    np.testing.assert_array_equal(qs, plan.qs)
    assert summary["position_rms_mm"] == 1e3 * plan.rms("position")
    # the plan: 6 distinct configurations inside the joint limits, better than random
    lower, upper = head.joint_limits(plan.joint_names)
    assert plan.qs.shape == (6, len(names)) and len(np.unique(plan.qs, axis=0)) == 6
    assert np.all((plan.qs >= lower) & (plan.qs <= upper))
    assert plan.objective.name == "position" and plan.rms("position") < plan.random_rms


@pytest.mark.slow
def test_crossvalidate_of_noise_free_data_predicts_held_out_samples_exactly(experiment, capsys):
    d, _, _, data, _ = experiment
    bound = ChangeBound.for_known_error(5e-3, math.radians(1.0))  # the true head's error
    cv = kinfw.crossvalidate(
        kinfw.load_robot(d / "nominal.urdf"), data, k=3, seed=1, change_bound=bound
    )
    assert cv.sets == ("none", "frames", "full", "auto")  # auto: calibrate's default
    for fitted in ("full", "auto"):
        assert max(s.of("position") for s in cv.scores if s.parameters == fitted) < 1e-6  # mm
    assert min(s.of("position") for s in cv.scores if s.parameters == "none") > 1.0
    argv = ["crossval", d / "data.json", "--urdf", d / "nominal.urdf", "--k", "3"]
    argv += ["--max-change-mm", 1e3 * bound.max_m, "--max-change-deg", math.degrees(bound.max_rad)]
    assert main([str(a) for a in [*argv, "--seed", "1", "--jobs", "2", "--json"]]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(cv.to_dict()))


def test_show_writes_a_self_contained_scene_of_the_calibration(experiment):
    d, nominal, _, data, result = experiment
    result.write(d / "shown.urdf")
    path = kinfw.show(nominal, d / "shown.urdf", data, sample=3, html=d / "scene.html")
    assert path == d / "scene.html"
    html = path.read_text()
    assert external_urls(html) == [] and len(html) > 100_000


def test_fixate_puts_the_point_on_both_optical_axes_by_pinocchio():
    ideal = kinfw.load_robot(IDEAL_HEAD)
    for q_true, point in ideal_fixation_points(ideal, 3, seed=5):
        fix = kinfw.fixate(ideal, point, q_start=q_true + 0.05)
        assert fix.fixated and np.all(fk_errors_rad(ideal, fix.q, point) < 1e-9)


def test_reach_puts_the_frame_at_a_pose_the_robot_had_by_pinocchio():
    head = kinfw.load_robot(HEAD_URDF)
    model = pin.buildModelFromXML(head.urdf_xml)
    lower, upper = head.joint_limits(head.joint_names)
    q_true = dict(zip(head.joint_names, 0.5 * (lower + upper) + 0.2 * (upper - lower), strict=True))
    target = _fk(model, q_true, "right_plate").homogeneous
    result = kinfw.reach(head, "right_plate", target)
    reached = _fk(model, dict(zip(result.joint_names, result.q, strict=True)), "right_plate")
    assert result.reached
    assert np.linalg.norm(pin.log6(pin.SE3(target).inverse() * reached).vector) < 1e-6


def _command_functions() -> dict[str, ast.FunctionDef]:
    out = {}
    for path in sorted((REPO / "kinfw" / "cli").glob("_*.py")):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("cmd_"):
                out[node.name] = node
    return out


def test_every_command_calls_its_library_verb_and_is_short():
    """No workflow only in the command line: each command calls its verb (the tests
    above check they give the same files) and is a thin layer (at most 80 lines)."""
    verbs = {
        "cmd_calibrate": "calibrate_and_report",
        "cmd_crossval": "crossvalidate",
        "cmd_simulate": "simulate_measurements",
        "cmd_plan": "plan_measurement",
        "cmd_verify": "evaluate_model",
        "cmd_view": "show",
        "cmd_gaze": "fixate",
        "cmd_reach": "reach",
        "cmd_demo": "run_demo",
        "cmd_crosscheck": "crosscheck_cpc",
    }
    commands = _command_functions()
    for command, verb in verbs.items():
        called = {
            n.func.id
            for n in ast.walk(commands[command])
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
        }
        assert verb in called, command
    long = {c: f.end_lineno - f.lineno + 1 for c, f in commands.items()}
    assert {c: n for c, n in long.items() if n > 80} == {}
