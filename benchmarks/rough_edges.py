"""The rough edges of issues 25 and 35, re-run as a shell user meets them: one row per case
with the command, its exit code, the first line it prints on stderr and what else was
checked (files left, the warning seen, numbers read back from what was written).

Each case runs ``python -m kinfw.cli`` in a fresh process (or a ``python -c`` one-liner)
in a temporary folder, on data the script makes: ``kinfw simulate`` of the built-in IIS
head (poses, the plates alone), of example-robot-data's UR10 (mocap markers, calibrated
with the UR5's URDF) and of the 6R arm of ``tests/robots.py`` with a flange camera (a
ChArUco board rendered with square 0.034 m, ``kinfw detect``-ed with 0.043); TALOS's two
arms touching a table measured in the stance foot (``tests/contacts.py``, the setup of
``tests/identification/test_foot_plane.py``); hand-eye pose pairs simulated with
Pinocchio (``tests/kinfw/cli/test_cli_handeye.py``); the TIAGo Vicon CSV of
``tests/data/tiago_figaroh`` re-saved with a byte-order mark, ``;`` separators and decimal
commas, or in mm.

Issue 35's rows are labelled with its item (``35.6`` ...; ``35 view`` for the view of a URDF
whose meshes are missing). Three of them (35.2 contacts moving the robot, 35.3 the wrong
board size, 35.4 another robot's URDF) belong to the plausibility guard: without it they
exit 0, and the "also" column gives the moves the written URDF holds. The "also" column
is computed from what the command printed and wrote, never typed.

The tests that hold these behaviours: issue 25 in ``tests/kinfw/cli/test_rough_edges.py``,
``tests/kinfw/measurements/test_figaroh_csv.py``, ``tests/kinfw/model/test_xacro.py`` and
``tests/kinfw/cli/test_package_dir.py``; issue 35 in ``tests/kinfw/model/test_xacro.py``
(35.1; 35.10 empty stdin), ``tests/identification/test_foot_plane.py`` (35.2: what the
contacts do not determine stays at the nominal),
``tests/identification/checks/test_fit_checks.py`` (35.5),
``tests/kinfw/cli/test_cli_handeye_checks.py`` and
``tests/identification/checks/test_pose_pair_checks.py`` (35.6),
``tests/kinfw/measurements/test_duplicates.py`` and
``tests/verification/reporting/test_duplicates.py`` (35.7),
``tests/kinfw/cli/test_rough_edges.py`` (35.8, 35.9; 35.10 a number of 1e300),
``tests/identification/checks/test_units.py`` (35.10 the unit blamed on a joint),
``tests/kinfw/cli/test_detect_cli.py`` (35.10 the missing image, the ``;`` joints file),
``tests/kinfw/measurements/test_pose_pairs.py`` (35.10 the ``;`` pose pairs) and
``tests/verification/evaluation/test_model_choice.py`` (35.10 the candidates' warnings).

Run: ``python benchmarks/rough_edges.py`` (about three minutes on two busy cores; needs
example-robot-data, a test dependency, for the TIAGo, UR, TALOS and Panda URDFs).
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from kinfw import builtin_head_urdf
from kinfw.geometry import inverse_transform, rotation_angle
from kinfw.measurements import PosePairs, pose_pairs_text, write_measurements
from kinfw.model import load_robot
from kinfw.simulation import perturb_robot
from tests.contacts import two_arm_contacts
from tests.erd import robots_dir, urdf_path
from tests.identification.test_foot_plane import FOOT, JOINTS, OFFSETS, STANCE, _table_in_foot
from tests.kinfw.cli.test_cli_handeye import X_TRUE, _pairs
from tests.kinfw.cli.test_cli_handeye_checks import _scalar_first as _scalar_first_csv
from tests.kinfw.cli.test_rough_edges import _scalar_first
from tests.kinfw.observations.test_cameras_anywhere import setup_urdf

KINFW = [sys.executable, "-m", "kinfw.cli"]
HEAD = builtin_head_urdf()
TIAGO = urdf_path("tiago_description/robots/tiago_no_hand.urdf")
UR5 = urdf_path("ur_description/urdf/ur5_robot.urdf")
UR10 = urdf_path("ur_description/urdf/ur10_robot.urdf")
TALOS = urdf_path("talos_data/robots/talos_reduced.urdf")
PANDA = urdf_path("panda_description/urdf/panda.urdf")
VICON = ROOT / "tests/data/tiago_figaroh/vicon_calibration_gripper3_base1.csv"
#: the ChArUco board rendered (square 0.034 m) and the one typed to detect it (0.043 m)
BOARD, WRONG_BOARD = "charuco:7x5:0.034:0.025", "charuco:7x5:0.043:0.025"

#: what a row's "also" column is computed from: (exit code, stdout, stderr)
Also = Callable[[int, str, str], str]


@dataclass(frozen=True)
class Row:
    """One case: what the user typed (shell words), the exit code, stderr's first line,
    and what else was checked (files left, lines printed, numbers read back)."""

    case: str
    command: str
    code: int
    first_line: str
    note: str = ""


def _run(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of ``argv`` run in ``cwd`` with an empty stdin."""
    proc = subprocess.run(argv, cwd=cwd, capture_output=True, stdin=subprocess.DEVNULL)
    return proc.returncode, proc.stdout.decode().strip(), proc.stderr.decode().strip()


