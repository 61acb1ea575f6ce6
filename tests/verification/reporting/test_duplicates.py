"""Every sample recorded twice: kinfw.calibrate, kinfw.crossvalidate and ``kinfw
calibrate`` count each once (the sigmas of the set recorded once, to rounding) and say so
in one warning naming the copies; kept on request, every sigma shrinks by 1/sqrt(2)."""

import warnings

import numpy as np
import pytest

import kinfw
from kinfw.measurements import write_measurements
from tests.cli_run import run_cli
from tests.identification.checks.test_fit_checks import _arm_data
from tests.robots import ARM_6R


@pytest.fixture(scope="module")
def arm():
    nominal, data = _arm_data("flange", "flange", n=40)
    return nominal, data, data.subset(np.repeat(np.arange(data.n_samples), 2))


def _calibrate(nominal, data, **options):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        result = kinfw.calibrate(nominal, data, parameters="full", **options)
    return result.calibration.refined, [str(w.message) for w in record]


def test_every_sample_twice_gives_the_sigmas_of_once_and_one_warning(arm):
    nominal, once, twice = arm
    fit_once, said_once = _calibrate(nominal, once)
    fit, said = _calibrate(nominal, twice)
    free = fit.free
    np.testing.assert_allclose(fit.std[free], fit_once.std[free], rtol=1e-9)
    np.testing.assert_allclose(fit.estimate, fit_once.estimate, atol=1e-12)
    assert said_once == []
    (message,) = said  # no "residuals follow the robot's motion" either
    assert message.startswith("<simulated>: 40 of the 80 samples repeat an earlier one: ")
    assert "1 (= 0), 3 (= 2), 5 (= 4), 7 (= 6), 9 (= 8) and 35 more" in message


def test_kept_duplicates_shrink_every_sigma_by_one_over_root_two(arm):
    nominal, once, twice = arm
    fit_once, _ = _calibrate(nominal, once)
    fit, said = _calibrate(nominal, twice, keep_duplicates=True)
    ratio = fit.std[fit.free] / fit_once.std[fit.free]
    assert not any("repeat an earlier one" in m for m in said)
    assert 0.6 < float(np.median(ratio)) < 0.8  # 1/sqrt(2) = 0.707, noise re-estimated


def test_crossvalidate_drops_the_copies_before_the_folds(arm):
    nominal, once, twice = arm
    cv_once = kinfw.crossvalidate(nominal, once, k=2, sets=("frames",))
    with pytest.warns(UserWarning, match="40 of the 80 samples repeat an earlier one"):
        cv = kinfw.crossvalidate(nominal, twice, k=2, sets=("frames",))
    assert cv.to_dict() == cv_once.to_dict()


def test_kinfw_calibrate_warns_on_stderr_and_keep_duplicates_keeps_them(arm, tmp_path, capsys):
    _, _, twice = arm
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    write_measurements(tmp_path / "twice.json", twice)
    argv = ["-q", "calibrate", tmp_path / "twice.json", "--urdf", tmp_path / "arm.urdf"]
    argv += ["--out", tmp_path / "cal.urdf", "--params", "full", "--json"]
    code, _, stderr = run_cli(argv, capsys)
    assert code == 0, stderr
    assert stderr.count("repeat an earlier one") == 1
    assert "twice.json: 40 of the 80 samples repeat an earlier one: 1 (= 0)" in stderr
    code, _, stderr = run_cli([*argv, "--keep-duplicates"], capsys)
    assert code == 0 and "repeat an earlier one" not in stderr
    verify = ["-q", "verify", tmp_path / "arm.urdf", tmp_path / "twice.json", "--json"]
    code, _, stderr = run_cli(verify, capsys)
    assert code == 0 and stderr.count("40 of the 80 samples repeat an earlier one") == 1
    code, _, stderr = run_cli([*verify, "--keep-duplicates"], capsys)
    assert code == 0 and "repeat an earlier one" not in stderr
