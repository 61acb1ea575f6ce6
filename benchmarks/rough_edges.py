"""Issues 25's and 35's rough edges, re-run as a shell user meets them: one row per case
with the command, its exit code and the first line it prints on stderr.

Each case runs ``python -m kinfw.cli`` in a fresh process (or, for the two API cases, a
``python -c`` one-liner) in a temporary folder, on simulated IIS-head data
(``kinfw simulate``) and, for the spreadsheet CSVs, on the TIAGo Vicon CSV of
``tests/data/tiago_figaroh`` re-saved with a byte-order mark, ``;`` separators and
decimal commas. The tests that hold these behaviours are in
``tests/kinfw/cli/test_rough_edges.py``, ``tests/kinfw/measurements/test_figaroh_csv.py``,
``tests/kinfw/model/test_xacro.py`` and ``tests/kinfw/cli/test_package_dir.py``; issue 35's
also in ``tests/kinfw/cli/test_detect_cli.py``, ``tests/kinfw/measurements/test_pose_pairs.py``,
``tests/identification/checks/test_units.py`` and ``tests/kinfw/view/``.

Run: ``python benchmarks/rough_edges.py`` (about a minute; needs example-robot-data, a
test dependency, for the TIAGo URDF).
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import tempfile
import textwrap
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from kinfw import builtin_head_urdf
from tests.erd import urdf_path

KINFW = [sys.executable, "-m", "kinfw.cli"]
HEAD = str(builtin_head_urdf())
TIAGO = str(urdf_path("tiago_description/robots/tiago_no_hand.urdf"))
VICON = ROOT / "tests/data/tiago_figaroh/vicon_calibration_gripper3_base1.csv"


@dataclass(frozen=True)
class Row:
    """One case: what the user typed (shell words), the exit code, stderr's first line,
    and what else was checked (files left, lines printed)."""

    case: str
    command: str
    code: int
    first_line: str
    note: str = ""


def _run(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    proc = subprocess.run(argv, cwd=cwd, capture_output=True)
    return proc.returncode, proc.stdout.decode().strip(), proc.stderr.decode().strip()


def _first(err: str) -> str:
    """The error line if there is one, else the first line, shortened."""
    lines = err.splitlines() or ["(nothing)"]
    line = next((x for x in lines if ": error: " in x), lines[0])
    return line if len(line) <= 160 else line[:157] + "..."


def _shell(argv: list[str], work: Path) -> str:
    words = ["kinfw" if a == "-m" else a for a in argv[2:] if a != "kinfw.cli"]
    text = shlex.join(words).replace(HEAD, "HEAD.urdf").replace(f"{work}/", "")
    return text.replace(str(Path(TIAGO).parent) + "/", "")


def _simulate(work: Path, stage2: int, name: str) -> Path:
    out = work / f"{name}.json"
    argv = [*KINFW, "-q", "simulate", "--out", out, "--truth-out", work / f"{name}_true.urdf"]
    argv += ["--stage", "both", "--stage2-samples", str(stage2)] if stage2 else []
    code, _, err = _run([str(a) for a in argv], work)
    assert code == 0, err
    return out


def _ctrl_c(work: Path, data: Path) -> Row:
    argv = [*KINFW, "calibrate", data.name, "--urdf", HEAD, "--out", "c.urdf"]
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
    argv = [
        *KINFW,
        "-q",
        "reach",
        HEAD,
        "--frame",
        "left_plate",
        "--point",
        "0.3",
        "0.1",
        "0.4",
        "--json",
    ]
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader (`head`) has left before the output
    proc = subprocess.run(argv, cwd=work, stdout=write_end, stderr=subprocess.PIPE)
    os.close(write_end)
    err = proc.stderr.decode().strip()
    return Row("a reader that leaves", _shell(argv, work) + " | head", proc.returncode, _first(err))


def _kinfw_row(case: str, work: Path, args: list[str]) -> Row:
    """``kinfw -q ARGS``; on success, what it printed first on stdout."""
    argv = [*KINFW, "-q", *args]
    code, out, err = _run(argv, work)
    note = f"stdout: {_first(out)}" if code == 0 else ""
    return Row(case, _shell(argv, work), code, _first(err), note)


def _python_row(case: str, work: Path, code_text: str) -> Row:
    """``python -c CODE``: the exception's line."""
    code, _, err = _run([sys.executable, "-c", code_text], work)
    return Row(case, f'python -c "{code_text}"', code, _first(err.splitlines()[-1]))