def _argv(args: list) -> list[str]:
    """Command words from ``args``: a string is split at white space (several words), a
    path is one word."""
    return [w for a in args for w in ([str(a)] if isinstance(a, Path) else a.split())]


def _kinfw(work: Path, args: list) -> tuple[int, str, str]:
    """``kinfw -q ARGS`` (:func:`_argv`'s words) in ``work``."""
    return _run([*KINFW, "-q", *_argv(args)], work)


def _setup(work: Path, args: list) -> str:
    """``kinfw -q ARGS`` that makes a case's data: it must succeed; its stdout."""
    code, out, err = _kinfw(work, args)
    if code:
        raise RuntimeError(f"kinfw {' '.join(_argv(args))}: exit {code}\n{err}")
    return out


def _first(err: str) -> str:
    """The error line if there is one, else the first line, shortened."""
    lines = err.splitlines() or ["(nothing)"]
    line = next((x for x in lines if ": error: " in x), lines[0])
    return line if len(line) <= 160 else line[:157] + "..."


def _local(text: str, work: Path) -> str:
    """``text`` with the temporary folder, the head's URDF and example-robot-data's robots
    folder left out of its paths, as a user in the folder reads them."""
    text = text.replace(f"{work}/", "").replace(str(HEAD), "HEAD.urdf")
    return text.replace(f"{robots_dir()}/", "")


def _shell(argv: list[str], work: Path) -> str:
    """``argv`` (``python -m kinfw.cli ...``) as a user types it in ``work``."""
    return _local(shlex.join(["kinfw", *argv[len(KINFW) :]]), work)


def _written(work: Path, *names: str) -> str:
    """Which of ``names`` (files or folders in ``work``) exist."""
    there = [n for n in names if (work / n).exists()]
    return f"written: {', '.join(there)}" if there else "nothing written"


def _simulate(work: Path, stage2: int, name: str, *extra: str) -> Path:
    out = work / f"{name}.json"
    argv = ["simulate", "--out", out, "--truth-out", work / f"{name}_true.urdf", *extra]
    _setup(work, argv + (["--stage", "both", "--stage2-samples", str(stage2)] if stage2 else []))
    return out


def _ctrl_c(work: Path, data: Path) -> Row:
    argv = [*KINFW, *_argv(["calibrate", data.name, "--urdf", HEAD, "--out c.urdf"])]
    proc = subprocess.Popen(argv, cwd=work, stderr=subprocess.PIPE, text=True)
    for _ in range(3):  # piped progress: plain lines once the work has begun
        proc.stderr.readline()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    left = sorted(p.name for p in work.iterdir() if p.name.startswith("c."))
    last = err.strip().splitlines()[-1]
    note = f"last line only; traceback: {'Traceback' in err}; files left: {left or 'none'}"
    command = _shell(argv, work) + "  # then Ctrl-C"
    return Row("Ctrl-C during a long calibrate", command, proc.returncode, last, note)


def _closed_pipe(work: Path) -> Row:
    reach = ["-q reach", HEAD, "--frame left_plate --point 0.3 0.1 0.4 --json"]
    argv = [*KINFW, *_argv(reach)]
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader (`head`) has left before the output
    proc = subprocess.run(argv, cwd=work, stdout=write_end, stderr=subprocess.PIPE)
    os.close(write_end)
    err = proc.stderr.decode().strip()
    return Row("a reader that leaves", _shell(argv, work) + " | head", proc.returncode, _first(err))