def _spreadsheet_csv(work: Path) -> Path:
    """The Vicon CSV as a European spreadsheet saves it: BOM, ``;``, decimal commas."""
    text = VICON.read_text().replace(",", ";").replace(".", ",")
    path = work / "vicon_excel.csv"
    path.write_text(text, encoding="utf-8-sig")
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


def _sidecar_rows(work: Path, poses: Path) -> list[Row]:
    """Issue 35: verify given another calibration's sidecar (two calibrations of the head,
    on the plates and cameras and on the plates alone)."""
    plates = _simulate(work, 0, "plates")
    for name, data in (("a", poses), ("b", plates)):
        (work / name).mkdir()
        argv = [*KINFW, "-q", "calibrate", data.name, "--urdf", HEAD, "--out", f"{name}/c.urdf"]
        code, _, err = _run([*argv, "--params", "full"], work)
        assert code == 0, err
    argv = ["verify", "b/c.urdf", poses.name, "--sidecar", "a/c.kinfw.json"]
    return [_kinfw_row("verify with another calibration's sidecar", work, argv)]


def _handeye_pairs(work: Path) -> Path:
    """Ten eye-in-hand pose pairs of a known mount, as a European spreadsheet saves them
    (byte-order mark, ';', decimal commas)."""
    import re

    import numpy as np
    import pinocchio as pin

    from kinfw.measurements import PosePairs, pose_pairs_text

    rng = np.random.default_rng(0)
    X = pin.SE3(pin.exp3(np.array([0.4, -0.3, 1.1])), np.array([0.02, -0.05, 0.11])).homogeneous
    target = pin.SE3(pin.exp3(np.array([0.1, 2.0, -0.3])), np.array([0.7, 0.1, 0.2])).homogeneous
    hands = np.stack(
        [
            pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.2).homogeneous
            for _ in range(10)
        ]
    )
    cameras = np.stack([np.linalg.inv(X) @ np.linalg.inv(h) @ target for h in hands])
    text = pose_pairs_text(PosePairs(hands, cameras, "sim", None), "csv")
    path = work / "pairs_excel.csv"
    path.write_text("\ufeff" + re.sub(r"(\d)\.(\d)", r"\1,\2", text.replace(",", ";")))
    return path