def _kinfw_row(
    case: str, work: Path, args: list, also: Also | None = None, shown: str | None = None
) -> Row:
    """``kinfw -q ARGS`` (:func:`_argv`'s words); the "also" column from ``also``
    (default: on success, what it printed first on stdout); ``shown`` replaces the
    command's words (a glob for files)."""
    argv = [*KINFW, "-q", *_argv(args)]
    code, out, err = _run(argv, work)
    if also is not None:
        note = also(code, out, err)
    else:
        note = f"stdout: {_first(out)}" if code == 0 else ""
    first = _local(_first(err), work)
    return Row(case, shown or _shell(argv, work), code, first, _local(note, work))


def _python_row(case: str, work: Path, code_text: str) -> Row:
    """``python -c CODE``: the exception's line."""
    code, _, err = _run([sys.executable, "-c", code_text], work)
    return Row(case, f'python -c "{code_text}"', code, _first(err.splitlines()[-1]))


def _semicolons(text: str) -> str:
    """A comma-separated table as a European spreadsheet saves it: ``;`` between fields,
    decimal commas in the numbers (names such as ``img_000.png`` kept)."""

    def field(v: str) -> str:
        try:
            float(v)
        except ValueError:
            return v
        return v.replace(".", ",")

    return "\n".join(";".join(map(field, line.split(","))) for line in text.splitlines()) + "\n"


def _spreadsheet_csv(work: Path) -> Path:
    """The Vicon CSV as a European spreadsheet saves it: BOM, ``;``, decimal commas."""
    path = work / "vicon_excel.csv"
    path.write_text(_semicolons(VICON.read_text()), encoding="utf-8-sig")
    return path


def _arm(work: Path, name: str, head: str, origin: str, tool: str) -> Path:
    """A one-joint arm: ``head`` opens the robot tag, ``origin`` is the joint's xyz,
    ``tool`` the tool link's body."""
    path = work / name
    path.write_text(
        textwrap.dedent(
            f"""\
            {head}
              <link name="base_link"/><link name="tool0">{tool}</link>
              <joint name="j1" type="revolute"><parent link="base_link"/><child link="tool0"/>
                <origin xyz="{origin}"/><axis xyz="0 0 1"/>
                <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
            </robot>
            """
        )
    )
    return path


def _edited(path: Path, to: Path, edit: Callable[[dict], object]) -> Path:
    """The measurement file ``path`` with ``edit`` applied to its parsed JSON, at ``to``."""
    doc = json.loads(path.read_text())
    edit(doc)
    to.write_text(json.dumps(doc))
    return to


def _issue_25(work: Path, poses: Path) -> list[Row]:
    """Issue 25's cases, in its order."""
    wrong = _scalar_first(poses, work / "wxyz.json")
    xacro = _arm(
        work,
        "arm.urdf.xacro",
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" name="arm">'
        '<xacro:arg name="reach" default="0.5"/>',
        "$(arg reach) 0 0.1",
        "",
    )
    mesh = '<collision><geometry><mesh filename="package://arm_meshes/tool.stl"/></geometry></collision>'
    meshless = _arm(work, "arm.urdf", '<robot name="arm">', "0.5 0 0.1", mesh)
    calibrate = ["calibrate", poses.name, "--urdf", HEAD]
    vicon = _spreadsheet_csv(work).name
    return [
        _ctrl_c(work, _simulate(work, 200, "long")),
        _closed_pipe(work),
        _kinfw_row(
            "--holdout = the training file",
            work,
            [*calibrate, "--out", "h.urdf", "--holdout", poses.name],
        ),
        _kinfw_row(
            "quaternions stored (w, x, y, z)",
            work,
            ["calibrate", wrong.name, "--urdf", HEAD, "--out", "q.urdf"],
        ),
        _python_row(
            "a path where data is expected",
            work,
            "from kinfw import builtin_head_urdf; from kinfw.model import load_robot; "
            "from kinfw.identification import identify; "
            "identify(load_robot(builtin_head_urdf()), 'file.json')",
        ),
        _python_row(
            "write_html into a missing folder",
            work,
            "from kinfw.files import write_text_atomic; "
            "write_text_atomic('missing/scene.html', '<html/>')",
        ),
        _kinfw_row(
            "a xacro file, with an argument",
            work,
            ["reach", xacro.name, "--xacro-arg reach:=0.7 --frame tool0 --point 0.7 0 0.1"],
        ),
        _kinfw_row(
            "CSV with BOM, ';' and decimal commas",
            work,
            ["import-csv", vicon, "--urdf", TIAGO, "--frame arm_7_link --out v.json"],
        ),
        _kinfw_row(
            "plan --collisions, meshes missing",
            work,
            ["plan --urdf", meshless.name, "--frames tool0 --collisions --out p.json"],
        ),
    ]