def _issue_35_rows(work: Path, poses: Path) -> list[Row]:
    """Issue 35's cases: ordinary URDFs, a foreign sidecar, half-written outputs, messages."""
    import json

    from kinfw.camera import CameraIntrinsics

    (work / VICON.name).write_text(VICON.read_text())
    huge = json.loads(poses.read_text())
    huge["samples"][3]["q"][0] = 1e300
    (work / "huge.json").write_text(json.dumps(huge))
    (work / "cam.json").write_text(
        json.dumps(CameraIntrinsics(480, 360, 400.0, 404.0, 240.0, 180.0).to_dict())
    )
    (work / "joints.csv").write_text("image,pan\nimg_0.png,0.1\nimg_1.png,0.2\n")
    (work / "img_0.png").write_bytes(b"")  # exists; its neighbour's name is mistyped
    (work / "panda.urdf").write_text(urdf_path("panda_description/urdf/panda.urdf").read_text())
    return [
        _kinfw_row(
            "a URDF that only declares xmlns:xacro (read without xacro too)",
            work,
            ["crosscheck", "panda.urdf", "--frames", "panda_link8", "-n", "5"],
        ),
        *_sidecar_rows(work, poses),
        _kinfw_row(
            "plan --plot with a suffix matplotlib cannot write",
            work,
            ["plan", "--urdf", HEAD, "--n", "5", "--out", "plan.json", "--plot", "plan.xyz"],
        ),
        _kinfw_row(
            "a joint value of 1e300",
            work,
            ["calibrate", "huge.json", "--urdf", HEAD, "--out", "huge.urdf"],
        ),
        _kinfw_row(
            "import-csv --length-unit mm of a file in m, then calibrate",
            work,
            [
                "import-csv",
                VICON.name,
                "--urdf",
                TIAGO,
                "--frame",
                "arm_7_link",
                "--measured-in",
                "vicon",
                "--length-unit",
                "mm",
                "--out",
                "v_mm.json",
            ],
        ),
        _kinfw_row(
            "calibrate it", work, ["calibrate", "v_mm.json", "--urdf", TIAGO, "--out", "v.urdf"]
        ),
        _kinfw_row(
            "detect with a mistyped image name",
            work,
            [
                *("detect", "img_0.png", "img_O.png", "--joints", "joints.csv"),
                *("--camera", "cam.json", "--frame", "cam"),
                *("--board", "chessboard:9x6:0.03", "--out", "d.json"),
            ],
        ),
        _stdin_row(work),
        _kinfw_row(
            "handeye on a ';' CSV with decimal commas",
            work,
            ["handeye", _handeye_pairs(work).name],
        ),
    ]


def _stdin_row(work: Path) -> Row:
    """``kinfw crosscheck - < /dev/null``."""
    argv = [*KINFW, "-q", "crosscheck", "-"]
    proc = subprocess.run(argv, cwd=work, stdin=subprocess.DEVNULL, capture_output=True)
    err = proc.stderr.decode().strip()
    return Row(
        "an empty stdin for --urdf -",
        _shell(argv, work) + " < /dev/null",
        proc.returncode,
        _first(err),
    )


def rows(work: Path) -> list[Row]:
    """Every case, in the issue's order."""
    poses = _simulate(work, 40, "poses")
    wrong = work / "wxyz.json"
    _scalar_first(poses, wrong)
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
    return [
        _ctrl_c(work, _simulate(work, 200, "long")),
        _closed_pipe(work),
        _kinfw_row(
            "--holdout = the training file",
            work,
            ["calibrate", poses.name, "--urdf", HEAD, "--out", "h.urdf", "--holdout", poses.name],
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
            "from kinfw.identification import calibrate; "
            "calibrate(load_robot(builtin_head_urdf()), 'file.json')",
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
            [
                "reach",
                xacro.name,
                "--xacro-arg",
                "reach:=0.7",
                "--frame",
                "tool0",
                "--point",
                "0.7",
                "0",
                "0.1",
            ],
        ),
        _kinfw_row(
            "CSV with BOM, ';' and decimal commas",
            work,
            [
                "import-csv",
                _spreadsheet_csv(work).name,
                "--urdf",
                TIAGO,
                "--frame",
                "arm_7_link",
                "--out",
                "v.json",
            ],
        ),
        _kinfw_row(
            "plan --collisions, meshes missing",
            work,
            [
                "plan",
                "--urdf",
                meshless.name,
                "--frames",
                "tool0",
                "--collisions",
                "--out",
                "p.json",
            ],
        ),
        *_issue_35_rows(work, poses),
    ]


def _scalar_first(path: Path, to: Path) -> None:
    """Every quat_xyzw written (w, x, y, z)."""
    import json

    def walk(o):
        if isinstance(o, dict):
            return {k: [v[3], *v[:3]] if k == "quat_xyzw" else walk(v) for k, v in o.items()}
        return [walk(v) for v in o] if isinstance(o, list) else o

    to.write_text(json.dumps(walk(json.loads(path.read_text()))))


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        table = rows(Path(tmp))
    print("| case | command | exit | stderr (first line) | also |")
    print("|---|---|---|---|---|")
    for r in table:
        print(f"| {r.case} | `{r.command}` | {r.code} | {r.first_line} | {r.note} |")


if __name__ == "__main__":
    main()