def _moves(nominal: str | Path, written: Path) -> list[tuple[float, float, str]]:
    """Each joint origin's move (mm) and turn (deg) from ``nominal`` to ``written``,
    largest move first."""
    a, b = load_robot(nominal), load_robot(written)
    out = []
    for joint in a.joints:
        a_T_b = inverse_transform(joint.parent_T_child) @ b.joint(joint.name).parent_T_child
        turn = float(np.degrees(rotation_angle(a_T_b[:3, :3])))
        out.append((1e3 * float(np.linalg.norm(a_T_b[:3, 3])), turn, joint.name))
    return sorted(out, reverse=True)


def _largest_moves(nominal: str | Path, written: Path, k: int = 3) -> str:
    """The written URDF's ``k`` largest joint origin moves, or that none was written."""
    if not written.exists():
        return f"no {written.name} written"
    moves = _moves(nominal, written)[:k]
    return "joints moved " + ", ".join(f"{name} {mm:.0f} mm" for mm, _, name in moves)


def _item_1(work: Path) -> Row:
    """example-robot-data's panda.urdf, which declares xmlns:xacro, without xacro."""
    args = _argv(["-q simulate --urdf", PANDA, "--markers panda_link8 --mocap-samples 5"])
    args += ["--out", "panda.json", "--truth-out", "panda_true.urdf"]
    code_text = (
        "import runpy, sys; sys.modules['xacro'] = None; "
        f"sys.argv = ['kinfw', *{args!r}]; runpy.run_module('kinfw.cli', run_name='__main__')"
    )
    code, out, err = _run([sys.executable, "-c", code_text], work)
    declares = "xmlns:xacro" in PANDA.read_text()
    note = f"declares xmlns:xacro: {declares}; xacro hidden; stdout: {_first(out)}"
    command = _shell([*KINFW, *args], work) + "  # without the ros extra (xacro)"
    return Row("35.1 a URDF that only declares xmlns:xacro", command, code, _first(err), note)


def _stance_move(nominal: Path, written: Path) -> str:
    """How far the written URDF puts the root from the stance foot (at the stance), vs
    the nominal's: mm and deg."""
    if not written.exists():
        return f"no {written.name} written"
    q = np.array([[STANCE.get(j, 0.0) for j in JOINTS]])
    root_T_foot = [load_robot(u).frame_poses(q, FOOT, JOINTS)[0] for u in (nominal, written)]
    moved = root_T_foot[0] @ inverse_transform(root_T_foot[1])
    mm = 1e3 * float(np.linalg.norm(moved[:3, 3]))
    deg = float(np.degrees(rotation_angle(moved[:3, :3])))
    return f"base_link moved {mm:.3g} mm, {deg:.3g} deg from {FOOT}"


def _item_2(work: Path) -> Row:
    """TALOS standing on its left foot, both hands touching a table measured in the
    foot (30 contacts per arm), calibrated with the default options."""
    nominal = load_robot(TALOS)
    rng = np.random.default_rng(1)
    truth = load_robot(perturb_robot(nominal, rng, joints=JOINTS))
    data = two_arm_contacts(
        truth,
        _table_in_foot(truth),
        OFFSETS,
        30,
        rng,
        measured_in=FOOT,
        joint_names=JOINTS,
        fixed=STANCE,
    )
    write_measurements(work / "talos.json", data)
    out = work / "talos_cal.urdf"
    return _kinfw_row(
        "35.2 contacts in the stance foot (guard)",
        work,
        ["calibrate", "talos.json", "--urdf", TALOS, "--out", out.name],
        lambda *_: f"{_stance_move(TALOS, out)}; {_largest_moves(TALOS, out, 2)}",
    )


def _render_board(work: Path) -> tuple[Path, Path]:
    """The 6R arm with a flange camera (``hand_camera``) imaging a ChArUco board of
    square 0.034 m (12 images), detected with square 0.043: the URDF, the detections."""
    urdf = work / "eye_in_hand.urdf"
    urdf.write_text(setup_urdf("eye_in_hand"))
    _simulate(
        work,
        0,
        "board",
        "--urdf",
        urdf.name,
        f"--pixels --board {BOARD} --images img --cameras hand_camera --stage 2",
        "--stage2-samples 12 --seed 3",
    )
    cam = work / "img" / "hand_camera"
    _setup(work, [*_detect_args(cam, cam / "joints.csv"), "--out", "board_det.json"])
    return urdf, work / "board_det.json"


def _detect_args(cam: Path, joints: Path, *extra: str) -> list:
    """``kinfw detect`` of every PNG in ``cam`` (and ``extra`` images) with the wrong
    board size."""
    images = [*sorted(cam.glob("*.png")), *extra]
    camera = ["--camera", cam / "camera.json", "--frame hand_camera"]
    return ["detect", *images, "--board", WRONG_BOARD, "--joints", joints, *camera]


def _detect_shown(work: Path, cam: Path, joints: Path, out: str, *extra: str) -> str:
    """How a user types :func:`_detect_args` writing ``out`` (a glob for the images)."""
    words = ["kinfw", "-q", "detect", f"{cam.relative_to(work)}/*.png", *extra, "--board"]
    words += [WRONG_BOARD, "--joints", str(joints.relative_to(work))]
    words += ["--camera", str((cam / "camera.json").relative_to(work)), "--frame", "hand_camera"]
    words += ["--out", out]
    return shlex.join(words).replace("'", "")


def _item_3(work: Path, urdf: Path, detections: Path) -> Row:
    """The flange camera's ChArUco images, detected with the wrong square, calibrated."""
    out = work / "board_cal.urdf"
    args = ["calibrate", detections.name, "--urdf", urdf.name, "--out", out.name]
    cam = work / "img" / "hand_camera"
    detect = _detect_shown(work, cam, cam / "joints.csv", detections.name)
    return _kinfw_row(
        "35.3 board detected with square 0.043, rendered 0.034 (guard)",
        work,
        args,
        lambda *_: _largest_moves(urdf, out),
        f"{detect} && {_shell([*KINFW, '-q', *args], work)}",
    )


def _item_4(work: Path) -> Row:
    """A UR10's mocap markers (30 samples) calibrated with the UR5's URDF."""
    _simulate(work, 0, "ur10", "--urdf", UR10, "--markers", "tool0", "--mocap-samples", "30")
    out = work / "ur5_cal.urdf"
    return _kinfw_row(
        "35.4 a UR10's data, the UR5's URDF (guard)",
        work,
        ["calibrate", "ur10.json", "--urdf", UR5, "--out", out.name],
        lambda *_: _largest_moves(UR5, out),
    )


def _item_5(work: Path, poses: Path) -> Row:
    """``--sigma-mm 500`` typed for 0.5 on the head's 0.5 mm poses."""
    return _kinfw_row(
        "35.5 --sigma-mm 500 typed for 0.5",
        work,
        ["calibrate", poses.name, "--urdf", HEAD, "--sigma-mm 500 --sigma-deg 0.5 --out s.urdf"],
        lambda _c, _o, err: (
            f"warns of the stated noise: {'times the stated noise' in err}; "
            + _written(work, "s.urdf")
        ),
    )


def _pose_pairs(work: Path) -> dict[str, Path]:
    """Hand-eye pose pairs of a flange camera (12 pairs, 0.5 mm noise), as CSV files:
    as recorded, quaternions w, x, y, z under qx..qw, positions in mm, every pair twice,
    and the ``;`` / decimal-comma spreadsheet."""
    pairs = _pairs(0, 12, noise=5e-4)
    twice = PosePairs(
        *(np.concatenate([a, a]) for a in (pairs.base_T_hands, pairs.sensor_T_targets)), "x"
    )
    text = pose_pairs_text(pairs, "csv")
    files = {
        "pairs.csv": text,
        "wxyz.csv": _scalar_first_csv(text, ("hand", "sensor")),
        "pairs_mm.csv": pose_pairs_text(pairs.scaled(1e3), "csv"),
        "pairs_twice.csv": pose_pairs_text(twice, "csv"),
        "pairs_excel.csv": _semicolons(text),
    }
    for name, content in files.items():
        (work / name).write_text(content)
    return {name: work / name for name in files}


def _handeye_json(work: Path, *args) -> dict:
    """``kinfw handeye ARGS --json``'s document (it must succeed)."""
    return json.loads(_setup(work, ["handeye", *args, "--json"]))


def _camera_from_hand_mm(doc: dict) -> float:
    """How far ``kinfw handeye --json``'s camera is from the hand, mm."""
    return 1e3 * float(np.linalg.norm(np.array(doc["calibration"]["hand_T_camera"])[:3, 3]))


def _item_6(work: Path, files: dict[str, Path]) -> list[Row]:
    """handeye on quaternions stored scalar first, mm read as m, m read as mm."""
    truth_mm = 1e3 * float(np.linalg.norm(X_TRUE[:3, 3]))
    mm = _camera_from_hand_mm(_handeye_json(work, files["pairs_mm.csv"].name, "--unit", "mm"))
    unit_mm = f"with --unit mm: the camera {mm:.1f} mm from the hand (truth {truth_mm:.1f})"
    cases = (
        ("35.6 handeye: w, x, y, z under qx..qw", "wxyz.csv", [], ""),
        ("35.6 handeye: positions in mm read as m", "pairs_mm.csv", [], f"; {unit_mm}"),
        ("35.6 handeye: --unit mm on metre data", "pairs.csv", ["--unit", "mm"], ""),
    )
    return [
        _kinfw_row(
            case,
            work,
            ["handeye", name, *extra, "--ros-out", "ros"],
            lambda _c, _o, _e, more=more: _written(work, "ros") + more,
        )
        for case, name, extra, more in cases
    ]


def _sigma_ratios(kept: np.ndarray, once: np.ndarray, twice: np.ndarray) -> str:
    """The median ratios of the sigmas of every sample twice (default, kept) to once."""
    return (
        f"sigma twice/once: {np.median(twice / once):.3f}, "
        f"with --keep-duplicates {np.median(kept / once):.3f}"
    )


def _free_sigmas(report: str) -> np.ndarray:
    """The free parameters' sigmas in ``kinfw calibrate --json``'s report."""
    parameters = json.loads(report)["refine"]["parameters"]
    return np.array([p["std"] for p in parameters if not p["fixed"]])


def _calibrate_sigmas(work: Path, data: str, *extra: str) -> np.ndarray:
    """The free parameters' sigmas of ``kinfw calibrate DATA --params full``."""
    argv = ["calibrate", data, "--urdf", HEAD, "--params", "full", "--json", *extra]
    return _free_sigmas(_setup(work, [*argv, "--out", f"sig_{len(extra)}.urdf"]))


def _item_7(work: Path, poses: Path, files: dict[str, Path]) -> list[Row]:
    """Every sample (head poses) and every pose pair recorded twice."""
    twice = _edited(poses, work / "twice.json", lambda d: d.update(samples=d["samples"] * 2))
    once = _calibrate_sigmas(work, poses.name)
    kept = _calibrate_sigmas(work, twice.name, "--keep-duplicates")

    def calibrate_note(_code: int, out: str, err: str) -> str:
        motion = err.count("residuals follow the robot's motion")
        ratios = _sigma_ratios(kept, once, _free_sigmas(out))
        return f"{ratios}; 'follow the robot's motion' warnings: {motion}"

    def sigmas(doc: dict) -> np.ndarray:
        return np.array(doc["sigma_translation_mm"] + doc["sigma_rotation_deg"])

    pairs_once = sigmas(_handeye_json(work, files["pairs.csv"].name))
    pairs_kept = sigmas(_handeye_json(work, files["pairs_twice.csv"].name, "--keep-duplicates"))
    return [
        _kinfw_row(
            "35.7 every sample twice",
            work,
            ["calibrate", twice.name, "--urdf", HEAD, "--params full --json --out twice.urdf"],
            calibrate_note,
        ),
        _kinfw_row(
            "35.7 handeye: every pose pair twice",
            work,
            ["handeye", files["pairs_twice.csv"].name, "--json"],
            lambda _c, out, _e: _sigma_ratios(pairs_kept, pairs_once, sigmas(json.loads(out))),
        ),
    ]


def _item_8(work: Path, poses: Path, plates: Path) -> Row:
    """verify of the plates' calibration with the sidecar of the poses' calibration."""
    for name, data in (("mine", plates), ("foreign", poses)):
        _setup(
            work,
            ["calibrate", data.name, "--urdf", HEAD, "--params", "full", "--out", f"{name}.urdf"],
        )

    def note(_code: int, out: str, err: str) -> str:
        used = "using the calibration sidecar" in out
        sha = sum("sha256" in line for line in err.splitlines()[1:])
        return f"says 'using the calibration sidecar': {used}; detail lines with a SHA-256: {sha}"

    return _kinfw_row(
        "35.8 verify --sidecar of another calibration",
        work,
        ["verify", "mine.urdf", poses.name, "--sidecar", "foreign.kinfw.json"],
        note,
    )


def _item_9(work: Path) -> Row:
    return _kinfw_row(
        "35.9 plan --plot out.xyz",
        work,
        ["plan", "--urdf", HEAD, "--n", "5", "--out", "plan.json", "--plot", "out.xyz"],
        lambda *_: _written(work, "plan.json", "out.xyz"),
    )


def _item_10_inputs(work: Path, poses: Path) -> list[Row]:
    """Messages about inputs: a coordinate of 1e300, a mm-as-m import blamed on a joint
    too, empty stdin for ``--urdf -``."""
    huge = _edited(poses, work / "huge.json", lambda d: d["samples"][3]["q"].__setitem__(0, 1e300))
    header, *lines = VICON.read_text().split()
    mm = [
        ",".join(repr(float(v) * (1e3 if k < 3 else 1.0)) for k, v in enumerate(line.split(",")))
        for line in lines
    ]
    (work / "vicon_mm.csv").write_text("\n".join([header, *mm]) + "\n")
    _setup(
        work, ["import-csv vicon_mm.csv --urdf", TIAGO, "--frame arm_7_link --out vicon_mm.json"]
    )
    joints = load_robot(TIAGO).joint_names
    stdin = ["calibrate", poses.name, "--urdf", "-", "--out", "stdin.urdf"]

    def huge_note(_code: int, _out: str, err: str) -> str:
        return (
            f"stderr lines: {len(err.splitlines())}; 'overflow' said: {'overflow' in err}; "
            f"'x_table' named: {'x_table' in err}"
        )

    return [
        _kinfw_row(
            "35.10 a coordinate of 1e300",
            work,
            ["calibrate", huge.name, "--urdf", HEAD, "--out", "huge.urdf"],
            huge_note,
        ),
        _kinfw_row(
            "35.10 TIAGo Vicon CSV in mm imported as m",
            work,
            ["calibrate", "vicon_mm.json", "--urdf", TIAGO, "--out", "vicon_mm.urdf"],
            lambda _c, _o, err: f"joints named: {[j for j in joints if j in err] or 'none'}",
        ),
        _kinfw_row(
            "35.10 empty stdin for --urdf -",
            work,
            stdin,
            lambda _c, _o, err: f"'Is a directory' said: {'Is a directory' in err}",
            _shell([*KINFW, "-q", *stdin], work) + " < /dev/null",
        ),
    ]


def _item_10_files(work: Path, plates: Path, files: dict[str, Path]) -> list[Row]:
    """Messages about files: a missing image, ``;`` / decimal-comma CSVs for detect and
    handeye, the scalar-first refusal's first line."""
    cam = work / "img" / "hand_camera"
    excel = work / "joints_excel.csv"
    excel.write_text(_semicolons((cam / "joints.csv").read_text()))
    missing = str(cam / "hand_camera_012.png")
    reference = json.loads((work / "board_det.json").read_text())["samples"]

    def same_detections(code: int, _out: str, _err: str) -> str:
        if code:
            return _written(work, "excel_det.json")
        same = json.loads((work / "excel_det.json").read_text())["samples"] == reference
        return f"the same samples as with the ',' joints file: {same}"

    mount = _camera_from_hand_mm(_handeye_json(work, files["pairs.csv"].name))
    wrong = _scalar_first(plates, work / "plates_wxyz.json")

    def line_length(_code: int, _out: str, err: str) -> str:
        lines = err.splitlines()
        first = _local(next((x for x in lines if ": error: " in x), lines[0]), work)
        return f"error line {len(first)} characters (in the folder, the path {wrong.name})"

    return [
        _kinfw_row(
            "35.10 detect: an image that does not exist",
            work,
            [*_detect_args(cam, cam / "joints.csv", missing), "--out", "missing_det.json"],
            lambda _c, _o, err: (
                f"the joints CSV blamed: {'joints' in err}; " + _written(work, "missing_det.json")
            ),
            _detect_shown(
                work, cam, cam / "joints.csv", "missing_det.json", missing.replace(f"{work}/", "")
            ),
        ),
        _kinfw_row(
            "35.10 detect: a ';' / decimal-comma joints CSV",
            work,
            [*_detect_args(cam, excel), "--out", "excel_det.json"],
            same_detections,
            _detect_shown(work, cam, excel, "excel_det.json"),
        ),
        _kinfw_row(
            "35.10 handeye: a ';' / decimal-comma CSV",
            work,
            ["handeye", files["pairs_excel.csv"].name, "--json"],
            lambda _c, out, _e: (
                "camera from the hand: "
                f"{_camera_from_hand_mm(json.loads(out)):.3f} mm, ',' file {mount:.3f} mm"
            ),
        ),
        _kinfw_row(
            "35.10 the scalar-first refusal's first line",
            work,
            ["calibrate", wrong.name, "--urdf", HEAD, "--out", "plates_wxyz.urdf"],
            line_length,
        ),
    ]


def _in_sample_table(out: str) -> str:
    """``kinfw calibrate``'s in-sample table: from its title to the refine line."""
    return out.split("(in-sample):", 1)[-1].split("\nrefine:", 1)[0]


def _item_10_reports(work: Path, poses: Path) -> list[Row]:
    """Messages about fits: the model choice's candidates' warnings, clean data's tail
    called gross errors, an in-sample table with a rejected 67 mm sample."""
    _simulate(
        work,
        0,
        "precise",
        "--noise-mm",
        "0.1",
        "--noise-deg",
        "0.0573",
        "--per-joint",
        "4",
        "--seed",
        "4",
    )
    moved = _edited(
        poses,
        work / "moved.json",
        lambda d: d["samples"][5]["observations"][0]["xyz"].__setitem__(
            0, d["samples"][5]["observations"][0]["xyz"][0] + 0.067
        ),
    )

    precise = "--sigma-mm 0.1 --sigma-deg 0.0573 --out precise.urdf"  # the noise simulated

    def candidates(_code: int, _out: str, err: str) -> str:
        said = [line for line in err.splitlines() if ": warning: " in line]
        named = sum(": warning: model choice, candidate " in line for line in said)
        return f"warnings: {len(said)}, naming their candidate: {named}"

    def clean(_code: int, out: str, _err: str) -> str:
        gross = out.count("rejected as a gross error")
        expected = out.count("expected on clean data")
        return f"'rejected as a gross error': {gross}; 'expected on clean data': {expected}"

    def table(_code: int, out: str, _err: str) -> str:
        rows = _in_sample_table(out)
        plate = next(line.split() for line in rows.splitlines() if "left_plate" in line)
        said = "reject" in rows or "without" in rows
        rejected = any(
            line.strip().startswith("rejected") and "samples[5]" in line
            for line in out.splitlines()
        )
        return (
            f"in-sample left_plate RMS {plate[2]} -> {plate[-1]} mm, the table says what it "
            f"excludes: {said}; samples[5] rejected: {rejected}"
        )

    return [
        _kinfw_row(
            "35.10 the model choice's candidates' warnings",
            work,
            ["calibrate precise.json --urdf", HEAD, precise],
            candidates,
        ),
        _kinfw_row(
            "35.10 clean Gaussian data's tail",
            work,
            ["calibrate", poses.name, "--urdf", HEAD, "--params", "full", "--out", "clean.urdf"],
            clean,
        ),
        _kinfw_row(
            "35.10 in-sample table with a rejected 67 mm sample",
            work,
            ["calibrate", moved.name, "--urdf", HEAD, "--params", "full", "--out", "moved.urdf"],
            table,
        ),
    ]


def _view_without_meshes(work: Path) -> Row:
    """``kinfw view`` of the UR5's URDF copied away from its ``package://`` meshes."""
    urdf = work / "ur5.urdf"
    urdf.write_text(UR5.read_text())

    def note(_code: int, _out: str, err: str) -> str:
        lines = sum("not found" in line for line in err.splitlines())
        said = "skeleton" in err
        return f"'not found' lines: {lines}; 'skeleton' said: {said}; " + _written(work, "ur5.html")

    return _kinfw_row(
        "35 view: meshes not found", work, ["view", urdf.name, "--html ur5.html"], note
    )


def rows(work: Path) -> list[Row]:
    """Every case: issue 25's, then issue 35's in its order."""
    poses = _simulate(work, 40, "poses")
    plates = _simulate(work, 0, "plates")
    urdf, detections = _render_board(work)
    files = _pose_pairs(work)
    return [
        *_issue_25(work, poses),
        _item_1(work),
        _item_2(work),
        _item_3(work, urdf, detections),
        _item_4(work),
        _item_5(work, poses),
        *_item_6(work, files),
        *_item_7(work, poses, files),
        _item_8(work, poses, plates),
        _item_9(work),
        *_item_10_inputs(work, poses),
        *_item_10_files(work, plates, files),
        *_item_10_reports(work, poses),
        _view_without_meshes(work),
    ]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        table = rows(Path(tmp))
    print("| case | command | exit | stderr (first line) | also |")
    print("|---|---|---|---|---|")
    for r in table:
        cells = [r.case, f"`{r.command}`", str(r.code), r.first_line, r.note]
        print("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")


if __name__ == "__main__":
    main()
